//! Device emulators on pseudo-terminals: a CyberGlove ([`glove`]) and a FASTRAK ([`tracker`])
//! that speak the protocols the drivers speak, so the drivers are tested end to end through a
//! real tty, and a session can run with no hardware.
//!
//! An emulator serves a pty and publishes its slave under a stable *link* path (a symlink,
//! like `socat`'s `link=`), so a session config names the link as its `port` and the same
//! config points at `/dev/ttyUSB0` for the real device. Behaviour is scriptable with
//! [`Fault`]s keyed by record number: noise, cut records, silence, an unplugged cable.
//!
//! Two ways to run one:
//! * in a test: [`glove::spawn`] / [`tracker::spawn`] start it on a thread with a link in a
//!   fresh temporary folder; [`Emulator::stop`] (or drop) stops it and cleans up;
//! * as a program: [`glove::run`] / [`tracker::run`] serve a given link path until a stop
//!   predicate says so (e.g. `handblocks emulate glove --link /tmp/glove`).

pub mod glove;
pub mod pty;
pub mod tracker;

use std::io;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use pty::Pty;

/// Something that goes wrong with an emulated device, at a given record.
#[derive(Debug, Clone, PartialEq)]
pub enum Fault {
    /// These bytes go out just before the record.
    Garbage(Vec<u8>),
    /// Only the first n bytes of the record go out.
    Truncate(usize),
    /// One byte of the record (at this index, if it has one) is flipped.
    Corrupt(usize),
    /// The device goes quiet at this record (which is not sent) for this long: it sends
    /// nothing and ignores every command. `Duration::MAX` is for good.
    Silence(Duration),
    /// The cable is pulled at this record: the pty closes and the link disappears, and after
    /// this long a new pty appears under the same link.
    Unplug(Duration),
}

impl Fault {
    /// Parses a fault as a command line gives it, `KIND@RECORD[:ARG]`:
    ///
    /// | spec | fault |
    /// |---|---|
    /// | `garbage@100` / `garbage@100:TEXT` | noise bytes (default 16 bytes of junk) before record 100 |
    /// | `truncate@200:5` | only the first 5 bytes of record 200 |
    /// | `corrupt@300:7` | byte 7 of record 300 flipped |
    /// | `silence@400:1500` | quiet for 1500 ms from record 400 (`forever` for good) |
    /// | `unplug@500:1000` | the cable pulled at record 500, back after 1000 ms |
    pub fn parse(spec: &str) -> Result<(u64, Fault), String> {
        let usage = "a fault is KIND@RECORD[:ARG] with KIND one of garbage, truncate, corrupt, \
                     silence, unplug; e.g. silence@400:1500";
        let (kind, rest) = spec
            .split_once('@')
            .ok_or_else(|| format!("`{spec}`: {usage}"))?;
        let (record, arg) = match rest.split_once(':') {
            Some((r, a)) => (r, Some(a)),
            None => (rest, None),
        };
        let record: u64 = record
            .parse()
            .map_err(|_| format!("`{spec}`: the record number `{record}` is not a whole number"))?;
        let number = |what: &str| -> Result<u64, String> {
            let a = arg.ok_or_else(|| format!("`{spec}`: give {what} after a colon"))?;
            a.parse()
                .map_err(|_| format!("`{spec}`: {what} `{a}` is not a whole number"))
        };
        let fault = match kind {
            "garbage" => Fault::Garbage(
                arg.map(|a| a.as_bytes().to_vec())
                    .unwrap_or_else(|| b"\xff\x00#junk#\x7fGS01\r\n".to_vec()),
            ),
            "truncate" => Fault::Truncate(number("the bytes to keep")? as usize),
            "corrupt" => Fault::Corrupt(number("the byte index")? as usize),
            "silence" if arg == Some("forever") => Fault::Silence(Duration::MAX),
            "silence" => Fault::Silence(Duration::from_millis(number("milliseconds")?)),
            "unplug" => Fault::Unplug(Duration::from_millis(number("milliseconds")?)),
            _ => return Err(format!("`{spec}`: unknown fault `{kind}`; {usage}")),
        };
        Ok((record, fault))
    }
}

