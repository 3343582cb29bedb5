//! `handblocks config keys`: every configuration key, its type, default, range and what it
//! does, as the code that checks the keys reports them (`common::config::catalog`); the
//! committed docs/config.md is its `--markdown`.

use std::process::ExitCode;

use common::config::catalog;

/// `handblocks config ...`.
#[derive(clap::Subcommand)]
pub enum ConfigCommand {
    /// Every key of the session, scene, device and hand model files: its type, its default,
    /// what it may be and what it does, from the code that checks them.
    ///
    /// Plain text by default; --markdown is docs/config.md (regenerate it with
    /// `handblocks config keys --markdown > docs/config.md`), --json one object per key
    /// (file, key, type, default, allowed, what).
    Keys {
        /// docs/config.md: one table per kind of file.
        #[arg(long, conflicts_with = "json")]
        markdown: bool,
        /// A JSON array, one object per key.
        #[arg(long)]
        json: bool,
    },
}

pub fn run(what: ConfigCommand) -> ExitCode {
    crate::end_quietly_on_closed_pipe();
    let ConfigCommand::Keys { markdown, json } = what;
    let keys = match catalog::keys() {
        Ok(keys) => keys,
        Err(e) => {
            eprintln!("handblocks config keys: {e}");
            return ExitCode::from(crate::error::CliError::EXIT_STATUS);
        }
    };
    if json {
        match serde_json::to_string_pretty(&keys) {
            Ok(text) => println!("{text}"),
            Err(e) => {
                eprintln!("handblocks config keys: {e}");
                return ExitCode::from(crate::error::CliError::EXIT_STATUS);
            }
        }
    } else if markdown {
        print!("{}", catalog::markdown(&keys));
    } else {
        print!("{}", catalog::text(&keys));
    }
    ExitCode::SUCCESS
}
