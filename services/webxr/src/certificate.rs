//! The certificate WebXR's secure context needs: made on first use (self-signed, for
//! `localhost` and this machine's addresses), kept in a folder for the next session so the
//! headset's browser, once told to trust it, is not asked again, and named by its SHA-256
//! fingerprint so the user can check what the browser shows. Its files are [`keyfile`]'s:
//! private, never written through a link, valid a year and made anew before they expire.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer};
use sha2::Digest;

use keyfile::{KeyFileError, PairStatus};

/// Why no certificate could be had.
#[derive(Debug, thiserror::Error)]
pub enum CertificateError {
    /// The folder, or the key's file: what to do is in the message ([`keyfile`]).
    #[error("{0}; or set [source] certificate_dir")]
    KeyFile(#[from] KeyFileError),
    #[error("{}: {problem}; delete the file to have a new certificate made", file.display())]
    Damaged { file: PathBuf, problem: String },
    #[error("the certificate is refused by TLS: {0}; delete certificate.pem and key.pem in its folder to have a new one made")]
    Tls(String),
}

/// A loaded certificate: the TLS server's configuration and what to tell the user.
pub struct Certificate {
    pub config: Arc<rustls::ServerConfig>,
    /// SHA-256 of the certificate (DER), as browsers show it: `AB:CD:...`.
    pub fingerprint: String,
    pub file: PathBuf,
    /// True when it was made now (the browser will ask to trust it).
    pub made: bool,
    /// Why it was made anew, when it was (expired, near expiry, made to last for ever).
    pub renewed: Option<String>,
    /// Days it is still valid, when kept.
    pub days_left: Option<u64>,
}

/// The default folder: `$XDG_DATA_HOME/handblocks/webxr`, or `~/.local/share/handblocks/webxr`,
/// or, with neither, `.handblocks/webxr` here.
pub fn default_dir() -> PathBuf {
    if let Some(d) = std::env::var_os("XDG_DATA_HOME").filter(|d| !d.is_empty()) {
        return PathBuf::from(d).join("handblocks/webxr");
    }
    if let Some(h) = std::env::var_os("HOME").filter(|h| !h.is_empty()) {
        return PathBuf::from(h).join(".local/share/handblocks/webxr");
    }
    PathBuf::from(".handblocks/webxr")
}

/// The certificate in `dir` (`certificate.pem`, `key.pem`), made there when absent, expired or
/// near expiry ([`keyfile::self_signed_pair`]: 0700 folder, 0600 files written without
/// following links, a key others may read refused), for the names `hosts` (`localhost` and
/// addresses).
pub fn load_or_make(dir: &Path, hosts: &[String]) -> Result<Certificate, CertificateError> {
    let pair = keyfile::self_signed_pair(dir, hosts)?;
    let damaged = |file: &Path, problem: String| CertificateError::Damaged {
        file: file.to_path_buf(),
        problem,
    };
    let cert = CertificateDer::from_pem_slice(&pair.certificate_pem).map_err(|e| {
        damaged(
            &pair.certificate_file,
            format!("not a PEM certificate ({e})"),
        )
    })?;
    let key = PrivateKeyDer::from_pem_slice(&pair.key_pem)
        .map_err(|e| damaged(&pair.key_file, format!("not a PEM private key ({e})")))?;
    let fingerprint = sha2::Sha256::digest(cert.as_ref())
        .iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(":");
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let config = rustls::ServerConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .map_err(|e| CertificateError::Tls(e.to_string()))?
        .with_no_client_auth()
        .with_single_cert(vec![cert], key)
        .map_err(|e| CertificateError::Tls(e.to_string()))?;
    let (made, renewed, days_left) = match pair.status {
        PairStatus::Kept { days_left } => (false, None, Some(days_left)),
        PairStatus::Made => (true, None, None),
        PairStatus::Renewed { why } => (true, Some(why), None),
    };
    Ok(Certificate {
        config: Arc::new(config),
        fingerprint,
        file: pair.certificate_file,
        made,
        renewed,
        days_left,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_certificate_is_made_once_and_kept_and_a_damaged_one_is_named() {
        let dir = std::env::temp_dir().join(format!("hb-cert-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let hosts = vec!["localhost".to_string(), "127.0.0.1".to_string()];
        let first = load_or_make(&dir, &hosts).unwrap();
        assert!(first.made);
        assert_eq!(first.fingerprint.len(), 32 * 3 - 1);
        let again = load_or_make(&dir, &hosts).unwrap();
        assert!(!again.made, "kept for the next session");
        assert_eq!(again.fingerprint, first.fingerprint);
        std::fs::write(dir.join("key.pem"), "not a key").unwrap();
        let e = load_or_make(&dir, &hosts).err().unwrap().to_string();
        assert!(
            e.contains("key.pem") && e.contains("delete the file"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
