//! The SROS2 keystore layout: what `keystore` writes and the `ros` runtime opens, so the
//! two (and ROS 2's own `ros2 security` tools) agree on it.

use std::path::{Path, PathBuf};

/// The files an enclave directory must hold (rmw_dds_common's required set); `crl.pem`
/// is optional.
pub const FILES: [&str; 6] = [
    "identity_ca.cert.pem",
    "cert.pem",
    "key.pem",
    "permissions_ca.cert.pem",
    "governance.p7s",
    "permissions.p7s",
];

/// The directory of enclave `name` in the keystore at `root`
/// (`/tending/robot_3` -> `root/enclaves/tending/robot_3`; `/` -> `root/enclaves`).
pub fn dir(root: &Path, name: &str) -> PathBuf {
    root.join("enclaves").join(name.trim_start_matches('/'))
}
