//! On-robot inference allocates nothing after the first decision with given counts.
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;
static ALLOCS: AtomicUsize = AtomicUsize::new(0);
thread_local! {
    // Only the measuring thread counts: the test harness allocates on its own threads.
    static MEASURING: Cell<bool> = const { Cell::new(false) };
}
fn count() {
    if MEASURING.try_with(|m| m.get()).unwrap_or(false) {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
    }
}
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        count();
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        count();
        unsafe { System.realloc(p, l, n) }
    }
}
#[global_allocator]
static GLOBAL: Counting = Counting;

fn obs_row(m: usize, k: usize, p: usize, shift: f32) -> obs::ObsBatch {
    let mut b = obs::ObsBatch::zeros(
        1,
        obs::Counts {
            machines: m,
            storages: k,
            peers: p,
        },
    );
    for (i, v) in b.machines.iter_mut().enumerate() {
        *v = if i % 3 == 2 {
            (i % 2) as f32
        } else {
            (i as f32 * 0.37 + shift).sin()
        };
    }
    for (i, v) in b.storages.iter_mut().enumerate() {
        *v = (i as f32 * 0.11 - shift).cos();
    }
    for (i, v) in b.peers.iter_mut().enumerate() {
        *v = if i % 3 == 2 {
            0.0
        } else {
            (i as f32 * 0.23 + shift).sin()
        };
    }
    b.own.copy_from_slice(&[0.1 * shift, -0.2, 0.0]);
    b
}

#[test]
fn act_does_not_allocate_after_warm_up() {
    let actor = policy::Actor::new(policy::ArchConfig::smappo(), 1);
    let mut pol = policy::Policy::from_actor(actor, serde_json::json!({}));
    let mut state = pol.new_state();
    let inputs: Vec<_> = (0..8).map(|s| obs_row(10, 4, 13, s as f32)).collect();
    pol.act(&inputs[0], &mut state, policy::ActMode::Greedy)
        .unwrap();
    MEASURING.with(|m| m.set(true));
    let before = ALLOCS.load(Ordering::SeqCst);
    let mut actions = [0u8; 8];
    for (a, o) in actions.iter_mut().zip(&inputs) {
        *a = pol.act(o, &mut state, policy::ActMode::Greedy).unwrap();
    }
    let after = ALLOCS.load(Ordering::SeqCst);
    MEASURING.with(|m| m.set(false));
    assert!(actions.iter().all(|&a| a < 5));
    assert_eq!(
        after - before,
        0,
        "{} allocations in 8 decisions",
        after - before
    );
}
