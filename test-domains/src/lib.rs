//! ROS 2 domain ids for tests, leased so that tests running at the same time never share one.
//!
//! Every test that starts DDS participants needs a domain of its own: two tests on one
//! domain discover each other's nodes and read each other's topics. Picking a domain from
//! the process id is not enough once tests run concurrently (cargo-nextest runs every test
//! in a process of its own, several at once), because the ranges different files chose
//! overlap. A lease holds an advisory lock on one file per domain in the temp directory;
//! the kernel drops the lock when the holder exits, however it exits, so a crashed test
//! never leaks a domain. Written here rather than taken from a crate because it is twenty
//! lines over `std::fs::File::try_lock`.

use std::fs::{File, OpenOptions};
use std::path::PathBuf;
use std::sync::OnceLock;

/// The domains tests may take. 0 is the ROS default (a user's fleet on this machine),
/// 1-19 are left to people experimenting by hand, and DDS Security's port arithmetic
/// stops at 230 for our secure participants (DESIGN.md).
pub const FIRST: u16 = 20;
/// One past the last domain a lease may hand out.
pub const END: u16 = 231;

/// `count` consecutive ROS domain ids, held until the lease is dropped.
#[derive(Debug)]
pub struct DomainLease {
    first: u16,
    count: u16,
    _locks: Vec<File>,
}

impl DomainLease {
    /// The first leased domain.
    pub fn first(&self) -> u16 {
        self.first
    }

    /// The `offset`-th leased domain; panics (a bug in the test) past the lease.
    pub fn get(&self, offset: u16) -> u16 {
        assert!(
            offset < self.count,
            "domain offset {offset} is outside this lease of {} domains",
            self.count
        );
        self.first + offset
    }

    /// All leased domains.
    pub fn all(&self) -> std::ops::Range<u16> {
        self.first..self.first + self.count
    }
}

fn lock_dir() -> PathBuf {
    std::env::temp_dir().join("tending-test-domains")
}

/// Try to lock domain `d`'s file; `None` when another process (or this one) holds it.
fn try_take(d: u16) -> Option<File> {
    let path = lock_dir().join(format!("{d}.lock"));
    let f = OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&path)
        .unwrap_or_else(|e| panic!("test domain lock file {}: {e}", path.display()));
    f.try_lock().ok().map(|()| f)
}

/// Lease `count` consecutive free domains in `FIRST..END`. The search starts at a place
/// drawn from the process id, so concurrent tests rarely contend for the same files.
/// Panics, naming the range, when no such block is free.
pub fn lease(count: u16) -> DomainLease {
    assert!(
        (1..=END - FIRST).contains(&count),
        "cannot lease {count} domains"
    );
    let dir = lock_dir();
    std::fs::create_dir_all(&dir)
        .unwrap_or_else(|e| panic!("test domain lock directory {}: {e}", dir.display()));
    let starts = END - FIRST - count + 1;
    let offset = (std::process::id() % u32::from(starts)) as u16;
    for i in 0..starts {
        let first = FIRST + (offset + i) % starts;
        let mut locks = Vec::with_capacity(count.into());
        for d in first..first + count {
            match try_take(d) {
                Some(f) => locks.push(f),
                None => break,
            }
        }
        if locks.len() == usize::from(count) {
            return DomainLease {
                first,
                count,
                _locks: locks,
            };
        }
    }
    panic!(
        "no {count} consecutive free ROS domains in {FIRST}..{END} (locks in {})",
        dir.display()
    )
}

/// How many domains [`domain`] leases for a test process.
pub const PER_PROCESS: u16 = 8;

/// The `offset`-th domain of this process's block of [`PER_PROCESS`], leased at the first
/// call and held until the process exits. Under `cargo test` a test binary's tests share
/// the process, so each uses its own offsets; under cargo-nextest each test is a process
/// and gets a block of its own.
pub fn domain(offset: u16) -> u16 {
    static BLOCK: OnceLock<DomainLease> = OnceLock::new();
    BLOCK.get_or_init(|| lease(PER_PROCESS)).get(offset)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn leases_held_at_once_never_share_a_domain_and_a_dropped_one_is_free_again() {
        let a = lease(5);
        let b = lease(5);
        assert!(a.all().all(|d| !b.all().contains(&d)), "{a:?} {b:?}");
        assert!(a.all().all(|d| (FIRST..END).contains(&d)));
        let a_first = a.first();
        drop(a);
        // The freed block is takeable again: lock it file by file.
        let again: Vec<_> = (a_first..a_first + 5).map(try_take).collect();
        assert!(again.iter().all(Option::is_some));
    }

    #[test]
    #[should_panic(expected = "outside this lease")]
    fn an_offset_past_the_lease_is_a_test_bug() {
        let l = DomainLease {
            first: FIRST,
            count: 2,
            _locks: Vec::new(),
        };
        l.get(2);
    }
}
