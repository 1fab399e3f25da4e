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
//! The rule: at most [`PROCESSES_PER_CORE`] robot processes per core; a larger fleet is
//! split into that many processes of consecutive robots. `--robots-per-process K`
//! overrides it (K = 1: one process per robot whatever the size).

/// Robot processes per available core before robots are grouped.
pub const PROCESSES_PER_CORE: usize = 10;

/// Robots per process for `n` robots on `cores` cores, or `forced` when given.
pub fn robots_per_process(n: usize, cores: usize, forced: Option<usize>) -> usize {
    if let Some(k) = forced {
        return k.max(1);
    }
    let max_procs = (PROCESSES_PER_CORE * cores.max(1)).max(1);
    n.div_ceil(max_procs).max(1)
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
        assert_eq!(robots_per_process(6, 2, None), 1);
        assert_eq!(robots_per_process(20, 2, None), 1);
        assert_eq!(robots_per_process(21, 2, None), 2);
        assert_eq!(robots_per_process(50, 2, None), 3);
        assert_eq!(robots_per_process(100, 2, None), 5);
        assert_eq!(robots_per_process(100, 16, None), 1);
        assert_eq!(robots_per_process(0, 0, None), 1);
        // the override wins both ways
        assert_eq!(robots_per_process(100, 2, Some(1)), 1);
        assert_eq!(robots_per_process(6, 2, Some(3)), 3);
        assert_eq!(robots_per_process(6, 2, Some(0)), 1);
    }

    #[test]
    fn groups_cover_every_robot_once_in_order() {
        let g = groups(&names(50), robots_per_process(50, 2, None));
        assert_eq!(g.len(), 17);
        assert!(g.iter().all(|x| x.len() <= 3));
        assert_eq!(g.concat(), names(50));
        assert_eq!(label(&g[0]), "robot_0-robot_2");
        assert_eq!(label(&g[16]), "robot_48-robot_49");
        assert_eq!(label(&["robot_7".to_string()]), "robot_7");
    }
}
