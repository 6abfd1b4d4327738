//! The virtual rig for the end-to-end tests: `host virtual-rig` under its own name, so the tests
//! can spawn it (`CARGO_BIN_EXE_virtual_rig`); options and behaviour are `host::virtual_rig`'s.

use clap::Parser;
use std::process::ExitCode;

#[derive(Parser)]
#[command(name = "virtual_rig", about = "The firmware's core and the simulated exciter on a pseudo-terminal")]
struct Cli {
    #[command(flatten)]
    options: host::virtual_rig::Options,
}

fn main() -> ExitCode {
    match host::virtual_rig::serve(&Cli::parse().options) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
