//! The `throng` binary: the command line over the `throng` library. Parses
//! arguments (clap), runs a verb, prints, and maps the result to an exit code.
//! Only this crate prints or names a flag; the stages return values.
#![forbid(unsafe_code)]
#![allow(
    clippy::neg_cmp_op_on_partial_ord,
    reason = "`!(x > 0.0)` is how input checks reject NaN along with out-of-range values"
)]

use std::process::ExitCode;

use clap::Parser;

mod cmd;

fn main() -> ExitCode {
    let cli = cmd::Cli::parse();
    match cmd::run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("throng: error: {}", cmd::wording(&e));
            ExitCode::from(2)
        }
    }
}
