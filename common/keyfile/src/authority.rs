//! A certificate authority of one user's, for links between that user's sessions (issue 40: the
//! zenoh link was open and in clear).
//!
//! Why an authority and not one self-signed certificate: a peer pins what it trusts, once (the
//! user copies a file), so what it pins must outlive the names a session is reached by, which
//! change with the network. The authority (`authority.pem`, its key `authority-key.pem`) is
//! kept as every key here is ([`crate::private_dir`], [`crate::write_private`],
//! [`crate::read_private`]) and renewed as [`crate::self_signed_pair`] renews; at each start it
//! issues a short-lived certificate for this machine's current names, held in memory only.
//! It also signs: [`Authority::sign`] lets a peer prove, over a link whose TLS it cannot
//! inspect, that it holds the authority's key ([`verify`]).

use std::os::fd::AsRawFd as _;
use std::os::unix::fs::OpenOptionsExt as _;
use std::path::{Path, PathBuf};

use crate::{
    certificate_der, certificate_params, private_dir, read_certificate, read_private, renewal,
    unix_now, write_private, KeyFileError, PairStatus, DAY_S, VALIDITY_DAYS,
};

/// The authority's certificate in its folder: the file a peer is given to trust.
pub const AUTHORITY_FILE: &str = "authority.pem";
/// The authority's private key in its folder.
pub const AUTHORITY_KEY_FILE: &str = "authority-key.pem";
/// How long a certificate the authority issues at a start is valid: a session that runs
/// longer keeps its link (TLS checks validity when a link opens).
pub const ISSUED_VALIDITY_DAYS: u64 = 7;

/// The authority, loaded (or made) from its folder.
pub struct Authority {
    pub certificate_file: PathBuf,
    pub certificate_pem: Vec<u8>,
    /// SHA-256 of the certificate's DER, `AB:CD:...`, for the user to compare across machines.
    pub fingerprint: String,
    pub status: PairStatus,
    key: rcgen::KeyPair,
    issuer_pem: String,
}

/// A certificate the authority issued for this start, with its key (PEM).
pub struct Issued {
    /// The issued certificate, then the authority's (the chain a peer verifies).
    pub chain_pem: Vec<u8>,
    pub key_pem: Vec<u8>,
}

/// Holds an exclusive lock on `dir/.lock` while alive, so that two processes starting at once
/// (both halves of a session on one machine) never make two authorities, one overwriting the
/// other's key under it.
struct DirLock(std::fs::File);

impl DirLock {
    fn take(dir: &Path) -> Result<DirLock, KeyFileError> {
        let file = dir.join(".lock");
        let f = std::fs::OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .mode(0o600)
            .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC)
            .open(&file)
            .map_err(|source| KeyFileError::Io {
                path: file.clone(),
                source,
            })?;
        // SAFETY: flock on a descriptor this value owns; released when it is closed.
        if unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX) } != 0 {
            return Err(KeyFileError::Io {
                path: file,
                source: std::io::Error::last_os_error(),
            });
        }
        Ok(DirLock(f))
    }
}

impl Drop for DirLock {
    fn drop(&mut self) {
        // SAFETY: as in `take`.
        unsafe { libc::flock(self.0.as_raw_fd(), libc::LOCK_UN) };
    }
}

/// The authority kept in `dir`, made there when absent, expired, near expiry or made to last
/// for ever, as [`crate::self_signed_pair`] does for a certificate. `name` goes in its subject
/// ("handblocks link authority").
pub fn authority(dir: &Path, name: &str) -> Result<Authority, KeyFileError> {
    authority_at(dir, name, unix_now())
}

