//! Session files: which scene, which source feeds the pipeline, renderer and recorder settings,
//! and the interactive-rate budget (DESIGN.md, "Sessions").

use std::path::{Path, PathBuf};

use super::hand::HandModelSpec;
use super::reader::{parse_file, Reader};
use super::scene::Scene;
use super::ConfigError;

/// A whole session file, with its scene loaded.
#[derive(Debug, Clone, PartialEq)]
pub struct Session {
    pub file: PathBuf,
    /// The scene file, resolved against the session file's folder.
    pub scene_file: PathBuf,
    pub scene: Scene,
    pub source: Source,
    pub renderer: RendererSettings,
    pub recorder: RecorderSettings,
    pub budget: Budget,
    /// The hand model (`hand_model = "../hand.toml"`); the built-in adult hand when absent.
    pub hand_model: HandModelSpec,
}

/// `[source]`: what feeds the pipeline.
#[derive(Debug, Clone, PartialEq)]
pub enum Source {
    /// The scene's `[hand]` keyframes, sampled at `rate_hz`.
    Scripted { rate_hz: f64 },
    /// A CyberGlove and a FASTRAK on serial ports. The tables are the device drivers' own
    /// settings (acquisition::devices::settings reads and checks them; this crate cannot know
    /// the drivers), kept as written, with the folder relative paths are resolved against.
    Devices {
        glove: toml::Table,
        tracker: toml::Table,
        dir: PathBuf,
    },
    /// A recorded hand (one of our MCAP recordings or a CARL trace); `speed` 0 = as fast as the pipeline consumes;
    /// `offset` moves the recorded hand, metres (real traces hold it ~1 m above the floor).
    Replay {
        file: PathBuf,
        speed: f64,
        offset: [f64; 3],
    },
}

