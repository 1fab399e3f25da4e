//
// DDS Security spec v1.1
//
// Section "9.4.1.1 Permissions CA Certificate
//
// This is an X.509 certificate that contains the Public Key of the CA that will
// be used to sign the Domain Governance and Domain Permissions document. The
// certificate can be self-signed or signed by some other CA. Regardless of
// this the Public Key in the Certificate shall be trusted to sign the
// aforementioned Governance and Permissions documents (see 9.4.1.2 and
// 9.4.1.3). The Permissions CA Certificate shall be provided to the plugins
// using the PropertyQosPolicy on the DomainParticipantQos as specified in
// Table 56."
//

// So this type is to be used to verify both Domain Governance and Domain
// Permissions documents. The verification of the two can use the same or
// different Certificate instances.

#[allow(unused_imports)]
use log::{debug, error, info, trace, warn};
use bytes::Bytes;
use x509_certificate::{
  certificate::CapturedX509Certificate, EcdsaCurve, KeyAlgorithm, SignatureAlgorithm,
};
use der::{Decode, DecodePem, Encode};
use bcder::{encode::Values, Mode};
use x509_cert::{crl::CertificateList, time::Time};

use crate::security::{
  authentication::authentication_builtin::types::{
    CertificateAlgorithm, ECDSA_SIGNATURE_ALGO_NAME, RSA_2048_KEY_LENGTH, RSA_SIGNATURE_ALGO_NAME,
  },
  config::{to_config_error_other, to_config_error_parse, ConfigError},
  types::{security_error, SecurityResult},
};

// This is mostly a wrapper around
// x509_certificate::certificate::CapturedX509Certificate
// so that we can keep track of what operations we use.
#[derive(Clone, Debug)]
pub struct Certificate {
  cert: CapturedX509Certificate,
  subject_name: DistinguishedName,
  // Kept for the validity-period and revocation checks (RFC 5280 6.1.3 (a)(2), (a)(3)).
  serial_number: Vec<u8>,
  not_before: Time,
  not_after: Time,
}

impl Certificate {
  pub fn from_pem(pem_data: impl AsRef<[u8]>) -> Result<Self, ConfigError> {
    let cert = CapturedX509Certificate::from_pem(pem_data)
      .map_err(to_config_error_parse("Cannot read X.509 Certificate"))?;

    let other_cert = x509_cert::certificate::Certificate::from_der(cert.constructed_data())
      .map_err(to_config_error_parse("Cannot read X.509 Certificate(2)"))?;

    let tbs = other_cert.tbs_certificate();
    let subject_name = tbs.subject().clone().into();
    let serial_number = tbs.serial_number().as_bytes().to_vec();
    let validity = tbs.validity();

    Ok(Certificate {
      cert,
      subject_name,
      serial_number,
      not_before: validity.not_before,
      not_after: validity.not_after,
    })
  }

  /// The serial number (the DER INTEGER's content bytes).
  pub fn serial_number(&self) -> &[u8] {
    &self.serial_number
  }

  /// Fails unless `now` is within the certificate's validity period
  /// (notBefore <= now <= notAfter, RFC 5280 4.1.2.5). DDS Security v1.1 9.3.2.1
  /// requires the identity certificate to be valid; an expired or not yet valid
  /// certificate must not authenticate.
  pub fn check_validity_period(&self, now: SystemTime) -> SecurityResult<()> {
    let now_unix = now.duration_since(UNIX_EPOCH).unwrap_or_default();
    if now_unix < self.not_before.to_unix_duration() {
      Err(security_error(&format!(
        "Certificate '{}' is not valid yet: its validity starts at {} (notBefore)",
        self.subject_name, self.not_before
      )))
    } else if now_unix > self.not_after.to_unix_duration() {
      Err(security_error(&format!(
        "Certificate '{}' has expired: its validity ended at {} (notAfter)",
        self.subject_name, self.not_after
      )))
    } else {
      Ok(())
    }
  }

  pub fn to_pem(&self) -> String {
    self.cert.encode_pem()
  }

  // public key algorithm
  pub fn key_algorithm(&self) -> Option<x509_certificate::KeyAlgorithm> {
    self.cert.key_algorithm()
  }

  // name of the signature algoritm as a byte string accrding to Table 49
  // in DDS Security Spec v1.1 Section "9.3.2.5.1 HandshakeRequestMessageToken
  // objects"
  pub fn signature_algorithm_identifier(&self) -> SecurityResult<Bytes> {
    match self.cert.signature_algorithm() {
      None => Err(security_error(
        "Certificate has no known signature algorithm?!",
      )),
      Some(SignatureAlgorithm::RsaSha256) => Ok(Bytes::from_static(RSA_SIGNATURE_ALGO_NAME)),
      Some(SignatureAlgorithm::EcdsaSha256) => Ok(Bytes::from_static(ECDSA_SIGNATURE_ALGO_NAME)),
      Some(x) => Err(security_error(&format!(
        "Certificate has out-of-spec signature algorithm {x:?}"
      ))),
    }
  }

