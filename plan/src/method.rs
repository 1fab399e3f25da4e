//! The names of the controllers: one parser for every place that reads one (`tending sim`,
//! `eval` and `fleet`'s `--policy`, robot_node's `controller` parameter); the launch file's
//! list is held equal to [`MethodName::ON_ROBOT`] by a robot_node test.

use std::fmt;
use std::str::FromStr;

/// A controller by name: a script of this crate, or a learned policy (a checkpoint).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MethodName {
    Greedy,
    GreedyOrca,
    MatchingOrca,
    /// Uniformly random actions: an offline baseline, never run on a robot.
    Random,
    /// A learned policy, from a checkpoint.
    Policy,
}

impl MethodName {
    pub const ALL: [MethodName; 5] = [
        MethodName::Greedy,
        MethodName::GreedyOrca,
        MethodName::MatchingOrca,
        MethodName::Random,
        MethodName::Policy,
    ];
    /// What robot_node runs.
    pub const ON_ROBOT: [MethodName; 4] = [
        MethodName::Greedy,
        MethodName::GreedyOrca,
        MethodName::MatchingOrca,
        MethodName::Policy,
    ];

    pub const fn as_str(self) -> &'static str {
        match self {
            MethodName::Greedy => "greedy",
            MethodName::GreedyOrca => "greedy-orca",
            MethodName::MatchingOrca => "matching-orca",
            MethodName::Random => "random",
            MethodName::Policy => "policy",
        }
    }

    /// A scripted controller (everything but a learned policy).
    pub fn is_script(self) -> bool {
        self != MethodName::Policy
    }

    /// "greedy, greedy-orca, matching-orca or policy", for error messages.
    pub fn list(names: &[MethodName]) -> String {
        let s: Vec<&str> = names.iter().map(|n| n.as_str()).collect();
        match s.split_last() {
            Some((last, rest)) if !rest.is_empty() => format!("{} or {last}", rest.join(", ")),
            _ => s.join(""),
        }
    }
}

impl fmt::Display for MethodName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for MethodName {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Self::ALL
            .into_iter()
            .find(|n| n.as_str() == s)
            .ok_or_else(|| {
                format!(
                    "unknown controller `{s}`: expected {}",
                    Self::list(&Self::ALL)
                )
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_unknown_ones_are_listed() {
        for n in MethodName::ALL {
            assert_eq!(n.as_str().parse::<MethodName>(), Ok(n));
        }
        let e = "greedy_orca".parse::<MethodName>().unwrap_err();
        assert!(
            e.contains("greedy_orca") && e.contains("random or policy"),
            "{e}"
        );
        assert_eq!(
            MethodName::list(&MethodName::ON_ROBOT),
            "greedy, greedy-orca, matching-orca or policy"
        );
    }
}
