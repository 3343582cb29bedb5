//! `handblocks completions SHELL`: the shell completion script, generated from [`crate::cli`].

use std::process::ExitCode;

use clap::CommandFactory;

use crate::cli::Cli;

pub fn run(shell: clap_complete::Shell) -> ExitCode {
    clap_complete::generate(
        shell,
        &mut Cli::command(),
        "handblocks",
        &mut std::io::stdout(),
    );
    ExitCode::SUCCESS
}
