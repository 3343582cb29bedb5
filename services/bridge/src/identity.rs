//! Who this side of a link is, and whom it trusts (issue 40: the link was open and in clear;
//! a stranger read every hand and world, and fed a viewer invented ones).
//!
//! A `tls/` link is TLS 1.3 with both sides' certificates (zenoh's mutual TLS): each side
//! presents a certificate its user's authority ([`keyfile::authority`], kept in `key_dir`)
//! issued at this start for this machine's names, and accepts only a certificate issued by the
//! authority it was told to trust (`peer_certificate`: the other side's `authority.pem`, copied
//! once; by default this side's own, so two halves on one machine trust each other as they
//! are). The authority also signs this side's answers to the clock exchange
//! ([`crate::link`]): a connecting side's TLS (zenoh's) also trusts the public web
//! authorities, so a receiver publishes nothing until the sender has proved, by a signature
//! over the receiver's fresh nonce, that it holds the trusted authority's key.

use std::path::{Path, PathBuf};

use common::config::remote::{endpoint_host, is_loopback_host, LinkSecurity};
use keyfile::{Authority, KeyFileError, PairStatus};

/// The subject of a new link authority: the machine and a random tag, so that two users'
/// authorities never share a name (TLS then says which issuer it does not know, rather than
/// that a signature is bad).
fn authority_name() -> String {
    let mut tag = [0u8; 4];
    // SAFETY: writes at most 4 bytes into `tag`.
    unsafe { libc::getrandom(tag.as_mut_ptr() as *mut libc::c_void, tag.len(), 0) };
    format!(
        "handblocks link authority ({}, {:02x}{:02x}{:02x}{:02x})",
        keyfile::host_name().unwrap_or_else(|| "a machine".into()),
        tag[0],
        tag[1],
        tag[2],
        tag[3]
    )
}

/// Why a link's keys could not be had.
#[derive(Debug, thiserror::Error)]
pub enum IdentityError {
    /// This side's authority: what to do is in the message.
    #[error("the link's keys in {}: {source}", dir.display())]
    Keys {
        dir: PathBuf,
        #[source]
        source: KeyFileError,
    },
    /// The peer's certificate, named by the session's `peer_certificate`.
    #[error("{}: {problem}; [remote] peer_certificate (or [source] peer_certificate) names the other side's authority.pem, copied from its key_dir", file.display())]
    Peer { file: PathBuf, problem: String },
}

/// This side's keys for a `tls/` link, and the authority it trusts.
pub struct Identity {
    pub authority: Authority,
    /// The certificate chain (issued, then the authority) and its key, PEM: what TLS presents.
    pub chain_pem: Vec<u8>,
    pub key_pem: Vec<u8>,
    /// The trusted peer's authority certificate, PEM.
    pub peer_pem: Vec<u8>,
    /// Where it came from: None when it is this side's own.
    pub peer_file: Option<PathBuf>,
    /// The names and addresses in the issued certificate.
    pub names: Vec<String>,
}

impl Identity {
    /// The keys of a `tls/` link on `endpoint`: the authority in `key_dir` (made on first use),
    /// a certificate for this machine's names, and the trusted peer's authority.
    pub fn load(
        security: &LinkSecurity,
        endpoint: &str,
    ) -> Result<Option<Identity>, IdentityError> {
        let LinkSecurity::Tls {
            key_dir,
            peer_certificate,
            names,
        } = security
        else {
            return Ok(None);
        };
        let keys = |source| IdentityError::Keys {
            dir: key_dir.clone(),
            source,
        };
        let authority = keyfile::authority(key_dir, &authority_name()).map_err(keys)?;
        let names = certificate_names(endpoint, names);
        let issued = authority.issue(&names).map_err(keys)?;
        let (peer_pem, peer_file) = match peer_certificate {
            None => (authority.certificate_pem.clone(), None),
            Some(file) => (read_peer(file)?, Some(file.clone())),
        };
        Ok(Some(Identity {
            authority,
            chain_pem: issued.chain_pem,
            key_pem: issued.key_pem,
            peer_pem,
            peer_file,
            names,
        }))
    }

    /// What the terminal says of the keys at start: whose they are, what to copy where.
    pub fn describe(&self) -> String {
        let made = match &self.authority.status {
            PairStatus::Made => "made now".to_string(),
            PairStatus::Kept { days_left } => format!("valid {days_left} more days"),
            PairStatus::Renewed { why } => format!(
                "made anew ({why}): give the new one to the other side, whose \
                 peer_certificate names the old"
            ),
        };
        let trust = match &self.peer_file {
            None => "trusting only peers that hold this same authority (the other half of a \
                     session on this machine, or one given a copy of its folder); to trust \
                     another machine's, set peer_certificate to a copy of its authority.pem"
                .to_string(),
            Some(f) => format!(
                "trusting only peers whose certificate {} issued (SHA-256 {})",
                f.display(),
                keyfile::certificate_der(&self.peer_pem)
                    .map(|d| keyfile::fingerprint(&d))
                    .unwrap_or_default()
            ),
        };
        format!(
            "TLS 1.3, both sides authenticated; this side's authority {} ({made}; SHA-256 {}); \
             {trust}; names in this side's certificate: {}",
            self.authority.certificate_file.display(),
            self.authority.fingerprint,
            self.names.join(", ")
        )
    }
}

/// Reads the peer's authority certificate: a regular file, at most 64 KiB, holding a PEM
/// certificate.
fn read_peer(file: &Path) -> Result<Vec<u8>, IdentityError> {
    let peer = |problem: String| IdentityError::Peer {
        file: file.to_path_buf(),
        problem,
    };
    let pem = common::config::read_bounded(file, 64 << 10).map_err(|e| {
        peer(format!(
            "cannot read it: {e} (copy the other side's authority.pem here)"
        ))
    })?;
    if keyfile::certificate_der(&pem).is_none() {
        return Err(peer("not a PEM certificate".into()));
    }
    Ok(pem)
}

/// The names a certificate issued for this side holds: `localhost` and the loopback
/// addresses, the machine's host name and interface addresses, the endpoint's host (when it
/// names one, not `0.0.0.0`), and the session's `names`. A connecting side checks the name it
/// connected to against them.
pub fn certificate_names(endpoint: &str, extra: &[String]) -> Vec<String> {
    let mut names: Vec<String> = vec!["localhost".into(), "127.0.0.1".into(), "::1".into()];
    if let Some(h) = keyfile::host_name() {
        names.push(h);
    }
    names.extend(interface_addresses().iter().map(|a| a.to_string()));
    let host = endpoint_host(endpoint);
    let unspecified = host
        .parse::<std::net::IpAddr>()
        .is_ok_and(|a| a.is_unspecified());
    if !unspecified && !is_loopback_host(host) {
        names.push(host.to_string());
    }
    names.extend(extra.iter().cloned());
    let mut seen = std::collections::BTreeSet::new();
    names.retain(|n| seen.insert(n.clone()));
    names
}

/// The addresses of this machine's interfaces a peer can name: loopback (named apart) and
/// link-local IPv6 (it needs a zone to be used) left out.
fn interface_addresses() -> Vec<std::net::IpAddr> {
    let mut out = keyfile::interface_addresses();
    out.retain(|a| {
        let link_local =
            matches!(a, std::net::IpAddr::V6(v6) if v6.segments()[0] & 0xffc0 == 0xfe80);
        !a.is_loopback() && !link_local
    });
    out
}
