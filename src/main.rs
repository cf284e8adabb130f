//! The `throng` binary: parse arguments, run, map the result to an exit code.

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let cli = throng::cmd::Cli::parse();
    match throng::cmd::run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("throng: error: {e}");
            ExitCode::from(2)
        }
    }
}
