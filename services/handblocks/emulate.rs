//! `handblocks emulate glove|tracker --link PATH`: a CyberGlove or a FASTRAK on a
//! pseudo-terminal (acquisition's emulator), for sessions without hardware; `handblocks
//! emulate headset URL --trace FILE`: a headset's browser (headless Chromium with IWER as its
//! XR runtime) playing a recorded hand through a webxr session's page.

use std::fmt;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use acquisition::emulator::{glove, tracker, Fault};
use common::shutdown;
use webxr_wire::playback;

/// Why the emulated device did not run.
#[derive(Debug)]
pub enum EmulateError {
    /// A `--fault` spec was refused (the message says the syntax).
    Fault(String),
    /// `--rate` is not a usable record rate.
    Rate(f64),
    /// The pty or its link could not be made or served.
    Device {
        link: PathBuf,
        error: std::io::Error,
    },
    /// A key this device needs is missing, or one it does not take was given.
    Usage(String),
    /// The trace cannot be played (the message names the file).
    Trace(String),
    /// A tool the emulated headset needs is missing (the message says how to install it).
    Tool(String),
    /// The browser's driver failed (what it said is above).
    Driver(String),
}

impl fmt::Display for EmulateError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            EmulateError::Fault(e) => write!(f, "--fault: {e}"),
            EmulateError::Rate(r) => write!(
                f,
                "--rate {r}: allowed: more than 0 up to 10000 records per second"
            ),
            EmulateError::Device { link, error } => write!(f, "{}: {error}", link.display()),
            EmulateError::Usage(m)
            | EmulateError::Trace(m)
            | EmulateError::Tool(m)
            | EmulateError::Driver(m) => f.write_str(m),
        }
    }
}

impl std::error::Error for EmulateError {}

/// Serves the device until Ctrl-C, then says what it did.
pub fn run(
    device: &str,
    link: Option<&Path>,
    sensors: u8,
    rate: Option<f64>,
    faults: &[String],
) -> Result<ExitCode, EmulateError> {
    let faults = faults
        .iter()
        .map(|f| Fault::parse(f))
        .collect::<Result<Vec<_>, _>>()
        .map_err(EmulateError::Fault)?;
    let link = link.ok_or_else(|| {
        EmulateError::Usage(format!(
            "a {device} needs --link PATH: where the device appears (e.g. /tmp/glove)"
        ))
    })?;
    if let Some(r) = rate.filter(|r| !(r.is_finite() && *r > 0.0 && *r <= 10_000.0)) {
        return Err(EmulateError::Rate(r));
    }
    // The link is made in an existing folder: say so before the device starts.
    if let Some(dir) = link
        .parent()
        .filter(|d| !d.as_os_str().is_empty() && !d.is_dir())
    {
        return Err(EmulateError::Usage(format!(
            "--link {}: the folder {} does not exist; give a path in an existing folder (e.g. \
             /tmp/{device})",
            link.display(),
            dir.display()
        )));
    }
    shutdown::install_signal_handlers();
    eprintln!(
        "handblocks emulate: a {device} at {} (Ctrl-C stops it)",
        link.display()
    );
    let stop = || shutdown::requested();
    let result = if device == "glove" {
        let mut b = glove::GloveBehaviour::new(sensors);
        b.rate_hz = rate.unwrap_or(b.rate_hz);
        b.faults = faults;
        glove::run(link, b, &stop)
    } else {
        let mut b = tracker::TrackerBehaviour::new();
        b.rate_hz = rate.unwrap_or(b.rate_hz);
        b.faults = faults;
        tracker::run(link, b, &stop)
    };
    let report = result.map_err(|error| EmulateError::Device {
        link: link.to_path_buf(),
        error,
    })?;
    eprintln!(
        "handblocks emulate: stopped after {} records, {} unplugs; commands received: {:?}",
        report.records,
        report.unplugs,
        String::from_utf8_lossy(&report.received)
    );
    Ok(ExitCode::SUCCESS)
}

/// `emulate headset`'s arguments.
pub struct Headset {
    pub url: Option<String>,
    pub trace: Option<PathBuf>,
    /// The page's hands that play the trace: one (the trace's hand, the right of a CARL
    /// file), or both (a CARL file's right and left, or a two-hand recording's).
    pub hand: common::HandsUsed,
    pub screenshot: Option<PathBuf>,
    pub spectator: bool,
}

