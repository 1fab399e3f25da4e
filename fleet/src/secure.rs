//! `tending fleet --secure`: the keystore, each process's enclave, and the ROS 2 security
//! environment of the children (docs/adr/0013-dds-security.md).

use std::path::Path;
use std::process::Command;

use anyhow::{Context as _, Result};
use keystore::{Keystore, Role, Validity};

/// The keystore at `root`: opened if there is one, else created; with the bridge's,
/// recorder's and player's enclaves.
pub(super) fn keystore(root: &Path) -> Result<Keystore> {
    let ks = if root.join("public/ca.cert.pem").is_file() {
        Keystore::open(root)?
    } else {
        Keystore::create(root)?
    };
    let v = Validity::days_from_now(keystore::DEFAULT_VALIDITY_DAYS);
    for (name, role) in [
        (keystore::BRIDGE_ENCLAVE, Role::Bridge),
        (keystore::RECORDER_ENCLAVE, Role::Recorder),
        (keystore::PLAYER_ENCLAVE, Role::Player),
    ] {
        ensure(&ks, name, &role, v)?;
    }
    Ok(ks)
}

fn ensure(ks: &Keystore, name: &str, role: &Role, v: Validity) -> Result<()> {
    if !ks.enclave_dir(name).join("permissions.p7s").is_file() {
        ks.create_enclave(name, role, v)
            .with_context(|| format!("creating enclave {name} in {}", ks.root().display()))?;
    }
    Ok(())
}

/// The enclave of a robot_node process hosting `robots`: `/tending/robot_3` for one
/// robot, `/tending/robot_0_to_robot_24` for a group (allowed their cmd_vel only);
/// created if missing (a robot added live gets one on the spot).
pub(super) fn robots_enclave(ks: &Keystore, robots: &[String]) -> Result<String> {
    let name = match robots {
        [one] => keystore::robot_enclave(one),
        [first, .., last] => keystore::robot_enclave(&format!("{first}_to_{last}")),
        [] => anyhow::bail!("a robot process with no robots"),
    };
    let v = Validity::days_from_now(keystore::DEFAULT_VALIDITY_DAYS);
    ensure(ks, &name, &Role::Robots(robots.to_vec()), v)?;
    Ok(name)
}

/// ROS 2 security for a child: its enclave (`--enclave`, after its `--ros-args`) in `ks`,
/// enforced.
pub(super) fn env(c: &mut Command, ks: &Keystore, enclave: &str) {
    c.env("ROS_SECURITY_KEYSTORE", ks.root())
        .env("ROS_SECURITY_ENABLE", "true")
        .env("ROS_SECURITY_STRATEGY", "Enforce")
        .env_remove("ROS_SECURITY_ENCLAVE_OVERRIDE")
        .args(["--enclave", enclave]);
}
