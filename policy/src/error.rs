//! Errors of the policy crate.

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum PolicyError {
    #[error("invalid observation: {0}")]
    Obs(#[from] obs::ObsError),
    #[error("`{what}` has length {got}, expected {expected}")]
    Shape {
        what: &'static str,
        got: usize,
        expected: usize,
    },
    #[error("{field}: {got} entities exceed this MAPPO model's maximum of {max} (padded layout fixed at training time)")]
    TooMany {
        field: &'static str,
        got: usize,
        max: usize,
    },
    #[error("act() takes exactly one observation row, got {0}")]
    NotOneRow(usize),
    #[error("batch of {rows} rows is not a whole number of environments of {n} robots")]
    NotPerEnv { rows: usize, n: usize },
}

pub(crate) fn check_len(
    what: &'static str,
    got: usize,
    expected: usize,
) -> Result<(), PolicyError> {
    if got != expected {
        return Err(PolicyError::Shape {
            what,
            got,
            expected,
        });
    }
    Ok(())
}
