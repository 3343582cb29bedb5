//! `handblocks`: the one binary that holds every service of the system.
//!
//! A hand, measured by a data glove and a 6-DoF tracker (or scripted, or replayed), grasps,
//! pushes, carries and throws virtual blocks at interactive rate. `launch` runs a session as
//! separate processes over shared memory; `service` is how the launcher starts each of them.
//!
//! This file only dispatches: [`cli`] says what can be asked, one module per subcommand does
//! it through the crates (which hold the logic), and every refusal comes back as a
//! [`CliError`] that `main` prints once.

mod bench;
mod cli;
mod completions;
mod config_keys;
mod emulate;
mod error;
mod inspect;
mod launch;
mod list;
mod locate;
mod monitor;
mod replay;
mod service;
mod simulate;
mod world_summary;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;

use cli::{Cli, Command, EmulateDevice};
use error::CliError;

fn main() -> ExitCode {
    match run() {
        Ok(code) => code,
        Err(e) => {
            eprintln!("{e}");
            ExitCode::from(CliError::EXIT_STATUS)
        }
    }
}

/// Runs the subcommand asked for. `Ok` carries its verdict (0, or 1 for a session over its
/// budget or a damaged recording); `Err` is a refusal, which `main` prints and exits 2 for.
/// A command that only prints (simulate, inspect, list, completions) ends quietly when its
/// output pipe closes (`handblocks simulate ... | head`), as Unix tools do, instead of
/// panicking in `println!`. Not for `launch` and the services: they outlive their readers and
/// clean up, so a closed pipe must stay an error they can handle there.
fn end_quietly_on_closed_pipe() {
    // SAFETY: restoring the default disposition of one signal, before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

fn run() -> Result<ExitCode, CliError> {
    let cli = Cli::parse();
    if matches!(
        cli.command,
        Some(
            Command::List { .. }
                | Command::Completions { .. }
                | Command::Simulate { .. }
                | Command::Inspect { .. }
                | Command::Echo { .. }
                | Command::Hz { .. }
                | Command::Sessions { .. }
        )
    ) {
        end_quietly_on_closed_pipe();
    }
    let code = match cli.command {
        // `cargo run --release`: the live session, until Ctrl-C.
        None => launch::run(cli::LaunchArgs {
            session: PathBuf::from(cli::DEFAULT_SESSION),
            ..cli::LaunchArgs::default()
        })?,
        Some(Command::Launch(args)) => launch::run(args)?,
        Some(Command::List { dir }) => list::run(&dir)?,
        Some(Command::Config { what }) => config_keys::run(what),
        Some(Command::Completions { shell }) => completions::run(shell),
        Some(Command::Simulate {
            scene,
            frames,
            model,
            hand,
            hand_offset,
            hands,
            json,
            world_hashes,
            overrides,
        }) => simulate::run(simulate::SimulateArgs {
            world_hashes,
            hands: hands
                .as_deref()
                .and_then(common::HandsUsed::parse)
                .unwrap_or_default(),
            scene,
            frames,
            model,
            trace: hand,
            hand_offset: hand_offset.unwrap_or_default(),
            json,
            overrides,
        })?,
        Some(Command::Inspect {
            recording,
            json,
            samples: lines,
        }) => {
            if let Some(why) = inspect::refuse(&recording) {
                return Err(error::CliError::Refused("inspect", why));
            }
            match lines {
                Some(lines) => inspect::samples(&recording, &lines)?,
                None => inspect::run(&recording, json)?,
            }
        }
        Some(Command::Service {
            name,
            session,
            bus,
            frames_dir,
            record,
            preview,
            outcome_dir,
            overrides,
            restart,
        }) => service::run(
            &name,
            &session,
            &bus,
            service::ServiceArgs {
                frames_dir,
                record,
                preview,
                outcome_dir,
                overrides,
                restart,
            },
        )?,
        Some(Command::Replay(args)) => replay::run(args)?,
        Some(Command::Echo {
            topic,
            session,
            count,
            wait,
        }) => monitor::echo(&topic, session.as_deref(), count, wait)
            .map_err(|e| error::CliError::Monitor("echo", e))?,
        Some(Command::Hz {
            topic,
            session,
            window,
            seconds,
            wait,
        }) => monitor::hz(
            &topic,
            session.as_deref(),
            window as usize,
            seconds.map(|d| d.as_secs_f64()),
            wait,
        )
        .map_err(|e| error::CliError::Monitor("hz", e))?,
        Some(Command::Topics {
            session,
            verbose,
            json,
            window,
        }) => monitor::topics(session.as_deref(), verbose, json, window.as_secs_f64())
            .map_err(|e| error::CliError::Monitor("topics", e))?,
        Some(Command::Sessions { json }) => monitor::sessions(json),
        Some(Command::Bench { which }) => bench::run(which)?,
        Some(Command::BenchPeer { bus, rate, count }) => bench::peer(&bus, rate, count)?,
        Some(Command::BenchTransportPeer {
            transport,
            endpoint,
            bytes,
            rate,
            count,
        }) => bench::transport_peer(&transport, endpoint, bytes, rate, count)?,
        Some(Command::Emulate(device)) => match device {
            EmulateDevice::Glove { serial, sensors } => emulate::run(
                "glove",
                serial.link.as_deref(),
                sensors,
                serial.rate,
                &serial.faults,
            )?,
            EmulateDevice::Tracker { serial } => emulate::run(
                "tracker",
                serial.link.as_deref(),
                22,
                serial.rate,
                &serial.faults,
            )?,
            EmulateDevice::Headset {
                url,
                trace,
                hand,
                screenshot,
                spectator,
            } => emulate::headset(emulate::Headset {
                url,
                trace,
                // clap allows only right, left and both.
                hand: common::HandsUsed::parse(&hand).unwrap_or_default(),
                screenshot,
                spectator,
            })?,
        },
    };
    Ok(code)
}
