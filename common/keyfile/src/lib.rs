//! Private key files, written and read so that nobody else reads or swaps them, and a
//! self-signed certificate kept beside its key, made anew before it expires.
//!
//! Every TLS key this project keeps: the webxr page's certificate ([`self_signed_pair`]) and
//! a zenoh link's authority ([`authority`], which issues each start's certificate for this
//! machine's names, [`interface_addresses`] and [`host_name`], and signs what a peer checks
//! with [`verify`]). Everything here takes a folder and a file name.
//!
//! - **Writing** ([`write_private`]): a temporary name in the same folder, created with
//!   `O_CREAT|O_EXCL|O_NOFOLLOW` and mode 0600, written, synced, then renamed over the name.
//!   A link planted at the name (`key.pem -> victim.txt`) is replaced, never written through,
//!   and a reader never sees half a key.
//! - **Folders** ([`private_dir`]): made 0700; an existing one that others may write to is
//!   refused (whoever can write it can swap the key).
//! - **Reading** ([`read_private`]): a link, or a key readable by group or others, is refused
//!   with what to do (`chmod 600 PATH`), never loaded silently.
//! - **Validity** ([`self_signed_pair`]): [`VALIDITY_DAYS`], renewed (new key, new
//!   certificate) within [`RENEW_DAYS`] of its end, when past it, or when it was made to last
//!   for ever (rcgen's default, 1975-4096, which earlier versions wrote).

mod authority;
mod names;
pub use authority::{
    authority, authority_at, fingerprint, verify, Authority, Issued, AUTHORITY_FILE,
    AUTHORITY_KEY_FILE, ISSUED_VALIDITY_DAYS,
};
pub use names::{host_name, interface_addresses};

use std::fs::OpenOptions;
use std::io::Write;
use std::os::unix::fs::{DirBuilderExt, MetadataExt, OpenOptionsExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

/// How long a certificate made here is valid.
pub const VALIDITY_DAYS: u64 = 365;
/// A certificate is made anew when it expires within this many days.
pub const RENEW_DAYS: u64 = 30;
/// The certificate's file in its folder.
pub const CERTIFICATE_FILE: &str = "certificate.pem";
/// The private key's file in its folder.
pub const KEY_FILE: &str = "key.pem";

pub(crate) const DAY_S: u64 = 86_400;

/// What went wrong with a private file or its folder; each says what to do.
#[derive(Debug, thiserror::Error)]
pub enum KeyFileError {
    #[error("{}: {source}; check the folder's permissions, or name another folder", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: others may write to this folder, so they could swap the key: run `chmod 700 {}`, or name another folder", dir.display(), dir.display())]
    OpenFolder { dir: PathBuf },
    #[error("{}: the key is readable by others (mode {mode:o}): run `chmod 600 {}`, or delete it to have a new one made", file.display(), file.display())]
    Readable { file: PathBuf, mode: u32 },
    #[error("{}: is a link; a key must be a file of its own: remove the link to have a new key made", file.display())]
    Link { file: PathBuf },
    #[error("{}: {problem}; delete the file to have a new certificate made", file.display())]
    Damaged { file: PathBuf, problem: String },
    #[error("cannot make a certificate: {0}")]
    Make(String),
}

/// Makes `dir` (and the folders above it that are missing) readable by its owner only, and
/// refuses an existing `dir` that group or others may write to.
pub fn private_dir(dir: &Path) -> Result<(), KeyFileError> {
    let io = |source| KeyFileError::Io {
        path: dir.to_path_buf(),
        source,
    };
    std::fs::DirBuilder::new()
        .recursive(true)
        .mode(0o700)
        .create(dir)
        .map_err(io)?;
    let meta = std::fs::metadata(dir).map_err(io)?;
    if meta.permissions().mode() & 0o022 != 0 {
        return Err(KeyFileError::OpenFolder {
            dir: dir.to_path_buf(),
        });
    }
    Ok(())
}

/// Writes `bytes` as `dir/name`, readable by its owner only: a new temporary file
/// (`O_EXCL|O_NOFOLLOW`, mode 0600) renamed over the name, so a link at the name is replaced
/// rather than followed. `dir` should have passed [`private_dir`]. Returns the file's path.
pub fn write_private(dir: &Path, name: &str, bytes: &[u8]) -> Result<PathBuf, KeyFileError> {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let file = dir.join(name);
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| KeyFileError::Io { path, source }
    };
    let (tmp, mut f) = loop {
        let tmp = dir.join(format!(
            ".{name}.{}-{}.tmp",
            std::process::id(),
            NEXT.fetch_add(1, Ordering::Relaxed)
        ));
        match OpenOptions::new()
            .write(true)
            .create_new(true) // O_CREAT|O_EXCL
            .mode(0o600)
            .custom_flags(libc::O_NOFOLLOW)
            .open(&tmp)
        {
            Ok(f) => break (tmp, f),
            // A stale temporary of an earlier process with our pid: try the next name.
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(io(&tmp)(e)),
        }
    };
    let written = f
        .write_all(bytes)
        .and_then(|()| f.sync_all())
        .and_then(|()| std::fs::rename(&tmp, &file));
    if let Err(e) = written {
        let _ = std::fs::remove_file(&tmp);
        return Err(io(&file)(e));
    }
    Ok(file)
}

