//! A stolen identity with forged permissions, for the tests that check the fleet keeps
//! it out (ros/tests/security.rs against our participants, cyclone_refusals.rs with
//! Cyclone DDS holding it).

use std::path::PathBuf;

use keystore::{Keystore, Role, Validity};

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