  pub fn subject_name(&self) -> &DistinguishedName {
    &self.subject_name
  }

  pub fn subject_name_der(&self) -> Result<Vec<u8>, ConfigError> {
    let er = &self.cert.subject_name().encode_ref();
    let mut buf = Vec::with_capacity(er.encoded_len(Mode::Der));
    er.write_encoded(Mode::Der, &mut buf)
      .map_err(to_config_error_other(
        "Cannot extract subject_name DER encoding",
      ))?;
    Ok(buf)
  }

  pub(super) fn algorithm(&self) -> Option<CertificateAlgorithm> {
    let key_algorithm = &self.cert.key_algorithm();
    match key_algorithm {
      Some(KeyAlgorithm::Rsa) => {
        let key_length = self.cert.public_key_data().len();
        if key_length == RSA_2048_KEY_LENGTH {
          Some(CertificateAlgorithm::RSA2048)
        } else {
          log::error!("Wrong RSA key length: expected {RSA_2048_KEY_LENGTH}, got {key_length}");
          None
        }
      }
      Some(KeyAlgorithm::Ecdsa(EcdsaCurve::Secp256r1)) => Some(CertificateAlgorithm::ECPrime256v1),
      _ => {
        log::error!("Unknown key algorithm. cert.key_algorithm returned {key_algorithm:?}");
        None
      }
    }
  }

  pub fn verify_signed_data_with_algorithm(
    &self,
    signed_data: impl AsRef<[u8]>,
    signature: impl AsRef<[u8]>,
    verify_algorithm: &'static dyn ring::signature::VerificationAlgorithm,
  ) -> SecurityResult<()> {
    self
      .cert
      .verify_signed_data_with_algorithm(signed_data, signature, verify_algorithm)
      .map_err(|e| security_error(&format!("Signature verification failure: {e:?}")))
  }

  // Verify that `self` was signed by `other` Certificate
  // e.g.
  // `someones_identity.verify_signed_by_certificate( certificate_authority )`
  //
  pub fn verify_signed_by_certificate(&self, other: &Certificate) -> SecurityResult<()> {
    self
      .cert
      .verify_signed_by_certificate(&other.cert)
      .map_err(|e| {
        security_error(&format!(
          "Certificate signature verification failure: {e:?}"
        ))
      })
  }
}

// This represents X.501 Distinguished Name
//
// See https://datatracker.ietf.org/doc/html/rfc4514
//
// It is supposed to be a structured type of key-value-mappings,
// but for simplicity, we treat it just as a string for time being.
// It is needs to process "Subject Name" and "Issuer Name" in
// X.509 Certificates.
//
// Structured representation would allow standards-compliant
// equality comparison (`.matches()`) according to
// https://datatracker.ietf.org/doc/html/rfc5280#section-7.1
//
// TODO: Implement the structured format and matching.
#[derive(Debug, Clone)]
pub struct DistinguishedName(x509_cert::name::DistinguishedName);
impl DistinguishedName {
  pub fn parse(s: &str) -> Result<DistinguishedName, ConfigError> {
    x509_cert::name::DistinguishedName::from_str(s)
      .map(DistinguishedName)
      .map_err(|e| ConfigError::Parse(format!("Error parsing DistinguishedName: {e:?}")))
  }

  pub fn serialize(&self) -> String {
    // This returns the RFC 4514 Distinguished Name string representation
    self.0.to_string()
  }

  // TODO is this a too strict equivalence?
  pub fn matches(&self, other: &Self) -> bool {
    self.0 == other.0
  }
}

// This conversion should be non-fallible?
impl From<x509_cert::name::Name> for DistinguishedName {
  fn from(name: x509_cert::name::Name) -> DistinguishedName {
    DistinguishedName(name.into())
  }
}

use std::{
  fmt,
  str::FromStr,
  time::{SystemTime, UNIX_EPOCH},
};

// ecdsa-with-SHA256 (RFC 5758 3.2) and sha256WithRSAEncryption (RFC 4055 5): the
// signature algorithms of the builtin PKI-DH plugin's certificates (Table 49).
const OID_ECDSA_WITH_SHA256: &str = "1.2.840.10045.4.3.2";
const OID_SHA256_WITH_RSA: &str = "1.2.840.113549.1.1.11";

/// A certificate revocation list (X.509 CRL, RFC 5280 5) issued by the identity CA.
///
/// DDS Security v1.1 leaves revocation to the implementation (9.3.2.1: "should also
/// check ... revoked"); Connext reads a CRL from the `dds.sec.auth.crl` participant
/// property, Fast DDS from `dds.sec.auth.builtin.PKI-DH.identity_crl` (which ROS 2's
/// rmw sets when an enclave holds `crl.pem`). This is that file, checked against the
/// CA: a CRL that does not verify is a configuration error, not an empty list.
#[derive(Clone, Debug)]
pub struct RevocationList {
  revoked: Vec<Vec<u8>>,
}

