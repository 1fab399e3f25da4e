//! DDS Security the way ROS 2 (rcl) switches it on, for every node binary at once:
//!
//! - `ROS_SECURITY_ENABLE=true` turns it on (any other value: off);
//! - `ROS_SECURITY_KEYSTORE=DIR`: a keystore in the SROS2 layout (`tending security`);
//! - the enclave: `ROS_SECURITY_ENCLAVE_OVERRIDE`, else `--ros-args --enclave /...`, else
//!   `/` (the keystore's `enclaves/` directory itself);
//! - `ROS_SECURITY_STRATEGY=Enforce`: no valid enclave is an error and the process does
//!   not start; otherwise (Permissive) a missing enclave logs a warning and the process
//!   runs without security, as rcl does.
//!
//! With security on, the participant authenticates with the enclave's identity, joins
//! under its permissions and encrypts/signs as the governance says (rustdds's builtin
//! plugins); rustdds then refuses the participant if a file does not verify.

use std::path::{Path, PathBuf};

/// The ROS security environment variables of one process.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SecurityEnv {
    pub enable: Option<String>,
    pub strategy: Option<String>,
    pub keystore: Option<String>,
    pub enclave_override: Option<String>,
}

impl SecurityEnv {
    /// The process environment.
    pub fn from_env() -> Self {
        Self::from_lookup(|k| std::env::var(k).ok())
    }

    /// From any lookup (tests).
    pub fn from_lookup(get: impl Fn(&str) -> Option<String>) -> Self {
        Self {
            enable: get("ROS_SECURITY_ENABLE"),
            strategy: get("ROS_SECURITY_STRATEGY"),
            keystore: get("ROS_SECURITY_KEYSTORE"),
            enclave_override: get("ROS_SECURITY_ENCLAVE_OVERRIDE"),
        }
    }

    fn enabled(&self) -> bool {
        self.enable.as_deref() == Some("true")
    }

    fn enforce(&self) -> bool {
        self.strategy.as_deref() == Some("Enforce")
    }
}

/// What a process runs with.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Security {
    Off,
    /// Enclave `enclave` (e.g. `/tending/robot_3`) whose files are in `dir`.
    Enclave {
        enclave: String,
        dir: PathBuf,
    },
}

/// Why a process may not start.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SecurityError {
    #[error(
        "DDS Security is enforced (ROS_SECURITY_ENABLE=true, ROS_SECURITY_STRATEGY=Enforce) \
         but ROS_SECURITY_KEYSTORE is not set: refusing to start without an enclave"
    )]
    NoKeystore,
    #[error(
        "DDS Security is enforced but enclave `{enclave}` has no directory {dir} in keystore \
         {keystore} (create it with `tending security enclave`, or pass --ros-args --enclave \
         with an existing one): refusing to start"
    )]
    NoEnclave {
        enclave: String,
        dir: String,
        keystore: String,
    },
    #[error(
        "DDS Security is enforced but enclave `{enclave}` ({dir}) lacks {missing}: refusing to \
         start"
    )]
    MissingFiles {
        enclave: String,
        dir: String,
        missing: String,
    },
    #[error("enclave `{0}`: expected an absolute ROS name like /tending/robot_3")]
    BadName(String),
}

pub use msgs::enclave::FILES as ENCLAVE_FILES;

fn valid_enclave(name: &str) -> bool {
    name == "/"
        || (name.starts_with('/')
            && name[1..].split('/').all(|s| {
                !s.is_empty() && s.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_')
            }))
}