/// Reads the private file `file`: refused if it is a link, or if group or others may read or
/// write it.
pub fn read_private(file: &Path) -> Result<Vec<u8>, KeyFileError> {
    use std::io::Read;
    let io = |source| KeyFileError::Io {
        path: file.to_path_buf(),
        source,
    };
    let mut f = match OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW)
        .open(file)
    {
        Ok(f) => f,
        Err(e) if e.raw_os_error() == Some(libc::ELOOP) => {
            return Err(KeyFileError::Link {
                file: file.to_path_buf(),
            })
        }
        Err(e) => return Err(io(e)),
    };
    let meta = f.metadata().map_err(io)?;
    let mode = meta.mode() & 0o777;
    if mode & 0o077 != 0 {
        return Err(KeyFileError::Readable {
            file: file.to_path_buf(),
            mode,
        });
    }
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    f.read_to_end(&mut bytes).map_err(io)?;
    Ok(bytes)
}

/// What [`self_signed_pair`] did.
#[derive(Debug, Clone, PartialEq)]
pub enum PairStatus {
    /// The kept pair, valid for `days_left` more days.
    Kept { days_left: u64 },
    /// None was there: made now.
    Made,
    /// The kept certificate expired, expires within [`RENEW_DAYS`], or was made to last for
    /// ever: made anew (a new key too), and `why` says which.
    Renewed { why: String },
}

/// A certificate and its key, in PEM, and where they are kept.
#[derive(Debug, Clone)]
pub struct Pair {
    pub certificate_file: PathBuf,
    pub key_file: PathBuf,
    pub certificate_pem: Vec<u8>,
    pub key_pem: Vec<u8>,
    pub status: PairStatus,
}

/// The self-signed certificate for `hosts` (names or addresses) and its key in `dir`
/// ([`CERTIFICATE_FILE`], [`KEY_FILE`]): kept from an earlier run while valid for more than
/// [`RENEW_DAYS`], else made (anew) valid for [`VALIDITY_DAYS`]. `dir` is made 0700 and the
/// files 0600; a key others may read, or a link, is refused (see [`read_private`]).
pub fn self_signed_pair(dir: &Path, hosts: &[String]) -> Result<Pair, KeyFileError> {
    self_signed_pair_at(dir, hosts, unix_now())
}

/// [`self_signed_pair`] at `now` (seconds since 1970), for tests of the renewal.
pub fn self_signed_pair_at(dir: &Path, hosts: &[String], now: u64) -> Result<Pair, KeyFileError> {
    private_dir(dir)?;
    let certificate_file = dir.join(CERTIFICATE_FILE);
    let key_file = dir.join(KEY_FILE);
    let exists = |f: &Path| std::fs::symlink_metadata(f).is_ok();
    let status = if exists(&certificate_file) && exists(&key_file) {
        let (pem, _, not_after) = read_certificate(&certificate_file)?;
        if let Some(why) = renewal(not_after, now) {
            PairStatus::Renewed { why }
        } else {
            // Checked before use: a key others may read is refused, not loaded silently.
            let key_pem = read_private(&key_file)?;
            return Ok(Pair {
                certificate_file,
                key_file,
                certificate_pem: pem,
                key_pem,
                status: PairStatus::Kept {
                    days_left: (not_after as u64 - now) / DAY_S,
                },
            });
        }
    } else {
        PairStatus::Made
    };
    let make = |e: rcgen::Error| KeyFileError::Make(e.to_string());
    let params = certificate_params(hosts, "handblocks (self-signed)", now, VALIDITY_DAYS)?;
    let key = rcgen::KeyPair::generate().map_err(make)?;
    let cert = params.self_signed(&key).map_err(make)?;
    let key_pem = key.serialize_pem().into_bytes();
    let certificate_pem = cert.pem().into_bytes();
    // The key first: a certificate never names a key that is not there yet.
    write_private(dir, KEY_FILE, &key_pem)?;
    write_private(dir, CERTIFICATE_FILE, &certificate_pem)?;
    Ok(Pair {
        certificate_file,
        key_file,
        certificate_pem,
        key_pem,
        status,
    })
}

