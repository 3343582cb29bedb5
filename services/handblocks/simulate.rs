//! `handblocks simulate SCENE`: a scene's block world alone, in one process, deterministically;
//! the hand from the scene's keyframes or, with `--hand TRACE`, from a trace, made into hands
//! by kinematics' [`kinematics::HandStream`] exactly as the live process makes them.

use std::path::PathBuf;
use std::process::ExitCode;

use common::config::scene::ModelKind;
use common::config::Scene;

/// What `handblocks simulate` was given.
pub struct SimulateArgs {
    pub scene: PathBuf,
    pub frames: Option<u64>,
    /// `paper` or `precise` (clap allows only those): replaces the scene's [world] model.
    pub model: Option<String>,
    /// `--hand TRACE`: one of our recordings or a CARL file, in place of the scene's [hand].
    pub trace: Option<PathBuf>,
    pub hand_offset: [f64; 3],
    /// `--hands left|right|both`: which hands of the trace drive (default: the right).
    pub hands: common::HandsUsed,
    pub json: bool,
    /// `--world-hashes`: `STEP HASH` after every step instead of the report.
    pub world_hashes: bool,
    /// `--set KEY=VALUE`: scene keys given on the command line.
    pub overrides: Vec<common::config::session::Override>,
}

pub use simulation::SimulateError;

pub fn run(args: SimulateArgs) -> Result<ExitCode, SimulateError> {
    if let Some(why) = crate::locate::missing(&args.scene, crate::locate::Kind::Scene)
        .or_else(|| crate::locate::wrong_kind(&args.scene, crate::locate::Kind::Scene))
    {
        return Err(SimulateError::Scene(common::config::ConfigError::new(
            &args.scene,
            "",
            why,
        )));
    }
    let file = crate::locate::resolve(&args.scene, crate::locate::Kind::Scene);
    let scene = Scene::load_with(&file, &args.overrides).map_err(SimulateError::Scene)?;
    let settings = simulation::SimulateSettings {
        model: match args.model.as_deref() {
            Some("precise") => Some(ModelKind::Precise),
            Some(_) => Some(ModelKind::Paper),
            None => None,
        },
        trace: args.trace,
        hand_offset: args.hand_offset,
        hands: args.hands,
        frames: args.frames,
    };
    if args.world_hashes {
        // One line a step, as `inspect --world-hashes` prints a recording's worlds.
        use std::io::Write as _;
        let mut out = std::io::BufWriter::new(std::io::stdout().lock());
        let mut sample = common::WorldSample::default();
        let (_, notes) = simulation::run_with_progress(&scene, &settings, &mut |_, world| {
            world.write_sample(&mut sample);
            let hash = common::world_hash::world_hash(&sample.header, &sample.blocks);
            let _ = writeln!(out, "{} {hash:016x}", sample.header.step);
            Ok(())
        })?;
        let _ = out.flush();
        for line in &notes.lines {
            eprintln!("handblocks simulate: {line}");
        }
        return Ok(ExitCode::SUCCESS);
    }
    let (report, notes) = simulation::run(&scene, &settings)?;
    for line in &notes.lines {
        eprintln!("handblocks simulate: {line}");
    }
    if args.json {
        print!("{}", report.to_json());
    } else {
        print!("{}", report.to_text());
    }
    Ok(ExitCode::SUCCESS)
}
