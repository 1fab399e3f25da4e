//! One way to read a file input: the scenario, a training config, a margins file, a
//! checkpoint. Every error names what the file is for and its path, and says which of three
//! things went wrong: it is not there, it cannot be read (permissions, a directory), or its
//! content is malformed (the parser's reason). Each crate parses its own format; only the
//! reading and the wording live here, so the messages cannot drift apart.

use std::io::ErrorKind;
use std::path::{Path, PathBuf};

/// Why a file input was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InputError {
    #[error("{what} {}: no such file", path.display())]
    Missing { what: &'static str, path: PathBuf },
    #[error("{what} {}: cannot be read: {reason}", path.display())]
    Unreadable {
        what: &'static str,
        path: PathBuf,
        reason: String,
    },
    #[error("{what} {}: malformed: {reason}", path.display())]
    Malformed {
        what: &'static str,
        path: PathBuf,
        reason: String,
    },
}

impl InputError {
    /// The content of `path` (a `what`) was refused by its parser for `reason`.
    pub fn malformed(what: &'static str, path: &Path, reason: impl ToString) -> Self {
        InputError::Malformed {
            what,
            path: path.to_path_buf(),
            reason: reason.to_string(),
        }
    }

    /// The path the error is about.
    pub fn path(&self) -> &Path {
        match self {
            InputError::Missing { path, .. }
            | InputError::Unreadable { path, .. }
            | InputError::Malformed { path, .. } => path,
        }
    }
}

/// The bytes of `path`, a `what` ("scenario file", "checkpoint", ...).
pub fn read_bytes(what: &'static str, path: &Path) -> Result<Vec<u8>, InputError> {
    std::fs::read(path).map_err(|e| io_error(what, path, e))
}

/// The text of `path`, a `what`; invalid UTF-8 is malformed content.
pub fn read_text(what: &'static str, path: &Path) -> Result<String, InputError> {
    let bytes = read_bytes(what, path)?;
    String::from_utf8(bytes).map_err(|e| InputError::malformed(what, path, e))
}

/// `path`, a `what`, read as text and given to `parse`; its error is the malformed reason.
pub fn parse_text<T, E: ToString>(
    what: &'static str,
    path: &Path,
    parse: impl FnOnce(&str) -> Result<T, E>,
) -> Result<T, InputError> {
    let text = read_text(what, path)?;
    parse(&text).map_err(|e| InputError::malformed(what, path, e))
}

fn io_error(what: &'static str, path: &Path, e: std::io::Error) -> InputError {
    match e.kind() {
        ErrorKind::NotFound => InputError::Missing {
            what,
            path: path.to_path_buf(),
        },
        _ => InputError::Unreadable {
            what,
            path: path.to_path_buf(),
            reason: e.to_string(),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str, content: &[u8]) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("inputs-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join(name);
        std::fs::write(&p, content).unwrap();
        p
    }

    #[test]
    fn a_missing_file_is_named_and_said_missing() {
        let e = read_text("scenario file", Path::new("/nonexistent/x.toml")).unwrap_err();
        assert!(matches!(e, InputError::Missing { .. }));
        assert_eq!(
            e.to_string(),
            "scenario file /nonexistent/x.toml: no such file"
        );
    }

    #[test]
    fn a_directory_is_unreadable_not_missing() {
        let e = read_text("margins file", &std::env::temp_dir()).unwrap_err();
        assert!(matches!(e, InputError::Unreadable { .. }), "{e}");
        assert!(e.to_string().starts_with("margins file "), "{e}");
    }

    #[test]
    fn bad_content_is_malformed_with_the_parsers_reason() {
        let p = tmp("bad.toml", b"n_envs = ");
        let e = parse_text("training config", &p, |t| {
            t.parse::<u32>().map_err(|e| format!("not a number: {e}"))
        })
        .unwrap_err();
        assert!(matches!(e, InputError::Malformed { .. }));
        let s = e.to_string();
        assert!(
            s.contains("training config") && s.contains("bad.toml: malformed: not a number"),
            "{s}"
        );
        let p = tmp("latin1.toml", &[0xff, 0xfe]);
        assert!(matches!(
            read_text("scenario file", &p),
            Err(InputError::Malformed { .. })
        ));
    }
}