/// A certificate's parameters: `hosts` as its names, `name` as its subject, valid from a day
/// before `now` (a peer whose clock is a little behind still accepts it) for `days` days.
pub(crate) fn certificate_params(
    hosts: &[String],
    name: &str,
    now: u64,
    days: u64,
) -> Result<rcgen::CertificateParams, KeyFileError> {
    let mut params = rcgen::CertificateParams::new(hosts.to_vec())
        .map_err(|e| KeyFileError::Make(e.to_string()))?;
    let epoch = rcgen::date_time_ymd(1970, 1, 1);
    params.not_before = epoch + Duration::from_secs(now.saturating_sub(DAY_S));
    params.not_after = epoch + Duration::from_secs(now + days * DAY_S);
    params.distinguished_name = rcgen::DistinguishedName::new();
    params
        .distinguished_name
        .push(rcgen::DnType::CommonName, name);
    Ok(params)
}

/// A kept certificate file: its PEM, its DER and its end of validity (seconds since 1970).
pub(crate) fn read_certificate(file: &Path) -> Result<(Vec<u8>, Vec<u8>, i64), KeyFileError> {
    let pem = std::fs::read(file).map_err(|source| KeyFileError::Io {
        path: file.to_path_buf(),
        source,
    })?;
    let damaged = |problem: &str| KeyFileError::Damaged {
        file: file.to_path_buf(),
        problem: problem.into(),
    };
    let der = certificate_der(&pem).ok_or_else(|| damaged("not a PEM certificate"))?;
    let (_, not_after) =
        validity(&der).ok_or_else(|| damaged("a certificate without a validity"))?;
    Ok((pem, der, not_after))
}

/// Why a certificate valid until `not_after` is made anew at `now`, if it is: expired,
/// expiring within [`RENEW_DAYS`], or made to last longer than [`VALIDITY_DAYS`].
pub(crate) fn renewal(not_after: i64, now: u64) -> Option<String> {
    let until = date(not_after);
    if not_after <= now as i64 {
        Some(format!("it expired on {until}"))
    } else if (not_after as u64) < now + RENEW_DAYS * DAY_S {
        Some(format!("it expires on {until}"))
    } else if (not_after as u64) > now + (VALIDITY_DAYS + 1) * DAY_S {
        Some(format!(
            "it was valid until {until}, and a key is not kept for ever: a new one every \
             {VALIDITY_DAYS} days"
        ))
    } else {
        None
    }
}

pub(crate) fn unix_now() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs())
}

/// The DER of the first certificate in `pem`.
pub fn certificate_der(pem: &[u8]) -> Option<Vec<u8>> {
    use rustls::pki_types::pem::PemObject;
    use rustls::pki_types::CertificateDer;
    CertificateDer::from_pem_slice(pem)
        .ok()
        .map(|c| c.as_ref().to_vec())
}

/// One DER element at the start of `b`: (tag, contents, the rest).
fn tlv(b: &[u8]) -> Option<(u8, &[u8], &[u8])> {
    let (&tag, b) = b.split_first()?;
    let (&first, mut b) = b.split_first()?;
    let len = if first < 0x80 {
        usize::from(first)
    } else {
        let n = usize::from(first & 0x7f);
        if n == 0 || n > 4 || b.len() < n {
            return None;
        }
        let len = b[..n]
            .iter()
            .fold(0usize, |acc, &x| (acc << 8) | usize::from(x));
        b = &b[n..];
        len
    };
    (b.len() >= len).then(|| (tag, &b[..len], &b[len..]))
}