/// [`authority`] at `now` (seconds since 1970), for tests of the renewal.
pub fn authority_at(dir: &Path, name: &str, now: u64) -> Result<Authority, KeyFileError> {
    private_dir(dir)?;
    let _lock = DirLock::take(dir)?;
    let certificate_file = dir.join(AUTHORITY_FILE);
    let key_file = dir.join(AUTHORITY_KEY_FILE);
    let make = |e: rcgen::Error| KeyFileError::Make(e.to_string());
    let exists = |f: &Path| std::fs::symlink_metadata(f).is_ok();
    let status = if exists(&certificate_file) && exists(&key_file) {
        let (pem, der, not_after) = read_certificate(&certificate_file)?;
        let damaged = |problem: &str| KeyFileError::Damaged {
            file: certificate_file.clone(),
            problem: problem.into(),
        };
        match renewal(not_after, now) {
            Some(why) => PairStatus::Renewed { why },
            None => {
                let key_pem = read_private(&key_file)?;
                let key_text = String::from_utf8(key_pem).map_err(|_| KeyFileError::Damaged {
                    file: key_file.clone(),
                    problem: "not a PEM key".into(),
                })?;
                let key =
                    rcgen::KeyPair::from_pem(&key_text).map_err(|e| KeyFileError::Damaged {
                        file: key_file.clone(),
                        problem: format!("not a key: {e}"),
                    })?;
                let pem_text =
                    String::from_utf8(pem.clone()).map_err(|_| damaged("not a PEM certificate"))?;
                // The kept certificate must be this key's: a swapped pair is refused.
                if !spki_matches(&der, &key) {
                    return Err(damaged(
                        "it is not the certificate of authority-key.pem beside it",
                    ));
                }
                return Ok(Authority {
                    fingerprint: fingerprint(&der),
                    certificate_file,
                    certificate_pem: pem,
                    status: PairStatus::Kept {
                        days_left: (not_after as u64).saturating_sub(now) / DAY_S,
                    },
                    key,
                    issuer_pem: pem_text,
                });
            }
        }
    } else {
        PairStatus::Made
    };
    let mut params = certificate_params(&[], name, now, VALIDITY_DAYS)?;
    params.is_ca = rcgen::IsCa::Ca(rcgen::BasicConstraints::Constrained(0));
    params.key_usages = vec![
        rcgen::KeyUsagePurpose::KeyCertSign,
        rcgen::KeyUsagePurpose::DigitalSignature,
    ];
    let key = rcgen::KeyPair::generate().map_err(make)?;
    let cert = params.self_signed(&key).map_err(make)?;
    let certificate_pem = cert.pem().into_bytes();
    write_private(dir, AUTHORITY_KEY_FILE, key.serialize_pem().as_bytes())?;
    write_private(dir, AUTHORITY_FILE, &certificate_pem)?;
    Ok(Authority {
        fingerprint: fingerprint(cert.der()),
        certificate_file,
        issuer_pem: cert.pem(),
        certificate_pem,
        status,
        key,
    })
}

impl Authority {
    /// A certificate for `hosts` (names and addresses), for both ends of TLS (server and
    /// client authentication), valid [`ISSUED_VALIDITY_DAYS`], and its new key: never written.
    pub fn issue(&self, hosts: &[String]) -> Result<Issued, KeyFileError> {
        let make = |e: rcgen::Error| KeyFileError::Make(e.to_string());
        let now = unix_now();
        let mut params = certificate_params(hosts, "handblocks link", now, ISSUED_VALIDITY_DAYS)?;
        params.extended_key_usages = vec![
            rcgen::ExtendedKeyUsagePurpose::ServerAuth,
            rcgen::ExtendedKeyUsagePurpose::ClientAuth,
        ];
        params.key_usages = vec![rcgen::KeyUsagePurpose::DigitalSignature];
        params.use_authority_key_identifier_extension = true;
        let issuer = rcgen::Issuer::from_ca_cert_pem(&self.issuer_pem, &self.key).map_err(make)?;
        let key = rcgen::KeyPair::generate().map_err(make)?;
        let cert = params.signed_by(&key, &issuer).map_err(make)?;
        let mut chain_pem = cert.pem().into_bytes();
        chain_pem.extend_from_slice(&self.certificate_pem);
        Ok(Issued {
            chain_pem,
            key_pem: key.serialize_pem().into_bytes(),
        })
    }

