//! The `damage-twin` binary: the headless CLI (and, with no arguments, the desktop app).

mod cli;

fn main() -> std::process::ExitCode {
    cli::main()
}