/// A certificate's (notBefore, notAfter), seconds since 1970, from its DER: Certificate ->
/// tbsCertificate -> [version], serialNumber, signature, issuer, validity (RFC 5280 4.1).
pub fn validity(der: &[u8]) -> Option<(i64, i64)> {
    let (0x30, cert, _) = tlv(der)? else {
        return None;
    };
    let (0x30, mut tbs, _) = tlv(cert)? else {
        return None;
    };
    if tbs.first() == Some(&0xa0) {
        tbs = tlv(tbs)?.2; // [0] version
    }
    for _ in 0..3 {
        tbs = tlv(tbs)?.2; // serial, signature algorithm, issuer
    }
    let (0x30, validity, _) = tlv(tbs)? else {
        return None;
    };
    let (t1, before, rest) = tlv(validity)?;
    let (t2, after, _) = tlv(rest)?;
    Some((time(t1, before)?, time(t2, after)?))
}

/// UTCTime (0x17, YYMMDDHHMMSSZ) or GeneralizedTime (0x18, YYYYMMDDHHMMSSZ) as seconds since
/// 1970.
fn time(tag: u8, s: &[u8]) -> Option<i64> {
    let digits = |s: &[u8]| -> Option<i64> {
        s.iter().try_fold(0i64, |acc, &c| {
            c.is_ascii_digit().then(|| acc * 10 + i64::from(c - b'0'))
        })
    };
    let (year, rest) = match (tag, s.len()) {
        (0x17, 13) => {
            let yy = digits(&s[..2])?;
            (if yy >= 50 { 1900 + yy } else { 2000 + yy }, &s[2..])
        }
        (0x18, 15) => (digits(&s[..4])?, &s[4..]),
        _ => return None,
    };
    if rest[10] != b'Z' {
        return None;
    }
    let [month, day, hour, minute, second] =
        [0, 2, 4, 6, 8].map(|i| digits(&rest[i..i + 2]).unwrap_or(-1));
    if !(1..=12).contains(&month) || !(1..=31).contains(&day) || hour.min(minute).min(second) < 0 {
        return None;
    }
    Some(days_from_civil(year, month, day) * DAY_S as i64 + hour * 3600 + minute * 60 + second)
}