/// What an emulator did, for tests and for the program's exit line.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct EmulatorReport {
    /// Records sent (after faults; a silenced or truncated record counts as not sent / sent).
    pub records: u64,
    /// Bytes received from the driver.
    pub bytes_in: u64,
    /// The first 4 KiB the driver sent: its commands, for protocol assertions.
    pub received: Vec<u8>,
    /// Times the emulated cable was pulled.
    pub unplugs: u64,
}

/// Where a device's output goes: applies the fault plan per record.
pub struct Emit {
    out: Vec<u8>,
    faults: Vec<(u64, Fault)>,
    next_record: u64,
    silent_until: Option<Option<Instant>>,
    unplug: Option<Duration>,
}

impl Emit {
    fn new(mut faults: Vec<(u64, Fault)>) -> Emit {
        faults.sort_by_key(|(k, _)| *k);
        Emit {
            out: Vec::with_capacity(4096),
            faults,
            next_record: 0,
            silent_until: None,
            unplug: None,
        }
    }

    /// A reply that is not a data record (e.g. the answer to a query): sent as is.
    pub fn reply(&mut self, bytes: &[u8]) {
        if self.silent_until.is_none() && self.unplug.is_none() {
            self.out.extend_from_slice(bytes);
        }
    }

    /// A data record, subject to the faults planned for its number.
    pub fn record(&mut self, bytes: &[u8]) {
        if self.silent_until.is_some() || self.unplug.is_some() {
            return;
        }
        let k = self.next_record;
        self.next_record += 1;
        let mut len = bytes.len();
        let mut corrupt = None;
        while let Some((at, _)) = self.faults.first() {
            if *at > k {
                break;
            }
            let (at, fault) = self.faults.remove(0);
            if at < k {
                continue;
            }
            match fault {
                Fault::Garbage(g) => self.out.extend_from_slice(&g),
                Fault::Truncate(n) => len = len.min(n),
                Fault::Corrupt(i) => corrupt = Some(i),
                Fault::Silence(d) => {
                    self.silent_until = Some(Instant::now().checked_add(d));
                    return;
                }
                Fault::Unplug(d) => {
                    self.unplug = Some(d);
                    return;
                }
            }
        }
        let start = self.out.len();
        self.out.extend_from_slice(&bytes[..len]);
        if let Some(i) = corrupt {
            if let Some(b) = self.out.get_mut(start + i) {
                *b ^= 0x5a;
            }
        }
    }

    /// Records numbered so far (the next record's number).
    pub fn records(&self) -> u64 {
        self.next_record
    }
}

/// An emulated device's protocol logic, driven by the server loop.
pub trait Device: Send {
    /// Bytes the driver sent.
    fn on_input(&mut self, bytes: &[u8], now: Instant, out: &mut Emit);
    /// Time passes: stream what is due. Returns when it wants to be called next.
    fn on_tick(&mut self, now: Instant, out: &mut Emit) -> Option<Instant>;
    /// The cable came back: the device restarts from power-up.
    fn power_up(&mut self) {}
}

/// The time between records at `rate_hz` (1..=10000 Hz; anything else, NaN included, gives
/// 100 Hz rather than a panic, since the rate may come from a command line).
pub fn period(rate_hz: f64) -> Duration {
    let r = if rate_hz.is_finite() && rate_hz > 0.0 {
        rate_hz.clamp(1.0, 10_000.0)
    } else {
        100.0
    };
    Duration::from_secs_f64(1.0 / r)
}

fn publish_link(pty: &Pty, link: &Path) -> io::Result<()> {
    if let Ok(meta) = std::fs::symlink_metadata(link) {
        if meta.file_type().is_symlink() {
            std::fs::remove_file(link)?;
        } else {
            return Err(io::Error::new(
                io::ErrorKind::AlreadyExists,
                format!(
                    "{} exists and is not a symlink; choose another --link path",
                    link.display()
                ),
            ));
        }
    }
    std::os::unix::fs::symlink(&pty.path, link)
}