/// Decide from the environment and the `--enclave` argument; `warn` gets the Permissive
/// fallback's message.
pub fn resolve(
    env: &SecurityEnv,
    enclave_arg: Option<&str>,
    warn: impl FnOnce(&str),
) -> Result<Security, SecurityError> {
    if !env.enabled() {
        return Ok(Security::Off);
    }
    let enclave = env
        .enclave_override
        .as_deref()
        .filter(|s| !s.is_empty())
        .or(enclave_arg)
        .unwrap_or("/")
        .to_string();
    if !valid_enclave(&enclave) {
        return Err(SecurityError::BadName(enclave));
    }
    let fallback = |err: SecurityError, warn: Box<dyn FnOnce(&str) + '_>| {
        if env.enforce() {
            Err(err)
        } else {
            warn(&format!(
                "{err}; ROS_SECURITY_STRATEGY is not Enforce, so running WITHOUT security"
            ));
            Ok(Security::Off)
        }
    };
    let Some(keystore) = env.keystore.as_deref().filter(|s| !s.is_empty()) else {
        return fallback(SecurityError::NoKeystore, Box::new(warn));
    };
    let dir = msgs::enclave::dir(Path::new(keystore), &enclave);
    if !dir.is_dir() {
        let err = SecurityError::NoEnclave {
            enclave,
            dir: dir.display().to_string(),
            keystore: keystore.to_string(),
        };
        return fallback(err, Box::new(warn));
    }
    let missing: Vec<&str> = ENCLAVE_FILES
        .iter()
        .copied()
        .filter(|f| !dir.join(f).is_file())
        .collect();
    if !missing.is_empty() {
        let err = SecurityError::MissingFiles {
            enclave,
            dir: dir.display().to_string(),
            missing: missing.join(", "),
        };
        return fallback(err, Box::new(warn));
    }
    Ok(Security::Enclave { enclave, dir })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env(enable: &str, strategy: &str, keystore: Option<&str>) -> SecurityEnv {
        SecurityEnv {
            enable: Some(enable.into()),
            strategy: Some(strategy.into()),
            keystore: keystore.map(Into::into),
            enclave_override: None,
        }
    }

    fn fake_keystore(name: &str, files: &[&str]) -> PathBuf {
        let root = std::env::temp_dir().join(format!("tending-sec-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let dir = root.join("enclaves/tending/robot_3");
        std::fs::create_dir_all(&dir).unwrap();
        for f in files {
            std::fs::write(dir.join(f), "x").unwrap();
        }
        root
    }

    #[test]
    fn off_unless_enable_is_exactly_true() {
        for v in ["", "1", "TRUE", "false"] {
            let e = env(v, "Enforce", None);
            assert_eq!(resolve(&e, Some("/x"), |_| {}), Ok(Security::Off), "{v}");
        }
        assert_eq!(
            resolve(&SecurityEnv::default(), None, |_| {}),
            Ok(Security::Off)
        );
    }

    #[test]
    fn enforce_without_keystore_or_enclave_refuses_with_the_reason() {
        let e = resolve(
            &env("true", "Enforce", None),
            Some("/tending/robot_3"),
            |_| {},
        );
        assert_eq!(e, Err(SecurityError::NoKeystore));
        assert!(e.unwrap_err().to_string().contains("ROS_SECURITY_KEYSTORE"));

        let root = fake_keystore("noenclave", &ENCLAVE_FILES);
        let e = env("true", "Enforce", root.to_str());
        let err = resolve(&e, Some("/tending/robot_9"), |_| {}).unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.contains("/tending/robot_9") && msg.contains("refusing"),
            "{msg}"
        );

        let root2 = fake_keystore("missing", &["cert.pem", "key.pem"]);
        let e = env("true", "Enforce", root2.to_str());
        let msg = resolve(&e, Some("/tending/robot_3"), |_| {})
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("permissions.p7s") && msg.contains("governance.p7s"),
            "{msg}"
        );
        assert!(!msg.contains("key.pem"), "{msg}");
        std::fs::remove_dir_all(root).unwrap();
        std::fs::remove_dir_all(root2).unwrap();
    }

    #[test]
    fn permissive_falls_back_to_off_with_a_warning() {
        let mut warned = String::new();
        let r = resolve(&env("true", "Permissive", None), Some("/a"), |m| {
            warned = m.to_string()
        });
        assert_eq!(r, Ok(Security::Off));
        assert!(warned.contains("WITHOUT security"), "{warned}");
    }

    #[test]
    fn the_override_wins_over_the_argument_and_a_complete_enclave_is_used() {
        let root = fake_keystore("ok", &ENCLAVE_FILES);
        let mut e = env("true", "Enforce", root.to_str());
        e.enclave_override = Some("/tending/robot_3".into());
        let r = resolve(&e, Some("/tending/robot_9"), |_| {}).unwrap();
        assert_eq!(
            r,
            Security::Enclave {
                enclave: "/tending/robot_3".into(),
                dir: root.join("enclaves/tending/robot_3"),
            }
        );
        let bad = resolve(&e, None, |_| {});
        assert!(bad.is_ok());
        e.enclave_override = Some("tending/../x".into());
        assert_eq!(
            resolve(&e, None, |_| {}),
            Err(SecurityError::BadName("tending/../x".into()))
        );
        std::fs::remove_dir_all(root).unwrap();
    }
}
