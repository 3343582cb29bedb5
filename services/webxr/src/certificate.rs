//! The certificate WebXR's secure context needs: made on first use (self-signed, for
//! `localhost` and this machine's addresses), kept in a folder for the next session so the
//! headset's browser, once told to trust it, is not asked again, and named by its SHA-256
//! fingerprint so the user can check what the browser shows.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer};
use sha2::Digest;

/// Why no certificate could be had.
#[derive(Debug, thiserror::Error)]
pub enum CertificateError {
    #[error("{}: {source}; check the folder's permissions, or set [source] certificate_dir", dir.display())]
    Folder {
        dir: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: {problem}; delete the file to have a new certificate made", file.display())]
    Damaged { file: PathBuf, problem: String },
    #[error("cannot make a certificate: {0}")]
    Make(String),
    #[error("the certificate is refused by TLS: {0}")]
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

/// The certificate in `dir` (`certificate.pem`, `key.pem`), made there when absent, for the
/// names `hosts` (`localhost` and addresses).
pub fn load_or_make(dir: &Path, hosts: &[String]) -> Result<Certificate, CertificateError> {
    let cert_file = dir.join("certificate.pem");
    let key_file = dir.join("key.pem");
    let folder = |source| CertificateError::Folder {
        dir: dir.to_path_buf(),
        source,
    };
    let made = !cert_file.exists() || !key_file.exists();
    if made {
        std::fs::create_dir_all(dir).map_err(folder)?;
        let key = rcgen::generate_simple_self_signed(hosts.to_vec())
            .map_err(|e| CertificateError::Make(e.to_string()))?;
        std::fs::write(&cert_file, key.cert.pem()).map_err(folder)?;
        write_private(&key_file, key.signing_key.serialize_pem().as_bytes()).map_err(folder)?;
    }
    let damaged = |file: &Path, problem: String| CertificateError::Damaged {
        file: file.to_path_buf(),
        problem,
    };
    let cert = CertificateDer::from_pem_file(&cert_file)
        .map_err(|e| damaged(&cert_file, format!("not a PEM certificate ({e})")))?;
    let key = PrivateKeyDer::from_pem_file(&key_file)
        .map_err(|e| damaged(&key_file, format!("not a PEM private key ({e})")))?;
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
    Ok(Certificate {
        config: Arc::new(config),
        fingerprint,
        file: cert_file,
        made,
    })
}

/// Writes the key readable by its owner only.
fn write_private(file: &Path, bytes: &[u8]) -> std::io::Result<()> {
    use std::io::Write;
    use std::os::unix::fs::OpenOptionsExt;
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .mode(0o600)
        .open(file)?;
    f.write_all(bytes)
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
