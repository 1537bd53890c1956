//! The headless client: parses arguments and drives the library's job API. No algorithms here.
//! Every subcommand lives in its own file with an `Args` struct and a `run` function.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "damage-twin",
    version,
    about = "A 3D digital twin of structural damage"
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand)]
enum Command {}

pub fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        None => {
            use clap::CommandFactory;
            Cli::command().print_help().map_err(anyhow::Error::from)
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // One line, the whole cause chain: "reading sparse/0/cameras.bin: truncated ...".
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