/// Serves `device` on a pty published at `link` until `stop()` is true.
pub fn serve(
    link: &Path,
    device: &mut dyn Device,
    faults: Vec<(u64, Fault)>,
    stop: &dyn Fn() -> bool,
) -> io::Result<EmulatorReport> {
    let mut report = EmulatorReport::default();
    let mut emit = Emit::new(faults);
    let mut pty = Some(Pty::open()?);
    if let Some(p) = &pty {
        publish_link(p, link)?;
    }
    let mut replug_at: Option<Instant> = None;
    let mut next_tick: Option<Instant> = None;
    let mut inbuf = [0u8; 512];
    let result = loop {
        if stop() {
            // Take in what the driver sent last (e.g. its stop-streaming command on close).
            if let Some(p) = &pty {
                while let Ok(n) = p.read(&mut inbuf) {
                    if n == 0 {
                        break;
                    }
                    report.bytes_in += n as u64;
                    let room = 4096usize.saturating_sub(report.received.len());
                    report.received.extend_from_slice(&inbuf[..n.min(room)]);
                }
            }
            break Ok(());
        }
        let now = Instant::now();
        if let Some(t) = replug_at {
            if now < t {
                std::thread::sleep((t - now).min(Duration::from_millis(10)));
                continue;
            }
            let p = match Pty::open() {
                Ok(p) => p,
                Err(e) => break Err(e),
            };
            if let Err(e) = publish_link(&p, link) {
                break Err(e);
            }
            pty = Some(p);
            replug_at = None;
            device.power_up();
        }
        let Some(p) = &pty else {
            break Ok(());
        };
        let wait_ms = next_tick
            .map(|t| t.saturating_duration_since(now).as_millis() as i32)
            .unwrap_or(10)
            .clamp(0, 10);
        match p.wait_readable(wait_ms) {
            Ok(_) => {}
            Err(e) => break Err(e),
        }
        let now = Instant::now();
        if let Some(until) = emit.silent_until {
            if until.is_some_and(|t| now >= t) {
                emit.silent_until = None;
            }
        }
        loop {
            // An error (EIO: no slave open, which cannot happen while we hold one) reads as
            // quiet.
            let n = p.read(&mut inbuf).unwrap_or(0);
            if n == 0 {
                break;
            }
            report.bytes_in += n as u64;
            let room = 4096usize.saturating_sub(report.received.len());
            report.received.extend_from_slice(&inbuf[..n.min(room)]);
            if emit.silent_until.is_none() {
                device.on_input(&inbuf[..n], now, &mut emit);
            }
        }
        next_tick = if emit.silent_until.is_none() {
            device.on_tick(now, &mut emit)
        } else {
            None
        };
        if !emit.out.is_empty() {
            p.write(&emit.out);
            emit.out.clear();
        }
        if let Some(d) = emit.unplug.take() {
            report.unplugs += 1;
            pty = None;
            let _ = std::fs::remove_file(link);
            replug_at = Some(
                Instant::now()
                    .checked_add(d)
                    .unwrap_or_else(|| Instant::now() + Duration::from_secs(365 * 24 * 3600)),
            );
        }
    };
    report.records = emit.records();
    drop(pty);
    if std::fs::symlink_metadata(link).is_ok_and(|m| m.file_type().is_symlink()) {
        let _ = std::fs::remove_file(link);
    }
    result.map(|()| report)
}

/// A running emulator on its own thread.
pub struct Emulator {
    link: PathBuf,
    dir: PathBuf,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<io::Result<EmulatorReport>>>,
}

static NEXT_DIR: AtomicU64 = AtomicU64::new(0);

