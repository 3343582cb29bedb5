//! `handblocks`: the one binary that holds every service of the system.
//!
//! A hand, measured by a data glove and a 6-DoF tracker (or scripted, or replayed), grasps,
//! pushes, carries and throws virtual blocks at interactive rate. `launch` runs a session as
//! separate processes over shared memory; `service` is how the launcher starts each of them.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use clap::{Parser, Subcommand};
use common::bus::{Bus, BusConfig};
use common::config::Session;
use common::{shutdown, Stage};

#[derive(Parser)]
#[command(
    name = "handblocks",
    version,
    about = "A hand grasps, pushes, carries and throws virtual blocks at interactive rate.",
    long_about = "A hand grasps, pushes, carries and throws virtual blocks at interactive rate.\n\n\
        A session runs as independent processes (acquisition, kinematics, stepper, renderer, \
        recorder) exchanging zero-copy samples over iceoryx2; the launcher measures every \
        stage's latency and judges it against the session's [budget].\n\n\
        Start with:  handblocks launch            (the scripted hand, until Ctrl-C)\n\
        \x20            handblocks launch --help     (options and the report)"
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand)]
enum Command {
    /// Run a session: start its processes, measure latency, judge the budget.
    ///
    /// Exit status: 0 when the session ran within its [budget], 1 when it ran but violated the
    /// budget or a process failed, 2 when it could not run (bad config, no processes).
    Launch {
        /// The session file (which scene, which source, renderer, recorder, budget).
        #[arg(default_value = "config/sessions/live.toml")]
        session: PathBuf,
        /// Stop after this many seconds (default: run until Ctrl-C or SIGTERM).
        #[arg(long, value_name = "SECONDS", value_parser = parse_seconds)]
        duration: Option<Duration>,
        /// Also write the report as JSON to this file.
        #[arg(long, value_name = "FILE")]
        report: Option<PathBuf>,
        /// The session's bus id (iceoryx2 prefix `hb_<ID>_`); default: a fresh one.
        #[arg(long, value_name = "ID")]
        bus_id: Option<String>,
        /// No progress lines while running.
        #[arg(long)]
        quiet: bool,
    },
    /// Run one process of a session (the launcher starts each one this way).
    Service {
        /// acquisition, kinematics, stepper, renderer or recorder.
        name: String,
        /// The session file.
        #[arg(long)]
        session: PathBuf,
        /// The session's bus id, as the launcher chose it.
        #[arg(long)]
        bus: String,
    },
}

fn parse_seconds(s: &str) -> Result<Duration, String> {
    let v: f64 = s
        .parse()
        .map_err(|_| format!("{s:?} is not a number of seconds"))?;
    if !(v.is_finite() && v > 0.0 && v <= 86_400.0 * 365.0) {
        return Err(format!(
            "{s}: allowed: more than 0 and at most a year of seconds"
        ));
    }
    Ok(Duration::from_secs_f64(v))
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        None => launch(
            PathBuf::from("config/sessions/live.toml"),
            Some(Duration::from_secs(10)),
            None,
            None,
            false,
        ),
        Some(Command::Launch {
            session,
            duration,
            report,
            bus_id,
            quiet,
        }) => launch(session, duration, report, bus_id, quiet),
        Some(Command::Service { name, session, bus }) => service(&name, &session, &bus),
    }
}

fn launch(
    session: PathBuf,
    duration: Option<Duration>,
    report: Option<PathBuf>,
    bus_id: Option<String>,
    quiet: bool,
) -> ExitCode {
    let exe = match std::env::current_exe() {
        Ok(e) => e,
        Err(e) => {
            eprintln!("handblocks: cannot find my own executable to start the services: {e}");
            return ExitCode::from(2);
        }
    };
    if !quiet {
        let until = duration.map_or("until Ctrl-C".to_string(), |d| {
            format!("for {:.1} s", d.as_secs_f64())
        });
        eprintln!("handblocks: launching {} {until}", session.display());
    }
    let opts = launcher::LaunchOptions {
        session,
        duration,
        report: report.clone(),
        bus_id,
        exe,
        progress: !quiet,
    };
    match launcher::launch(&opts) {
        Ok(outcome) => {
            print!("{}", outcome.report.table());
            if let Some(path) = &report {
                if let Err(e) = launcher::write_report(&outcome.report, path) {
                    eprintln!("handblocks: {e}");
                    return ExitCode::from(2);
                }
            }
            if outcome.report.ok() {
                ExitCode::SUCCESS
            } else {
                ExitCode::from(1)
            }
        }
        Err(e) => {
            eprintln!("handblocks: {e}");
            ExitCode::from(2)
        }
    }
}

fn service(name: &str, session_file: &std::path::Path, bus_id: &str) -> ExitCode {
    shutdown::install_signal_handlers();
    shutdown::watch_parent_pipe();
    let Some(stage) = Stage::from_name(name) else {
        let names: Vec<&str> = Stage::ALL.iter().map(|s| s.name()).collect();
        eprintln!(
            "handblocks service: unknown service {name:?}; one of: {}",
            names.join(", ")
        );
        return ExitCode::from(2);
    };
    let result = (|| -> Result<(), Box<dyn std::error::Error>> {
        let session = Session::load(session_file)?;
        let bus = Bus::open(&BusConfig::for_session(bus_id)?, stage.name())?;
        match stage {
            Stage::Acquisition => acquisition::service::run(&session, &bus),
            Stage::Kinematics => kinematics::service::run(&session, &bus),
            Stage::Stepper => stepper::service::run(&session, &bus),
            Stage::Renderer => renderer::service::run(&session, &bus),
            Stage::Recorder => recorder::service::run(&session, &bus),
            Stage::Replay => Err("the replay source is not available yet (issue 5)".into()),
        }
    })();
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("handblocks {}: {e}", stage.name());
            ExitCode::from(2)
        }
    }
}
