//! DDS Security keystores in the SROS2 layout (what `ros2 security create_keystore` and
//! `create_enclave` write), so that ROS 2 tooling and our nodes read the same files:
//!
//! ```text
//! KEYSTORE/public/ca.cert.pem             the CA (identity and permissions CA at once)
//!         /public/identity_ca.cert.pem, permissions_ca.cert.pem   copies of it
//!         /public/crl.pem                 revoked identities (after `revoke`)
//!         /private/ca.key.pem             the CA's key (keep it off the robots)
//!         /enclaves/governance.xml, governance.p7s
//!         /enclaves/<enclave>/cert.pem key.pem identity_ca.cert.pem permissions_ca.cert.pem
//!                             governance.p7s permissions.xml permissions.p7s [crl.pem]
//! ```
//!
//! Keys are ECDSA P-256 (the builtin PKI-DH plugin accepts P-256 and RSA-2048); the
//! identity certificate's subject is `CN=<enclave>`, which the permissions grant names.
//! Certificates and CRLs come from rcgen, S/MIME signatures from OpenSSL (as
//! `openssl smime -sign -text`, what SROS2 does).

pub mod documents;
pub mod policy;
mod smime;

use std::fs;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context as _, Result};
use rcgen::{
    BasicConstraints, CertificateParams, CertificateRevocationListParams, DnType, IsCa, KeyPair,
    KeyUsagePurpose, RevokedCertParams, SerialNumber,
};
use time::{Duration, OffsetDateTime};

pub use policy::{Grant, Role};

pub use msgs::enclave::FILES as ENCLAVE_FILES;

/// How long a new identity and its permissions are valid (SROS2 uses ten years).
pub const DEFAULT_VALIDITY_DAYS: i64 = 3650;

/// A keystore directory.
#[derive(Debug, Clone)]
pub struct Keystore {
    root: PathBuf,
}

/// When an enclave's identity and permissions are valid.
#[derive(Debug, Clone, Copy)]
pub struct Validity {
    pub not_before: OffsetDateTime,
    pub not_after: OffsetDateTime,
}

impl Validity {
    /// From an hour ago (clocks of a fleet differ a little) for `days` days.
    pub fn days_from_now(days: i64) -> Self {
        let now = OffsetDateTime::now_utc();
        Self {
            not_before: now - Duration::hours(1),
            not_after: now + Duration::days(days),
        }
    }
}

fn write(path: &Path, text: &str) -> Result<()> {
    fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))
}

fn read(path: &Path) -> Result<String> {
    fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))
}

fn random_serial() -> SerialNumber {
    let mut b = [0u8; 16];
    openssl::rand::rand_bytes(&mut b).expect("OpenSSL random bytes");
    b[0] &= 0x7f; // positive
    b[0] |= 0x01; // and no leading zero byte (DER minimal)
    SerialNumber::from_slice(&b)
}

/// Check an enclave name: absolute, ROS name segments (`/tending/robot_3`).
pub fn check_enclave_name(name: &str) -> Result<()> {
    let ok = name.starts_with('/')
        && name.len() > 1
        && name[1..].split('/').all(|s| {
            !s.is_empty()
                && (s.as_bytes()[0].is_ascii_alphabetic() || s.as_bytes()[0] == b'_')
                && s.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_')
        });
    if !ok {
        bail!("enclave name `{name}`: expected an absolute ROS name like /tending/robot_3");
    }
    Ok(())
}