/// Plays a trace through a webxr session's page in headless Chromium (or, `--spectator`,
/// opens it as a spectator), through the browser driver `webxr::driver::HEADSET_JS` run by
/// Node.js; prints the driver's summary (JSON, indented for a person; still one JSON value
/// for a program) on stdout.
pub fn headset(h: Headset) -> Result<ExitCode, EmulateError> {
    let url = h.url.ok_or_else(|| {
        EmulateError::Usage(
            "headset needs the page's URL, as the webxr session printed it (with ?token=...)"
                .into(),
        )
    })?;
    if let (true, Some(trace)) = (h.spectator, &h.trace) {
        return Err(EmulateError::Usage(format!(
            "--spectator plays no trace: it opens the page as a spectator; give --spectator or \
             --trace {} (which plays it through the headset), not both",
            trace.display()
        )));
    }
    let work = std::env::temp_dir().join(format!("handblocks-headset-{}", std::process::id()));
    std::fs::create_dir_all(&work)
        .map_err(|e| EmulateError::Tool(format!("{}: {e}", work.display())))?;
    let driver = work.join("headset.js");
    std::fs::write(&driver, webxr::driver::HEADSET_JS)
        .map_err(|e| EmulateError::Tool(format!("{}: {e}", driver.display())))?;
    let mut args: Vec<std::ffi::OsString> = vec![driver.into(), "--url".into(), url.into()];
    if h.spectator {
        args.push("--spectator".into());
    } else {
        let trace = h.trace.ok_or_else(|| {
            EmulateError::Usage(
                "headset needs --trace FILE (a CARL file or a recording with joints), or \
                 --spectator"
                    .into(),
            )
        })?;
        let samples = work.join("samples.bin");
        let n = write_headset_samples(&trace, &samples, h.hand)?;
        eprintln!(
            "handblocks emulate: playing {n} samples of {} as {}",
            trace.display(),
            match h.hand {
                common::HandsUsed::Both => "both hands".to_string(),
                common::HandsUsed::One(side) => format!("the {} hand", side.name()),
            }
        );
        args.extend(["--samples".into(), samples.into()]);
        args.extend(["--hand".into(), h.hand.name().into()]);
    }
    if let Some(png) = &h.screenshot {
        args.extend(["--screenshot".into(), png.into()]);
    }
    let node = std::env::var_os("HB_NODE").unwrap_or_else(|| "node".into());
    let modules = webxr_node_modules();
    let chromium = std::env::var_os("HB_CHROMIUM").unwrap_or_else(|| "/usr/bin/chromium".into());
    if !Path::new(&chromium).exists() {
        return Err(EmulateError::Tool(format!(
            "no Chromium at {} (set HB_CHROMIUM, or install Debian's `chromium`; tests/run \
             installs it)",
            Path::new(&chromium).display()
        )));
    }
    if !modules.join("playwright-core").is_dir() || !modules.join("iwer").is_dir() {
        return Err(EmulateError::Tool(format!(
            "no playwright-core and iwer in {} (scripts/webxr-tools.sh installs them there; \
             or set HB_WEBXR_NODE_PATH to a node_modules that has them)",
            modules.display()
        )));
    }
    let out = std::process::Command::new(&node)
        .args(&args)
        .env("NODE_PATH", &modules)
        .env("HB_CHROMIUM", &chromium)
        .stderr(std::process::Stdio::inherit())
        .output()
        .map_err(|e| {
            EmulateError::Tool(format!(
                "cannot run {} ({e}): the emulated headset needs Node.js (set HB_NODE)",
                Path::new(&node).display()
            ))
        })?;
    let _ = std::fs::remove_dir_all(&work);
    let stdout = String::from_utf8_lossy(&out.stdout);
    match serde_json::from_str::<serde_json::Value>(stdout.trim()) {
        Ok(summary) => println!(
            "{}",
            serde_json::to_string_pretty(&summary).unwrap_or_else(|_| stdout.trim().to_string())
        ),
        Err(_) => print!("{stdout}"),
    }
    if !out.status.success() {
        return Err(EmulateError::Driver(format!(
            "the browser's driver failed ({}); what it said is above",
            out.status
        )));
    }
    Ok(ExitCode::SUCCESS)
}

