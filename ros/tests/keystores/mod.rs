//! Keystores for the security tests (ros/tests/security.rs, cyclone.rs,
//! cyclone_refusals.rs): a fleet's, and a stolen identity with forged permissions that
//! the fleet must keep out.

#![allow(dead_code)] // each test binary uses its own part

use std::path::PathBuf;

use keystore::{Keystore, Role, Validity};

/// A fresh keystore in the temp directory (`tending-{prefix}-{name}-{pid}`) with enclaves
/// for robot_0 and robot_1, valid for a day; returns its root and the keystore.
pub fn fleet(prefix: &str, name: &str) -> (PathBuf, Keystore) {
    let root = std::env::temp_dir().join(format!("tending-{prefix}-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let ks = Keystore::create(&root).unwrap();
    ks.create_fleet_enclaves(
        &["robot_0".into(), "robot_1".into()],
        Validity::days_from_now(1),
    )
    .unwrap();
    (root, ks)
}

/// `victim`'s identity (certificate, key and identity CA from `fleet`) in an enclave of
/// `forger`'s keystore, whose own permissions CA signed permissions for `robots`:
/// everything in it verifies locally, but the fleet's permissions CA did not sign it.
pub fn stolen_identity(
    fleet: &Keystore,
    forger: &Keystore,
    victim: &str,
    robots: &[&str],
) -> PathBuf {
    let forged = forger
        .create_enclave(
            victim,
            &Role::Robots(robots.iter().map(|r| r.to_string()).collect()),
            Validity::days_from_now(1),
        )
        .unwrap();
    let real = fleet.enclave_dir(victim);
    for f in ["cert.pem", "key.pem", "identity_ca.cert.pem"] {
        std::fs::copy(real.join(f), forged.join(f)).unwrap();
    }
    forged
}
