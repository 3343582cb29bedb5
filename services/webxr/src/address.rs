//! What the user is told to open: the page's URL on this machine's network address (a headset
//! on the same network reaches it), the `localhost` URL for `adb reverse`, and the first as a
//! QR code in the terminal (a headset's browser can scan it, and nobody types a token).

use std::net::{IpAddr, SocketAddr, UdpSocket};

/// This machine's address on the network it would use to reach others, if it has one: a UDP
/// socket "connected" to a non-routed address names the interface; no packet is sent.
pub fn lan_ip() -> Option<IpAddr> {
    let s = UdpSocket::bind("0.0.0.0:0").ok()?;
    s.connect("10.255.255.255:1").ok()?;
    let ip = s.local_addr().ok()?.ip();
    (!ip.is_unspecified() && !ip.is_loopback()).then_some(ip)
}

/// This machine's interfaces' addresses (the shared `keyfile` crate's, which names them in
/// certificates too): to say where a server listening on every interface can be reached.
pub use keyfile::interface_addresses;

/// The host a headset should use for a server listening on `listen`.
pub fn public_host(listen: SocketAddr) -> IpAddr {
    let ip = listen.ip();
    if ip.is_unspecified() {
        lan_ip().unwrap_or(IpAddr::from([127, 0, 0, 1]))
    } else {
        ip
    }
}

/// The page's URL.
pub fn url(tls: bool, host: IpAddr, port: u16, token: &str) -> String {
    let scheme = if tls { "https" } else { "http" };
    let host = match host {
        IpAddr::V6(v6) => format!("[{v6}]"),
        IpAddr::V4(v4) => v4.to_string(),
    };
    format!("{scheme}://{host}:{port}/?token={token}")
}

/// `text` as a QR code drawn with half-block characters (two rows of modules per line), with
/// the quiet zone, or None when it does not fit a QR code.
pub fn qr(text: &str) -> Option<String> {
    let code = qrcode::QrCode::new(text.as_bytes()).ok()?;
    Some(
        code.render::<qrcode::render::unicode::Dense1x2>()
            .dark_color(qrcode::render::unicode::Dense1x2::Light)
            .light_color(qrcode::render::unicode::Dense1x2::Dark)
            .build(),
    )
}

/// A new random token: 22 characters of base64url (128 bits) from the kernel's generator.
pub fn random_token() -> std::io::Result<String> {
    use std::io::Read;
    let mut bytes = [0u8; 16];
    std::fs::File::open("/dev/urandom")?.read_exact(&mut bytes)?;
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789-_";
    let mut bits: u128 = u128::from_le_bytes(bytes);
    Ok((0..22)
        .map(|_| {
            let c = ALPHABET[(bits & 63) as usize] as char;
            bits >>= 6;
            c
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn urls_tokens_and_the_qr_code() {
        let t = random_token().unwrap();
        assert_eq!(t.len(), 22);
        assert_ne!(t, random_token().unwrap());
        let u = url(true, IpAddr::from([192, 168, 1, 5]), 8443, &t);
        assert_eq!(u, format!("https://192.168.1.5:8443/?token={t}"));
        let q = qr(&u).unwrap();
        assert!(q.lines().count() > 10);
        assert!(interface_addresses().iter().any(|a| a.is_loopback()));
    }
}
