//! The `throng` binary: parse arguments, run, map the result to an exit code.

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let cli = throng::cli::Cli::parse();
    match throng::cli::run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("throng: error: {e}");
            ExitCode::from(2)
        }
    }
}
