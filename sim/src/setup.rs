//! Setup names: `N.M_K` = N robots, M machines, K storage areas (the paper's notation).

use crate::SimError;
use std::fmt;
use std::str::FromStr;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Setup {
    pub robots: usize,
    pub machines: usize,
    pub storages: usize,
}

impl Setup {
    pub const fn new(robots: usize, machines: usize, storages: usize) -> Self {
        Self {
            robots,
            machines,
            storages,
        }
    }
}

impl fmt::Display for Setup {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}.{}_{}", self.robots, self.machines, self.storages)
    }
}

impl FromStr for Setup {
    type Err = SimError;
    /// Accepts `14.10_4` (paper text) and `14_10_4` (paper tables).
    fn from_str(s: &str) -> Result<Self, SimError> {
        let bad = || SimError::BadSetupName(s.to_string());
        let parts: Vec<&str> = s.trim().split(['.', '_']).collect();
        if parts.len() != 3 {
            return Err(bad());
        }
        let n: Vec<usize> = parts
            .iter()
            .map(|p| p.parse::<usize>().map_err(|_| bad()))
            .collect::<Result<_, _>>()?;
        let setup = Setup::new(n[0], n[1], n[2]);
        if setup.machines == 0 || setup.storages == 0 {
            return Err(SimError::BadSetup {
                setup: s.to_string(),
                reason: "a setup needs at least one machine and one storage area".into(),
            });
        }
        if setup.robots == 0 {
            return Err(SimError::BadSetup {
                setup: s.to_string(),
                reason: "a setup needs at least one robot".into(),
            });
        }
        Ok(setup)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_both_notations() {
        assert_eq!("14.10_4".parse::<Setup>().unwrap(), Setup::new(14, 10, 4));
        assert_eq!("2_2_2".parse::<Setup>().unwrap(), Setup::new(2, 2, 2));
        assert_eq!(Setup::new(100, 16, 2).to_string(), "100.16_2");
    }

    #[test]
    fn rejects_bad_names_and_empty_groups() {
        assert!(matches!(
            "14.10".parse::<Setup>(),
            Err(SimError::BadSetupName(_))
        ));
        assert!(matches!(
            "a.b_c".parse::<Setup>(),
            Err(SimError::BadSetupName(_))
        ));
        assert!(matches!(
            "4.0_2".parse::<Setup>(),
            Err(SimError::BadSetup { .. })
        ));
        assert!(matches!(
            "4.2_0".parse::<Setup>(),
            Err(SimError::BadSetup { .. })
        ));
        assert!(matches!(
            "0.2_2".parse::<Setup>(),
            Err(SimError::BadSetup { .. })
        ));
    }
}