impl Emulator {
    /// Starts `device` on a thread, on a pty linked from a fresh temporary folder.
    pub fn spawn(
        name: &str,
        mut device: Box<dyn Device>,
        faults: Vec<(u64, Fault)>,
    ) -> io::Result<Emulator> {
        let dir = std::env::temp_dir().join(format!(
            "handblocks-emu-{}-{}",
            std::process::id(),
            NEXT_DIR.fetch_add(1, Ordering::Relaxed)
        ));
        std::fs::create_dir_all(&dir)?;
        let link = dir.join(name);
        let stop = Arc::new(AtomicBool::new(false));
        let (ready_tx, ready_rx) = std::sync::mpsc::channel();
        let thread = {
            let stop = stop.clone();
            let link = link.clone();
            std::thread::Builder::new()
                .name(format!("emulate-{name}"))
                .spawn(move || {
                    let stop_fn = || stop.load(Ordering::Relaxed);
                    // Signal readiness once the link exists (first loop turn).
                    let ready = std::cell::Cell::new(Some(ready_tx));
                    let stop_and_ready = || {
                        if let Some(tx) = ready.take() {
                            let _ = tx.send(());
                        }
                        stop_fn()
                    };
                    serve(&link, device.as_mut(), faults, &stop_and_ready)
                })?
        };
        let mut emu = Emulator {
            link,
            dir,
            stop,
            thread: Some(thread),
        };
        if ready_rx.recv_timeout(Duration::from_secs(5)).is_err() {
            // The thread ended before serving (e.g. no ptys): report why.
            let err = emu.stop_inner().err().unwrap_or_else(|| {
                io::Error::new(io::ErrorKind::TimedOut, "the emulator did not start")
            });
            return Err(err);
        }
        Ok(emu)
    }

    /// The path a driver opens (a symlink to the current pty).
    pub fn path(&self) -> &Path {
        &self.link
    }

    /// Stops the emulator, joins its thread, removes its folder.
    pub fn stop(mut self) -> io::Result<EmulatorReport> {
        self.stop_inner()
    }

    fn stop_inner(&mut self) -> io::Result<EmulatorReport> {
        self.stop.store(true, Ordering::Relaxed);
        let result = match self.thread.take() {
            Some(t) => t
                .join()
                .map_err(|_| io::Error::other("the emulator thread panicked"))?,
            None => Ok(EmulatorReport::default()),
        };
        let _ = std::fs::remove_dir_all(&self.dir);
        result
    }
}

impl Drop for Emulator {
    fn drop(&mut self) {
        if self.thread.is_some() {
            let _ = self.stop_inner();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fault_specs_parse_and_errors_say_the_form() {
        assert_eq!(
            Fault::parse("silence@400:1500"),
            Ok((400, Fault::Silence(Duration::from_millis(1500))))
        );
        assert_eq!(
            Fault::parse("silence@4:forever"),
            Ok((4, Fault::Silence(Duration::MAX)))
        );
        assert_eq!(Fault::parse("truncate@2:5"), Ok((2, Fault::Truncate(5))));
        assert_eq!(
            Fault::parse("garbage@1:ab"),
            Ok((1, Fault::Garbage(b"ab".to_vec())))
        );
        assert!(matches!(
            Fault::parse("garbage@1"),
            Ok((1, Fault::Garbage(_)))
        ));
        assert!(Fault::parse("unplug@x:1")
            .unwrap_err()
            .contains("not a whole number"));
        assert!(Fault::parse("melt@1").unwrap_err().contains("KIND@RECORD"));
        assert!(Fault::parse("corrupt@1")
            .unwrap_err()
            .contains("after a colon"));
    }

    #[test]
    fn emit_applies_faults_by_record_number() {
        let mut e = Emit::new(vec![
            (1, Fault::Truncate(2)),
            (2, Fault::Garbage(b"xx".to_vec())),
            (2, Fault::Corrupt(0)),
            (3, Fault::Silence(Duration::MAX)),
        ]);
        for _ in 0..5 {
            e.record(b"abcd");
        }
        e.reply(b"!");
        assert_eq!(
            e.out,
            [b"abcd".as_slice(), b"ab", b"xx", &[b'a' ^ 0x5a], b"bcd"].concat()
        );
        assert_eq!(e.records(), 4);
    }
}
