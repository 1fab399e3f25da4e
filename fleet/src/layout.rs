//! How many robots each robot_node process hosts.
//!
//! One process per robot is what a real fleet looks like, but each process carries a DDS
//! participant with its own threads, sockets and discovery traffic: on this project's
//! 2-core machines 20 processes at 10 Hz are fine, 50 are not (robots stop receiving state,
//! the bridge falls behind), and RustDDS picks participant ids below 120 per host and
//! domain. `robot_node -p robots:=...` hosts many robots in one process with one reader
//! per topic shared by all of them (0 % missed ticks for 100-200 robots in one process,
//! docs/bench/ros.md), each robot still with its own `cmd_vel` writer and controller.
//!
//! The rule: one process per robot up to [`PROCESSES_PER_CORE`] processes per core; a
//! larger fleet runs as [`GROUPS_PER_CORE`] processes per core, each hosting a run of
//! consecutive robots. Measured here (docs/bench/startup.md): 100.16_2 as 20 processes of
//! 5 lost most robots under load (each process carries a participant with 234 readers and
//! its discovery traffic), as 4 processes of 25 it ran at 10 Hz with every robot on state.
//! `--robots-per-process K` overrides it (K = 1: one process per robot whatever the size).
//!
//! With DDS Security every pair of participants runs an authentication handshake
//! (certificate and permissions signatures, Diffie-Hellman) and a key exchange per matched
//! endpoint pair, so start-up work grows with the square of the processes. Measured here
//! (docs/bench/security.md, 2 cores): 20.10_4 as 20 secure processes left 13-18 robots off
//! the bridge's state for the whole 45 s run (3 runs), as 4 processes of 5 every robot was
//! on state within 10 s. Secure fleets therefore group earlier, from
//! [`SECURE_PROCESSES_PER_CORE`] processes per core.

/// Single-robot secure processes per available core before robots are grouped.
pub const SECURE_PROCESSES_PER_CORE: usize = 4;

/// Single-robot processes per available core before robots are grouped.
pub const PROCESSES_PER_CORE: usize = 10;
/// Processes per available core once robots are grouped.
pub const GROUPS_PER_CORE: usize = 2;

/// Robots per process for `n` robots on `cores` cores (`secure`: DDS Security on), or
/// `forced` when given.
pub fn robots_per_process(n: usize, cores: usize, secure: bool, forced: Option<usize>) -> usize {
    if let Some(k) = forced {
        return k.max(1);
    }
    let cores = cores.max(1);
    let singles = if secure {
        SECURE_PROCESSES_PER_CORE
    } else {
        PROCESSES_PER_CORE
    };
    if n <= singles * cores {
        1
    } else {
        n.div_ceil(GROUPS_PER_CORE * cores)
    }
}

/// The robot names of each process, in order: `robot_0..` split into runs of `per`.
pub fn groups(names: &[String], per: usize) -> Vec<Vec<String>> {
    names.chunks(per.max(1)).map(|c| c.to_vec()).collect()
}

/// A process's label (log file name, status line): the robot's name, or
/// `robot_0-robot_4` for a group.
pub fn label(group: &[String]) -> String {
    match group {
        [] => "empty".into(),
        [one] => one.clone(),
        [first, .., last] => format!("{first}-{last}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(n: usize) -> Vec<String> {
        (0..n).map(|i| format!("robot_{i}")).collect()
    }

    #[test]
    fn small_fleets_get_one_process_per_robot_large_ones_are_grouped() {
        assert_eq!(robots_per_process(6, 2, false, None), 1);
        assert_eq!(robots_per_process(20, 2, false, None), 1);
        assert_eq!(robots_per_process(21, 2, false, None), 6);
        assert_eq!(robots_per_process(50, 2, false, None), 13);
        assert_eq!(robots_per_process(100, 2, false, None), 25);
        assert_eq!(robots_per_process(100, 16, false, None), 1);
        assert_eq!(robots_per_process(200, 16, false, None), 7);
        assert_eq!(robots_per_process(0, 0, false, None), 1);
        // the override wins both ways
        assert_eq!(robots_per_process(100, 2, false, Some(1)), 1);
        assert_eq!(robots_per_process(6, 2, false, Some(3)), 3);
        assert_eq!(robots_per_process(6, 2, false, Some(0)), 1);
    }

    #[test]
    fn secure_fleets_are_grouped_from_fewer_processes() {
        assert_eq!(robots_per_process(8, 2, true, None), 1);
        assert_eq!(robots_per_process(10, 2, true, None), 3);
        assert_eq!(robots_per_process(20, 2, true, None), 5);
        assert_eq!(robots_per_process(20, 16, true, None), 1);
        assert_eq!(robots_per_process(20, 2, true, Some(1)), 1);
    }

    #[test]
    fn groups_cover_every_robot_once_in_order() {
        let g = groups(&names(50), robots_per_process(50, 2, false, None));
        assert_eq!(g.len(), 4);
        assert!(g.iter().all(|x| x.len() <= 13));
        assert_eq!(g.concat(), names(50));
        assert_eq!(label(&g[0]), "robot_0-robot_12");
        assert_eq!(label(&g[3]), "robot_39-robot_49");
        let g = groups(&names(7), 3);
        assert_eq!(g.iter().map(Vec::len).collect::<Vec<_>>(), [3, 3, 1]);
        assert_eq!(label(&["robot_7".to_string()]), "robot_7");
    }
}
