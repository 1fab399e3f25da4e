//! S/MIME (PKCS#7 detached, multipart/signed) signing, as `openssl smime -sign -text`:
//! the form DDS Security expects for governance and permissions documents.

use anyhow::{Context as _, Result};
use openssl::pkcs7::{Pkcs7, Pkcs7Flags};
use openssl::pkey::PKey;
use openssl::stack::Stack;
use openssl::x509::X509;

/// Sign `doc` with the CA (`cert_pem`, `key_pem`); returns the S/MIME text.
pub fn sign(doc: &[u8], cert_pem: &str, key_pem: &str) -> Result<String> {
    let cert = X509::from_pem(cert_pem.as_bytes()).context("CA certificate")?;
    let key = PKey::private_key_from_pem(key_pem.as_bytes()).context("CA private key")?;
    let flags = Pkcs7Flags::DETACHED | Pkcs7Flags::TEXT;
    let extra: Stack<X509> = Stack::new()?;
    let p7 = Pkcs7::sign(&cert, &key, &extra, doc, flags).context("PKCS#7 sign")?;
    let smime = p7.to_smime(doc, flags).context("S/MIME encode")?;
    String::from_utf8(smime).context("S/MIME output is not text")
}

/// Verify an S/MIME document against `ca`; returns the signed content. (Tests and
/// `tending security` checks; the DDS side verifies with rustdds's own parser.)
#[cfg(test)]
pub fn verify(smime: &[u8], ca: &X509) -> Result<Vec<u8>> {
    use openssl::x509::store::X509StoreBuilder;
    let (p7, content) = Pkcs7::from_smime(smime).context("S/MIME parse")?;
    let mut store = X509StoreBuilder::new()?;
    store.add_cert(ca.clone())?;
    let store = store.build();
    let mut out = Vec::new();
    let certs: Stack<X509> = Stack::new()?;
    p7.verify(
        &certs,
        &store,
        content.as_deref(),
        Some(&mut out),
        Pkcs7Flags::TEXT,
    )
    .context("S/MIME signature")?;
    Ok(out)
}