impl Keystore {
    /// Create a keystore at `root` (which must not hold one yet): a fresh CA and the
    /// signed governance document.
    pub fn create(root: impl AsRef<Path>) -> Result<Self> {
        let ks = Self {
            root: root.as_ref().to_path_buf(),
        };
        if ks.ca_cert_path().exists() {
            bail!(
                "keystore {}: already exists (public/ca.cert.pem is there)",
                ks.root.display()
            );
        }
        for d in ["public", "private", "enclaves"] {
            let p = ks.root.join(d);
            fs::create_dir_all(&p).with_context(|| format!("cannot create {}", p.display()))?;
        }
        let key = KeyPair::generate_for(&rcgen::PKCS_ECDSA_P256_SHA256)?;
        let mut p = CertificateParams::default();
        p.distinguished_name = rcgen::DistinguishedName::new();
        p.distinguished_name
            .push(DnType::CommonName, "tending keystore CA");
        p.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
        p.key_usages = vec![
            KeyUsagePurpose::KeyCertSign,
            KeyUsagePurpose::CrlSign,
            KeyUsagePurpose::DigitalSignature,
        ];
        let v = Validity::days_from_now(DEFAULT_VALIDITY_DAYS);
        p.not_before = v.not_before;
        p.not_after = v.not_after;
        p.serial_number = Some(random_serial());
        let cert = p.self_signed(&key)?;
        write(&ks.ca_cert_path(), &cert.pem())?;
        for copy in ["identity_ca.cert.pem", "permissions_ca.cert.pem"] {
            write(&ks.root.join("public").join(copy), &cert.pem())?;
        }
        let key_path = ks.root.join("private/ca.key.pem");
        write(&key_path, &key.serialize_pem())?;
        restrict(&key_path)?;

        let gov = documents::governance_xml();
        write(&ks.root.join("enclaves/governance.xml"), &gov)?;
        let signed = smime::sign(gov.as_bytes(), &cert.pem(), &key.serialize_pem())?;
        write(&ks.root.join("enclaves/governance.p7s"), &signed)?;
        Ok(ks)
    }

    /// An existing keystore at `root`.
    pub fn open(root: impl AsRef<Path>) -> Result<Self> {
        let ks = Self {
            root: root.as_ref().to_path_buf(),
        };
        for f in ["public/ca.cert.pem", "enclaves/governance.p7s"] {
            if !ks.root.join(f).is_file() {
                bail!(
                    "keystore {}: no {f} (create one with `tending security create`)",
                    ks.root.display()
                );
            }
        }
        Ok(ks)
    }

    pub fn root(&self) -> &Path {
        &self.root
    }

    fn ca_cert_path(&self) -> PathBuf {
        self.root.join("public/ca.cert.pem")
    }

    /// The directory of enclave `name` (`/tending/robot_3` -> `enclaves/tending/robot_3`).
    pub fn enclave_dir(&self, name: &str) -> PathBuf {
        msgs::enclave::dir(&self.root, name)
    }

    /// The CA as rcgen signs with it (params rebuilt from the stored certificate; only its
    /// subject and key matter for issuing).
    fn ca(&self) -> Result<(rcgen::Certificate, KeyPair, String)> {
        let key_path = self.root.join("private/ca.key.pem");
        let key_pem = read(&key_path)?;
        let key = KeyPair::from_pem(&key_pem)
            .with_context(|| format!("{}: not a private key", key_path.display()))?;
        let cert_pem = read(&self.ca_cert_path())?;
        let params = CertificateParams::from_ca_cert_pem(&cert_pem)
            .with_context(|| format!("{}: not a CA certificate", self.ca_cert_path().display()))?;
        let cert = params.self_signed(&key)?;
        Ok((cert, key, key_pem))
    }

    /// Create (or replace) enclave `name` with `role`'s permissions, valid over `validity`.
    pub fn create_enclave(&self, name: &str, role: &Role, validity: Validity) -> Result<PathBuf> {
        self.create_enclave_with_grant(name, &role.grant(), validity)
    }

    /// Create (or replace) enclave `name` allowed exactly `grant` (tools and benchmarks
    /// whose topics are not a fleet role's), valid over `validity`.
    pub fn create_enclave_with_grant(
        &self,
        name: &str,
        grant: &Grant,
        validity: Validity,
    ) -> Result<PathBuf> {
        check_enclave_name(name)?;
        let (ca, ca_key, ca_key_pem) = self.ca()?;
        let ca_pem = read(&self.ca_cert_path())?;
        let dir = self.enclave_dir(name);
        fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;

        let key = KeyPair::generate_for(&rcgen::PKCS_ECDSA_P256_SHA256)?;
        let mut p = CertificateParams::default();
        p.distinguished_name = rcgen::DistinguishedName::new();
        p.distinguished_name.push(DnType::CommonName, name);
        p.key_usages = vec![KeyUsagePurpose::DigitalSignature];
        p.not_before = validity.not_before;
        p.not_after = validity.not_after;
        p.serial_number = Some(random_serial());
        p.use_authority_key_identifier_extension = true;
        let cert = p.signed_by(&key, &ca, &ca_key)?;
        write(&dir.join("cert.pem"), &cert.pem())?;
        write(&dir.join("key.pem"), &key.serialize_pem())?;
        restrict(&dir.join("key.pem"))?;
        write(&dir.join("identity_ca.cert.pem"), &ca_pem)?;
        write(&dir.join("permissions_ca.cert.pem"), &ca_pem)?;
        fs::copy(
            self.root.join("enclaves/governance.p7s"),
            dir.join("governance.p7s"),
        )
        .with_context(|| format!("cannot copy governance.p7s into {}", dir.display()))?;

        let xml = documents::permissions_xml(
            name,
            &format!("CN={name}"),
            validity.not_before,
            validity.not_after,
            grant,
        );
        write(&dir.join("permissions.xml"), &xml)?;
        let signed = smime::sign(xml.as_bytes(), &ca_pem, &ca_key_pem)?;
        write(&dir.join("permissions.p7s"), &signed)?;
        let crl = self.root.join("public/crl.pem");
        if crl.is_file() {
            fs::copy(&crl, dir.join("crl.pem"))
                .with_context(|| format!("cannot copy crl.pem into {}", dir.display()))?;
        }
        Ok(dir)
    }