    /// `message` signed with the authority's key (ECDSA P-256, SHA-256, ASN.1 DER): what a
    /// peer checks with [`verify`] against the authority certificate it was given.
    pub fn sign(&self, message: &[u8]) -> Result<Vec<u8>, KeyFileError> {
        use rcgen::SigningKey as _;
        self.key
            .sign(message)
            .map_err(|e| KeyFileError::Make(e.to_string()))
    }
}

/// True when `signature` is `message` signed by the key of the authority whose certificate is
/// `authority_pem` (PEM), as [`Authority::sign`] signs.
pub fn verify(authority_pem: &[u8], message: &[u8], signature: &[u8]) -> bool {
    let Some(der) = certificate_der(authority_pem) else {
        return false;
    };
    let Ok((_, cert)) = x509_parser::parse_x509_certificate(&der) else {
        return false;
    };
    let key = cert.public_key().subject_public_key.data.as_ref();
    ring::signature::UnparsedPublicKey::new(&ring::signature::ECDSA_P256_SHA256_ASN1, key)
        .verify(message, signature)
        .is_ok()
}

/// True when the certificate `der` carries `key`'s public key.
fn spki_matches(der: &[u8], key: &rcgen::KeyPair) -> bool {
    use rcgen::PublicKeyData as _;
    x509_parser::parse_x509_certificate(der).is_ok_and(|(_, cert)| {
        cert.public_key().subject_public_key.data.as_ref() == key.der_bytes()
    })
}

/// SHA-256 of `der` as `AB:CD:...`.
pub fn fingerprint(der: &[u8]) -> String {
    ring::digest::digest(&ring::digest::SHA256, der)
        .as_ref()
        .iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(":")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("hb-authority-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    #[test]
    fn an_authority_is_made_once_kept_and_signs_what_its_certificate_verifies() {
        let dir = scratch("kept");
        let a = authority(&dir, "handblocks link authority").unwrap();
        assert_eq!(a.status, PairStatus::Made);
        let b = authority(&dir, "handblocks link authority").unwrap();
        assert!(
            matches!(b.status, PairStatus::Kept { .. }),
            "{:?}",
            b.status
        );
        assert_eq!(a.certificate_pem, b.certificate_pem);
        assert_eq!(a.fingerprint, b.fingerprint);
        let sig = b.sign(b"nonce 42").unwrap();
        assert!(verify(&a.certificate_pem, b"nonce 42", &sig));
        assert!(!verify(&a.certificate_pem, b"nonce 43", &sig));
        let other = authority(&scratch("other"), "x").unwrap();
        assert!(!verify(&other.certificate_pem, b"nonce 42", &sig));
        // Its key is private; the issued certificate is a chain of two, never written.
        let issued = b.issue(&["localhost".into(), "127.0.0.1".into()]).unwrap();
        assert_eq!(
            String::from_utf8_lossy(&issued.chain_pem)
                .matches("BEGIN CERTIFICATE")
                .count(),
            2
        );
        use std::os::unix::fs::PermissionsExt as _;
        let mode = std::fs::metadata(dir.join(AUTHORITY_KEY_FILE))
            .unwrap()
            .permissions()
            .mode();
        assert_eq!(mode & 0o777, 0o600);
        let _ = std::fs::remove_dir_all(&dir);
        let _ = std::fs::remove_dir_all(scratch("other"));
    }

    #[test]
    fn an_authority_near_its_end_is_made_anew() {
        let dir = scratch("renew");
        let now = unix_now();
        let a = authority_at(&dir, "n", now).unwrap();
        let later = now + (VALIDITY_DAYS - crate::RENEW_DAYS + 1) * DAY_S;
        let b = authority_at(&dir, "n", later).unwrap();
        assert!(
            matches!(b.status, PairStatus::Renewed { .. }),
            "{:?}",
            b.status
        );
        assert_ne!(a.fingerprint, b.fingerprint);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_key_others_may_read_is_refused() {
        use std::os::unix::fs::PermissionsExt as _;
        let dir = scratch("readable");
        authority(&dir, "n").unwrap();
        let key = dir.join(AUTHORITY_KEY_FILE);
        std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o644)).unwrap();
        let e = authority(&dir, "n").err().unwrap().to_string();
        assert!(e.contains("chmod 600"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