impl Source {
    pub fn kind(&self) -> &'static str {
        match self {
            Source::Scripted { .. } => "scripted",
            Source::Devices { .. } => "devices",
            Source::Replay { .. } => "replay",
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RenderMode {
    Window,
    Headless,
    Off,
}

/// `[renderer]`.
#[derive(Debug, Clone, PartialEq)]
pub struct RendererSettings {
    pub mode: RenderMode,
    /// Per eye.
    pub width: u32,
    pub height: u32,
    /// "side-by-side", "anaglyph" (red-cyan) or "separate" (one image per eye).
    pub output: String,
    /// Distance between the eyes, millimetres (adults: 50-75, mean 63).
    pub ipd_mm: f64,
    /// The screen plane both eyes' frusta share (zero disparity), metres from the eyes.
    pub screen_distance_m: f64,
    pub screen_width_m: f64,
    /// Where the eyes' midpoint is and what it looks at, world frame.
    pub eye: [f64; 3],
    pub target: [f64; 3],
    pub shadows: bool,
    /// With `launch --frames-dir`, write every Nth frame.
    pub frames_every: u32,
    /// Run the renderer (and the recorder) on CPUs of their own, apart from the pipeline's,
    /// when the machine has at least two. A software rasteriser otherwise delays the stepper's
    /// wake-ups by milliseconds however low its priority.
    pub own_cpus: bool,
}

impl Default for RendererSettings {
    fn default() -> Self {
        RendererSettings {
            mode: RenderMode::Headless,
            width: 640,
            height: 480,
            output: "side-by-side".into(),
            ipd_mm: 63.0,
            screen_distance_m: 0.6,
            screen_width_m: 0.52,
            eye: [0.0, 0.75, 1.1],
            target: [0.0, 0.05, 0.0],
            shadows: true,
            frames_every: 1,
            own_cpus: true,
        }
    }
}

/// `[recorder]`.
#[derive(Debug, Clone, PartialEq)]
pub struct RecorderSettings {
    /// None: the recorder runs (it counts what flows) but writes no file.
    pub file: Option<PathBuf>,
}

/// `[budget]`: the interactive-rate budget; exceeding a limit fails the session.
#[derive(Debug, Clone, PartialEq)]
pub struct Budget {
    /// The renderer's frame rate.
    pub frame_hz: f64,
    pub origin_to_world_p99_us: Option<f64>,
    pub hop_p99_us: Option<f64>,
    pub origin_to_photon_p99_ms: Option<f64>,
    pub max_dropped: Option<u64>,
}

impl Default for Budget {
    fn default() -> Self {
        Budget {
            frame_hz: 90.0,
            origin_to_world_p99_us: None,
            hop_p99_us: None,
            origin_to_photon_p99_ms: None,
            max_dropped: None,
        }
    }
}

impl Session {
    /// Reads a session file and the scene it names.
    pub fn load(file: &Path) -> Result<Session, ConfigError> {
        let table = parse_file(file)?;
        let r = Reader::new(file, "", &table);
        let dir = file.parent().unwrap_or(Path::new("."));
        let scene_name = r
            .string("scene")?
            .ok_or_else(|| r.err("scene", "required: the scene file, relative to this file"))?;
        let scene_file = dir.join(&scene_name);
        let scene = Scene::load(&scene_file)?;
        let source = source(r.table("source")?, dir)?;
        if matches!(source, Source::Scripted { .. }) && scene.hand.is_none() {
            return Err(r.err(
                "source.kind",
                format!(
                    "\"scripted\" needs a [hand] in the scene {}; add one or choose another source",
                    scene_file.display()
                ),
            ));
        }
        let session = Session {
            file: file.to_path_buf(),
            scene_file,
            scene,
            source,
            renderer: renderer(r.table("renderer")?)?,
            recorder: recorder(r.table("recorder")?, dir)?,
            budget: budget(r.table("budget")?)?,
            hand_model: match r.string("hand_model")? {
                Some(f) => HandModelSpec::load(&dir.join(f))?,
                None => HandModelSpec::default(),
            },
        };
        r.finish()?;
        Ok(session)
    }
}

fn source(r: Option<Reader>, dir: &Path) -> Result<Source, ConfigError> {
    let Some(r) = r else {
        return Ok(Source::Scripted { rate_hz: 120.0 });
    };
    let s = match r.choice("kind", &["scripted", "devices", "replay"])? {
        "devices" => {
            let table = |key: &'static str| -> Result<toml::Table, ConfigError> {
                match r.raw(key) {
                    Some(toml::Value::Table(t)) => Ok(t.clone()),
                    Some(v) => Err(r.err(key, format!("expected a table, found {}", v.type_str()))),
                    None => Err(r.err(
                        key,
                        "required for kind = \"devices\": { port = \"/dev/ttyUSB0\", ... }",
                    )),
                }
            };
            Source::Devices {
                glove: table("glove")?,
                tracker: table("tracker")?,
                dir: dir.to_path_buf(),
            }
        }
        "replay" => {
            let f = r.string("file")?.ok_or_else(|| {
                r.err(
                    "file",
                    "required for kind = \"replay\": the recording or CARL file",
                )
            })?;
            Source::Replay {
                file: dir.join(f),
                speed: r.f64_in("speed", Some(1.0), 0.0..=1000.0)?.unwrap_or(1.0),
                offset: r.array::<3>("offset", -1.0e5..=1.0e5)?.unwrap_or([0.0; 3]),
            }
        }
        _ => Source::Scripted {
            rate_hz: r
                .f64_in("rate_hz", Some(120.0), 1.0..=10_000.0)?
                .unwrap_or(120.0),
        },
    };
    r.finish()?;
    Ok(s)
}

fn renderer(r: Option<Reader>) -> Result<RendererSettings, ConfigError> {
    let d = RendererSettings::default();
    let Some(r) = r else { return Ok(d) };
    let place = -1.0e5..=1.0e5;
    let s = RendererSettings {
        mode: match r.choice("mode", &["headless", "window", "off"])? {
            "window" => RenderMode::Window,
            "off" => RenderMode::Off,
            _ => RenderMode::Headless,
        },
        width: r.u64_in("width", 640, 16..=8192)? as u32,
        height: r.u64_in("height", 480, 16..=8192)? as u32,
        output: r
            .choice("output", &["side-by-side", "anaglyph", "separate"])?
            .to_string(),
        ipd_mm: r
            .f64_in("ipd_mm", Some(d.ipd_mm), 0.0..=100.0)?
            .unwrap_or(d.ipd_mm),
        screen_distance_m: r
            .f64_in("screen_distance_m", Some(d.screen_distance_m), 0.05..=100.0)?
            .unwrap_or(d.screen_distance_m),
        screen_width_m: r
            .f64_in("screen_width_m", Some(d.screen_width_m), 0.01..=100.0)?
            .unwrap_or(d.screen_width_m),
        eye: r.array::<3>("eye", place.clone())?.unwrap_or(d.eye),
        target: r.array::<3>("target", place)?.unwrap_or(d.target),
        shadows: r.bool("shadows", d.shadows)?,
        frames_every: r.u64_in("frames_every", 1, 1..=1_000_000)? as u32,
        own_cpus: r.bool("own_cpus", d.own_cpus)?,
    };
    if s.eye == s.target {
        return Err(r.err(
            "target",
            "must differ from `eye` (the camera looks from eye to target)",
        ));
    }
    r.finish()?;
    Ok(s)
}

fn recorder(r: Option<Reader>, dir: &Path) -> Result<RecorderSettings, ConfigError> {
    let Some(r) = r else {
        return Ok(RecorderSettings { file: None });
    };
    let s = RecorderSettings {
        file: r.string("file")?.map(|f| dir.join(f)),
    };
    r.finish()?;
    Ok(s)
}

fn budget(r: Option<Reader>) -> Result<Budget, ConfigError> {
    let d = Budget::default();
    let Some(r) = r else { return Ok(d) };
    let b = Budget {
        frame_hz: r
            .f64_in("frame_hz", Some(d.frame_hz), 1.0..=1000.0)?
            .unwrap_or(d.frame_hz),
        origin_to_world_p99_us: r.f64_in("origin_to_world_p99_us", None, 0.0..=1e9)?,
        hop_p99_us: r.f64_in("hop_p99_us", None, 0.0..=1e9)?,
        origin_to_photon_p99_ms: r.f64_in("origin_to_photon_p99_ms", None, 0.0..=1e6)?,
        max_dropped: if r.has("max_dropped") {
            Some(r.u64_in("max_dropped", 0, 0..=u64::MAX >> 1)?)
        } else {
            None
        },
    };
    r.finish()?;
    Ok(b)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    fn tmpdir(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("hb-session-test-{tag}-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    const SCENE: &str = "[hand]\n[[hand.key]]\nt = 0\nwrist = [0, 0.3, 0]\n";

    #[test]
    fn a_session_resolves_its_scene_and_budget() {
        let d = tmpdir("ok");
        write(&d, "scene.toml", SCENE);
        let s = write(&d, "s.toml", "scene = \"scene.toml\"\n[budget]\nframe_hz = 60\nmax_dropped = 0\norigin_to_world_p99_us = 500\n");
        let s = Session::load(&s).unwrap();
        assert_eq!(s.scene_file, d.join("scene.toml"));
        assert_eq!(s.budget.max_dropped, Some(0));
        assert_eq!(s.budget.origin_to_world_p99_us, Some(500.0));
        assert_eq!(s.source, Source::Scripted { rate_hz: 120.0 });
        std::fs::remove_dir_all(d).unwrap();
    }

    #[test]
    fn errors_name_file_key_and_allowed_values() {
        let d = tmpdir("bad");
        write(&d, "scene.toml", SCENE);
        let f = write(
            &d,
            "s.toml",
            "scene = \"scene.toml\"\n[source]\nkind = \"telepathy\"\n",
        );
        let e = Session::load(&f).unwrap_err();
        assert_eq!(e.file, f);
        assert_eq!(e.key, "source.kind");
        assert!(
            e.problem.contains("\"scripted\", \"devices\", \"replay\""),
            "{e}"
        );

        let f = write(
            &d,
            "s2.toml",
            "scene = \"scene.toml\"\n[budget]\nframe_hz = -3\n",
        );
        let e = Session::load(&f).unwrap_err();
        assert_eq!(e.key, "budget.frame_hz");
        assert!(e.to_string().contains("allowed: 1 to 1000"), "{e}");

        let f = write(&d, "s3.toml", "scene = \"missing.toml\"\n");
        let e = Session::load(&f).unwrap_err();
        assert_eq!(e.file, d.join("missing.toml"));

        let f = write(&d, "s4.toml", "scene = \"scene.toml\"\n[budget\n");
        let e = Session::load(&f).unwrap_err();
        assert!(e.problem.contains("not valid TOML"), "{e}");

        let f = write(&d, "s5.toml", "scene = \"scene.toml\"\nbudjet = 1\n");
        let e = Session::load(&f).unwrap_err();
        assert_eq!(e.key, "budjet");
        assert!(e.problem.contains("allowed here: budget"), "{e}");
        std::fs::remove_dir_all(d).unwrap();
    }
}