    /// Revoke enclave `name`'s identity certificate: add it to the CA's revocation list
    /// (`public/crl.pem`) and copy the list into every enclave (as `crl.pem`).
    pub fn revoke(&self, name: &str) -> Result<()> {
        check_enclave_name(name)?;
        let cert_path = self.enclave_dir(name).join("cert.pem");
        let serial = serial_of(&read(&cert_path)?)
            .with_context(|| format!("{}: cannot read its serial number", cert_path.display()))?;
        let crl_path = self.root.join("public/crl.pem");
        let mut revoked = if crl_path.is_file() {
            revoked_serials(&read(&crl_path)?)
                .with_context(|| format!("{}: not a CRL", crl_path.display()))?
        } else {
            Vec::new()
        };
        if !revoked.contains(&serial) {
            revoked.push(serial);
        }
        let (ca, ca_key, _) = self.ca()?;
        let now = OffsetDateTime::now_utc();
        let crl = CertificateRevocationListParams {
            this_update: now - Duration::minutes(5),
            next_update: now + Duration::days(DEFAULT_VALIDITY_DAYS),
            crl_number: random_serial(),
            issuing_distribution_point: None,
            revoked_certs: revoked
                .iter()
                .map(|s| RevokedCertParams {
                    serial_number: SerialNumber::from_slice(s),
                    revocation_time: now - Duration::minutes(5),
                    reason_code: Some(rcgen::RevocationReason::KeyCompromise),
                    invalidity_date: None,
                })
                .collect(),
            key_identifier_method: ca.params().key_identifier_method.clone(),
        }
        .signed_by(&ca, &ca_key)?;
        let pem = crl.pem()?;
        write(&crl_path, &pem)?;
        for dir in self.enclave_dirs()? {
            write(&dir.join("crl.pem"), &pem)?;
        }
        Ok(())
    }

    /// Every enclave directory (one holding a cert.pem) under `enclaves/`.
    pub fn enclave_dirs(&self) -> Result<Vec<PathBuf>> {
        let mut out = Vec::new();
        let mut stack = vec![self.root.join("enclaves")];
        while let Some(d) = stack.pop() {
            for e in fs::read_dir(&d).with_context(|| format!("cannot list {}", d.display()))? {
                let p = e?.path();
                if p.is_dir() {
                    if p.join("cert.pem").is_file() {
                        out.push(p.clone());
                    }
                    stack.push(p);
                }
            }
        }
        out.sort();
        Ok(out)
    }

    /// A standard fleet's enclaves: `/tending/sim_bridge`, `/tending/recorder`,
    /// `/tending/player`, and `/tending/<robot>` for each robot.
    pub fn create_fleet_enclaves(&self, robots: &[String], validity: Validity) -> Result<()> {
        self.create_enclave(BRIDGE_ENCLAVE, &Role::Bridge, validity)?;
        self.create_enclave(RECORDER_ENCLAVE, &Role::Recorder, validity)?;
        self.create_enclave(PLAYER_ENCLAVE, &Role::Player, validity)?;
        for r in robots {
            self.create_enclave(&robot_enclave(r), &Role::Robots(vec![r.clone()]), validity)?;
        }
        Ok(())
    }
}

pub const BRIDGE_ENCLAVE: &str = "/tending/sim_bridge";
pub const RECORDER_ENCLAVE: &str = "/tending/recorder";
pub const PLAYER_ENCLAVE: &str = "/tending/player";