/// Where the emulated headset's Node modules are: `HB_WEBXR_NODE_PATH`, or `webxr-node` in
/// the build folder the running binary is in (`target/webxr-node/node_modules`).
fn webxr_node_modules() -> PathBuf {
    if let Some(p) = std::env::var_os("HB_WEBXR_NODE_PATH") {
        return PathBuf::from(p);
    }
    let exe = std::env::current_exe().unwrap_or_default();
    exe.parent()
        .and_then(Path::parent)
        .map(|target| target.join("webxr-node/node_modules"))
        .unwrap_or_else(|| PathBuf::from("target/webxr-node/node_modules"))
}

/// The trace's joints as the driver plays them ([`webxr_wire::playback`]): per sample one
/// record per hand played (`hands`: one, or both, the right then the left), its time in ms
/// from the first sample (so that the page's time maps back to the trace's nanoseconds
/// exactly) and WebXR's joints ([`webxr_wire::from_joints`]). One hand is the trace's (a CARL
/// file's right); both are a CARL file's two hands, or a recording's `joints` of either side,
/// paired by source time (a hand a sample lacks is written untracked). Returns the sample
/// count.
fn write_headset_samples(
    trace: &Path,
    file: &Path,
    hands: common::HandsUsed,
) -> Result<usize, EmulateError> {
    let t = match hands {
        common::HandsUsed::Both => replay::HandTrace::load_hands(trace, [0.0; 3], hands),
        common::HandsUsed::One(_) => replay::HandTrace::load(trace, [0.0; 3]),
    }
    .map_err(EmulateError::Trace)?;
    let joints: Vec<&common::JointsSample> = t
        .samples
        .iter()
        .filter_map(|s| match s {
            replay::SourceSample::Joints(j) => Some(j),
            _ => None,
        })
        .collect();
    if joints.is_empty() {
        return Err(EmulateError::Trace(format!(
            "{}: no joints to play (a headset plays a hand tracker's joints: a CARL file, or a \
             recording of a replayed CARL or webxr session)",
            trace.display()
        )));
    }
    // Each sample's hands, by slot (0 the right or the one hand, 1 the left).
    let mut frames: Vec<[Option<&common::JointsSample>; 2]> = Vec::with_capacity(joints.len());
    for j in &joints {
        let slot = match hands {
            common::HandsUsed::Both => {
                usize::from(common::HandSide::from_code(j.side) == common::HandSide::Left)
            }
            common::HandsUsed::One(_) => 0,
        };
        match frames.last_mut() {
            Some(f)
                if f[slot].is_none()
                    && f.iter()
                        .flatten()
                        .all(|o| o.stamp.source_time_ns == j.stamp.source_time_ns) =>
            {
                f[slot] = Some(j);
            }
            _ => {
                let mut f = [None, None];
                f[slot] = Some(*j);
                frames.push(f);
            }
        }
    }
    if hands == common::HandsUsed::Both && frames.iter().all(|f| f[1].is_none()) {
        return Err(EmulateError::Trace(format!(
            "{}: --hand both: the trace holds one hand (both are a CARL file's two hands, or a \
             recording of a two-hand session); play it with --hand right or left",
            trace.display()
        )));
    }
    let played = if hands == common::HandsUsed::Both {
        2
    } else {
        1
    };
    let t0 = frames[0]
        .iter()
        .flatten()
        .map(|j| j.stamp.source_time_ns)
        .min()
        .unwrap_or(0);
    let records: Vec<[playback::Record; 2]> = frames
        .iter()
        .map(|f| {
            let time_ns = f.iter().flatten().map(|j| j.stamp.source_time_ns).min();
            let time_ms = time_ns.unwrap_or(t0).saturating_sub(t0) as f64 / 1e6;
            f.map(|hand| playback::Record {
                time_ms,
                tracked: hand.is_some_and(|j| j.tracked != 0),
                poses: hand.map_or([common::Pose::IDENTITY; webxr_wire::WEBXR_JOINTS], |j| {
                    webxr_wire::from_joints(j)
                }),
            })
        })
        .collect();
    let mut bytes = Vec::with_capacity(4 + frames.len() * played * playback::RECORD_BYTES);
    playback::encode(records.iter().map(|r| &r[..played]), &mut bytes);
    std::fs::write(file, &bytes)
        .map_err(|e| EmulateError::Trace(format!("{}: {e}", file.display())))?;
    Ok(frames.len())
}
