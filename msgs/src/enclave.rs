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

/// The highest domain id a keystore's governance and permissions cover (`0..=230`).
/// ROS allows `ROS_DOMAIN_ID` up to 232, but Cyclone DDS's access control refuses to
/// parse a document naming a domain above 230 ("Can not parse governance file", code 137;
/// 230 is its largest domain id), so the documents stop there to be read by every vendor;
/// a secure participant on 231 or 232 is refused at start.
pub const MAX_SECURE_DOMAIN: u16 = 230;

/// The directory of enclave `name` in the keystore at `root`
/// (`/tending/robot_3` -> `root/enclaves/tending/robot_3`; `/` -> `root/enclaves`).
pub fn dir(root: &Path, name: &str) -> PathBuf {
    root.join("enclaves").join(name.trim_start_matches('/'))
}