/// Days since 1970-01-01 of a proleptic Gregorian date (Howard Hinnant's algorithm).
fn days_from_civil(y: i64, m: i64, d: i64) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let doy = (153 * (m + if m > 2 { -3 } else { 9 }) + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// `YYYY-MM-DD` of seconds since 1970.
fn date(t: i64) -> String {
    let z = t.div_euclid(DAY_S as i64) + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!("{y:04}-{m:02}-{d:02}")
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::symlink;

    fn scratch(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("hb-keyfile-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    fn mode(p: &Path) -> u32 {
        std::fs::symlink_metadata(p).unwrap().permissions().mode() & 0o777
    }

    fn hosts() -> Vec<String> {
        vec!["localhost".into(), "127.0.0.1".into()]
    }

    #[test]
    fn a_key_planted_as_a_link_is_replaced_not_written_through() {
        let d = scratch("link");
        std::fs::create_dir_all(&d).unwrap();
        std::fs::set_permissions(&d, std::fs::Permissions::from_mode(0o700)).unwrap();
        let victim = d.join("victim.txt");
        std::fs::write(&victim, "the victim's own text").unwrap();
        std::fs::set_permissions(&victim, std::fs::Permissions::from_mode(0o644)).unwrap();
        symlink(&victim, d.join(KEY_FILE)).unwrap();
        let pair = self_signed_pair(&d, &hosts()).unwrap();
        assert_eq!(pair.status, PairStatus::Made);
        assert_eq!(
            std::fs::read_to_string(&victim).unwrap(),
            "the victim's own text"
        );
        let key = d.join(KEY_FILE);
        assert!(!std::fs::symlink_metadata(&key).unwrap().is_symlink());
        assert_eq!(mode(&key), 0o600);
        assert_eq!(mode(&d.join(CERTIFICATE_FILE)), 0o600);
        assert!(std::fs::read_to_string(&key)
            .unwrap()
            .contains("PRIVATE KEY"));
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn new_folders_are_0700_and_a_folder_others_may_write_is_refused() {
        let d = scratch("dirs");
        let inner = d.join("a/b");
        self_signed_pair(&inner, &hosts()).unwrap();
        assert_eq!(mode(&d.join("a")), 0o700);
        assert_eq!(mode(&inner), 0o700);
        std::fs::set_permissions(&inner, std::fs::Permissions::from_mode(0o777)).unwrap();
        let e = self_signed_pair(&inner, &hosts()).unwrap_err().to_string();
        assert!(e.contains("chmod 700"), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_key_others_may_read_is_refused_with_chmod_600_and_a_linked_key_is_refused() {
        let d = scratch("readable");
        self_signed_pair(&d, &hosts()).unwrap();
        let key = d.join(KEY_FILE);
        std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o644)).unwrap();
        let e = self_signed_pair(&d, &hosts()).unwrap_err().to_string();
        assert!(e.contains(&format!("chmod 600 {}", key.display())), "{e}");
        std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o600)).unwrap();
        let kept = self_signed_pair(&d, &hosts()).unwrap();
        assert!(matches!(kept.status, PairStatus::Kept { days_left } if days_left >= 364));
        // A link to a private key elsewhere is not followed either.
        let elsewhere = d.join("elsewhere.pem");
        std::fs::rename(&key, &elsewhere).unwrap();
        symlink(&elsewhere, &key).unwrap();
        let e = read_private(&key).unwrap_err().to_string();
        assert!(e.contains("is a link"), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_certificate_is_valid_a_year_and_made_anew_near_its_end_or_when_it_lasts_for_ever() {
        let d = scratch("renew");
        let now = 1_800_000_000; // 2027-01-15
        let first = self_signed_pair_at(&d, &hosts(), now).unwrap();
        let der = certificate_der(&first.certificate_pem).unwrap();
        let (before, after) = validity(&der).unwrap();
        assert_eq!(before, now as i64 - DAY_S as i64);
        assert_eq!(after, (now + VALIDITY_DAYS * DAY_S) as i64);
        // Kept while far from its end.
        let later = now + 200 * DAY_S;
        let kept = self_signed_pair_at(&d, &hosts(), later).unwrap();
        assert_eq!(kept.status, PairStatus::Kept { days_left: 165 });
        assert_eq!(kept.key_pem, first.key_pem);
        // Within RENEW_DAYS of its end: a new key and certificate.
        let near = now + (VALIDITY_DAYS - 10) * DAY_S;
        let renewed = self_signed_pair_at(&d, &hosts(), near).unwrap();
        assert!(
            matches!(&renewed.status, PairStatus::Renewed { why } if why.contains("expires on 2028-01-15")),
            "{:?}",
            renewed.status
        );
        assert_ne!(renewed.key_pem, first.key_pem);
        // Past its end.
        let past = near + 2 * VALIDITY_DAYS * DAY_S;
        let s = self_signed_pair_at(&d, &hosts(), past).unwrap().status;
        assert!(
            matches!(&s, PairStatus::Renewed { why } if why.contains("expired")),
            "{s:?}"
        );
        // One made to last for ever (rcgen's default, as earlier versions wrote it).
        let old = rcgen::generate_simple_self_signed(hosts()).unwrap();
        write_private(&d, CERTIFICATE_FILE, old.cert.pem().as_bytes()).unwrap();
        write_private(&d, KEY_FILE, old.signing_key.serialize_pem().as_bytes()).unwrap();
        let s = self_signed_pair_at(&d, &hosts(), now).unwrap().status;
        assert!(
            matches!(&s, PairStatus::Renewed { why } if why.contains("4096-01-01")),
            "{s:?}"
        );
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn dates_convert_both_ways() {
        assert_eq!(days_from_civil(1970, 1, 1), 0);
        assert_eq!(date(0), "1970-01-01");
        assert_eq!(date(1_800_000_000), "2027-01-15");
        assert_eq!(time(0x17, b"270115080000Z"), Some(1_800_000_000));
        assert_eq!(
            time(0x18, b"40960101000000Z").map(date).as_deref(),
            Some("4096-01-01")
        );
        assert_eq!(time(0x17, b"27011508000Z"), None);
        assert!(validity(b"\x30\x03\x30\x01").is_none());
    }
}