impl RevocationList {
  /// Parse a PEM CRL and verify that `issuer` (the identity CA) signed it.
  pub fn from_pem(pem_data: impl AsRef<[u8]>, issuer: &Certificate) -> Result<Self, ConfigError> {
    let crl = CertificateList::<x509_cert::certificate::Rfc5280>::from_pem(pem_data.as_ref())
      .map_err(to_config_error_parse("Cannot read X.509 CRL"))?;
    let tbs = &crl.tbs_cert_list;
    let crl_issuer = DistinguishedName::from(tbs.issuer.clone());
    if !crl_issuer.matches(issuer.subject_name()) {
      return Err(ConfigError::Security(format!(
        "CRL is issued by '{crl_issuer}', not by the identity CA '{}'",
        issuer.subject_name()
      )));
    }
    let algorithm: &'static dyn ring::signature::VerificationAlgorithm =
      match crl.signature_algorithm.oid.to_string().as_str() {
        OID_ECDSA_WITH_SHA256 => &ring::signature::ECDSA_P256_SHA256_ASN1,
        OID_SHA256_WITH_RSA => &ring::signature::RSA_PKCS1_2048_8192_SHA256,
        other => {
          return Err(ConfigError::Security(format!(
            "CRL signature algorithm {other} is not supported (expected ECDSA or RSA with \
             SHA-256)"
          )))
        }
      };
    // DER is canonical, so re-encoding the parsed TBSCertList gives the signed bytes.
    let signed = tbs
      .to_der()
      .map_err(to_config_error_parse("Cannot encode the CRL's TBSCertList"))?;
    let signature = crl
      .signature
      .as_bytes()
      .ok_or_else(|| ConfigError::Parse("CRL signature is not a whole number of bytes".into()))?;
    issuer
      .verify_signed_data_with_algorithm(signed, signature, algorithm)
      .map_err(|e| {
        ConfigError::Security(format!("CRL is not signed by the identity CA: {}", e.msg))
      })?;
    if let Some(next) = tbs.next_update {
      if SystemTime::now() > next.to_system_time() {
        // Still applied: an old list of revoked certificates is better than none.
        warn!("CRL's nextUpdate {next} has passed; using it anyway");
      }
    }
    let revoked = tbs
      .revoked_certificates
      .iter()
      .flatten()
      .map(|r| r.serial_number.as_bytes().to_vec())
      .collect();
    Ok(RevocationList { revoked })
  }

  /// Fails if `cert` (issued by this list's CA) is revoked.
  pub fn check_not_revoked(&self, cert: &Certificate) -> SecurityResult<()> {
    if self.revoked.iter().any(|s| s == cert.serial_number()) {
      Err(security_error(&format!(
        "Certificate '{}' (serial {}) is revoked by the CRL",
        cert.subject_name(),
        hex(cert.serial_number())
      )))
    } else {
      Ok(())
    }
  }

  /// How many certificates the list revokes.
  pub fn revoked_count(&self) -> usize {
    self.revoked.len()
  }
}

fn hex(bytes: &[u8]) -> String {
  bytes.iter().map(|b| format!("{b:02x}")).collect()
}

impl fmt::Display for DistinguishedName {
  fn fmt(&self, f: &mut fmt::Formatter<'_>) -> Result<(), fmt::Error> {
    write!(f, "{}", self.serialize())
  }
}

#[cfg(test)]
mod tests {
  use super::*;

  #[test]
  pub fn parse_example() {
    let cert_pem = r#"-----BEGIN CERTIFICATE-----
MIIBOzCB4qADAgECAhR361786/qVPfJWWDw4Wg5cmJUwBTAKBggqhkjOPQQDAjAS
MRAwDgYDVQQDDAdzcm9zMkNBMB4XDTIzMDcyMzA4MjgzNloXDTMzMDcyMTA4Mjgz
NlowEjEQMA4GA1UEAwwHc3JvczJDQTBZMBMGByqGSM49AgEGCCqGSM49AwEHA0IA
BMpvJQ/91ZqnmRRteTL2qaEFz2d7SGAQQk9PIhhZCV1tlLwYf/hI4xWLJaEv8FxJ
TjxXRGJ1U+/IqqqIvJVpWaSjFjAUMBIGA1UdEwEB/wQIMAYBAf8CAQEwCgYIKoZI
zj0EAwIDSAAwRQIgEiyVGRc664+/TE/HImA4WNwsSi/alHqPYB58BWINj34CIQDD
iHhbVPRB9Uxts9CwglxYgZoUdGUAxreYIIaLO4yLqw==
-----END CERTIFICATE-----
"#;

    let cert = Certificate::from_pem(cert_pem).unwrap();

    println!("{cert:?}");
  }
}