/// The enclave of robot `name` (a namespace without leading slash): `/tending/<name>`.
pub fn robot_enclave(name: &str) -> String {
    format!("/tending/{name}")
}

/// Only the owner reads a private key.
fn restrict(path: &Path) -> Result<()> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        fs::set_permissions(path, fs::Permissions::from_mode(0o600))
            .with_context(|| format!("cannot restrict {}", path.display()))?;
    }
    Ok(())
}

fn serial_of(cert_pem: &str) -> Result<Vec<u8>> {
    let c = openssl::x509::X509::from_pem(cert_pem.as_bytes())?;
    Ok(c.serial_number().to_bn()?.to_vec())
}

fn revoked_serials(crl_pem: &str) -> Result<Vec<Vec<u8>>> {
    let crl = openssl::x509::X509Crl::from_pem(crl_pem.as_bytes())?;
    let mut out = Vec::new();
    if let Some(list) = crl.get_revoked() {
        for r in list {
            out.push(r.serial_number().to_bn()?.to_vec());
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("tending-ks-{name}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&d);
        d
    }

    #[test]
    fn a_keystore_has_the_sros2_layout_and_its_signatures_verify() {
        let root = tmp("layout");
        let ks = Keystore::create(&root).unwrap();
        let dir = ks
            .create_enclave(
                "/tending/robot_3",
                &Role::Robots(vec!["robot_3".into()]),
                Validity::days_from_now(1),
            )
            .unwrap();
        for f in ENCLAVE_FILES {
            assert!(dir.join(f).is_file(), "{f} missing");
        }
        // The identity is issued by the CA, named after the enclave.
        let ca = openssl::x509::X509::from_pem(&fs::read(root.join("public/ca.cert.pem")).unwrap())
            .unwrap();
        let cert = openssl::x509::X509::from_pem(&fs::read(dir.join("cert.pem")).unwrap()).unwrap();
        assert!(cert.verify(&ca.public_key().unwrap()).unwrap());
        let cn = cert
            .subject_name()
            .entries_by_nid(openssl::nid::Nid::COMMONNAME)
            .next()
            .unwrap()
            .data()
            .to_string();
        assert_eq!(cn.unwrap(), "/tending/robot_3");
        // Both documents verify against the CA with OpenSSL and carry the XML.
        for doc in ["governance.p7s", "permissions.p7s"] {
            let text = smime::verify(&fs::read(dir.join(doc)).unwrap(), &ca).unwrap();
            assert!(String::from_utf8(text).unwrap().contains("<dds"), "{doc}");
        }
        // A changed byte breaks the permissions signature.
        let p = fs::read_to_string(dir.join("permissions.p7s")).unwrap();
        let tampered = p.replace("rt/robot_3/cmd_vel", "rt/robot_4/cmd_vel");
        assert_ne!(p, tampered);
        assert!(smime::verify(tampered.as_bytes(), &ca).is_err());
        fs::remove_dir_all(root).unwrap();
    }

    #[test]
    fn revoking_lists_the_serial_in_every_enclaves_crl() {
        let root = tmp("revoke");
        let ks = Keystore::create(&root).unwrap();
        let v = Validity::days_from_now(1);
        ks.create_fleet_enclaves(&["robot_0".into(), "robot_1".into()], v)
            .unwrap();
        ks.revoke("/tending/robot_1").unwrap();
        let serial =
            serial_of(&read(&ks.enclave_dir("/tending/robot_1").join("cert.pem")).unwrap())
                .unwrap();
        for d in ks.enclave_dirs().unwrap() {
            let revoked = revoked_serials(&read(&d.join("crl.pem")).unwrap()).unwrap();
            assert_eq!(revoked, vec![serial.clone()], "{}", d.display());
        }
        fs::remove_dir_all(root).unwrap();
    }

    #[test]
    fn bad_inputs_are_named() {
        let e = check_enclave_name("tending/robot").unwrap_err().to_string();
        assert!(e.contains("tending/robot"), "{e}");
        let e = Keystore::open("/nonexistent/ks").unwrap_err().to_string();
        assert!(e.contains("/nonexistent/ks"), "{e}");
        let root = tmp("twice");
        Keystore::create(&root).unwrap();
        let e = Keystore::create(&root).unwrap_err().to_string();
        assert!(e.contains("already exists"), "{e}");
        fs::remove_dir_all(root).unwrap();
    }
}
