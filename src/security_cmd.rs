//! `tending security`: DDS Security keystores in the SROS2 layout (the `keystore` crate).
//!
//! ```text
//! tending security create KEYSTORE [--robots robot_0,robot_1 | --fleet N] [--days D]
//! tending security enclave KEYSTORE /tending/robot_7 --role robots:robot_7 [--days D]
//! tending security revoke KEYSTORE /tending/robot_7
//! tending security list KEYSTORE
//! ```
//!
//! Then run a node with `ROS_SECURITY_KEYSTORE=KEYSTORE ROS_SECURITY_ENABLE=true
//! ROS_SECURITY_STRATEGY=Enforce robot_node --ros-args --enclave /tending/robot_3 ...`
//! (or `tending fleet --secure`, which does all of it).

use std::path::PathBuf;

use anyhow::Result;
use clap::{Args, Subcommand};
use keystore::{Keystore, Role, Validity};

#[derive(Args)]
pub struct SecurityArgs {
    #[command(subcommand)]
    cmd: SecurityCmd,
}

#[derive(Subcommand)]
enum SecurityCmd {
    /// Create a keystore: a CA, the signed governance, and the fleet's enclaves
    /// (/tending/sim_bridge, /tending/recorder, /tending/player, /tending/<robot> each).
    Create {
        keystore: PathBuf,
        /// Robot namespaces to create enclaves for (comma-separated).
        #[arg(long, value_delimiter = ',', conflicts_with = "fleet")]
        robots: Vec<String>,
        /// Enclaves for robot_0 .. robot_{N-1}.
        #[arg(long)]
        fleet: Option<usize>,
        /// Validity of the identities and permissions, days.
        #[arg(long, default_value_t = keystore::DEFAULT_VALIDITY_DAYS)]
        days: i64,
    },
    /// Create (or replace) one enclave with a role: bridge, recorder, player or
    /// robots:NAME[,NAME...] (may publish only those robots' cmd_vel).
    Enclave {
        keystore: PathBuf,
        /// Enclave name, e.g. /tending/robot_7.
        name: String,
        #[arg(long, value_parser = Role::parse)]
        role: Role,
        #[arg(long, default_value_t = keystore::DEFAULT_VALIDITY_DAYS)]
        days: i64,
    },
    /// Revoke an enclave's identity: the CA's revocation list (public/crl.pem), copied
    /// into every enclave as crl.pem.
    Revoke { keystore: PathBuf, name: String },
    /// List the enclaves of a keystore.
    List { keystore: PathBuf },
}

fn check_days(days: i64) -> Result<Validity> {
    anyhow::ensure!(days > 0, "--days {days}: must be at least 1");
    Ok(Validity::days_from_now(days))
}

pub fn run(a: SecurityArgs) -> Result<()> {
    match a.cmd {
        SecurityCmd::Create {
            keystore,
            robots,
            fleet,
            days,
        } => {
            let v = check_days(days)?;
            let robots: Vec<String> = match fleet {
                Some(n) => (0..n).map(|i| format!("robot_{i}")).collect(),
                None => robots,
            };
            for r in &robots {
                Role::parse(&format!("robots:{r}")).map_err(anyhow::Error::msg)?;
            }
            let ks = Keystore::create(&keystore)?;
            ks.create_fleet_enclaves(&robots, v)?;
            println!(
                "keystore {}: CA, governance and {} enclaves",
                keystore.display(),
                ks.enclave_dirs()?.len()
            );
            Ok(())
        }
        SecurityCmd::Enclave {
            keystore,
            name,
            role,
            days,
        } => {
            let dir = Keystore::open(&keystore)?.create_enclave(&name, &role, check_days(days)?)?;
            println!("enclave {name}: {}", dir.display());
            Ok(())
        }
        SecurityCmd::Revoke { keystore, name } => {
            Keystore::open(&keystore)?.revoke(&name)?;
            println!("revoked {name}: {}/public/crl.pem", keystore.display());
            Ok(())
        }
        SecurityCmd::List { keystore } => {
            let ks = Keystore::open(&keystore)?;
            for d in ks.enclave_dirs()? {
                let rel = d.strip_prefix(ks.root().join("enclaves")).unwrap_or(&d);
                println!("/{}", rel.display());
            }
            Ok(())
        }
    }
}
