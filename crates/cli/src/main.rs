//! `hybrid`: the command-line front end of the hybrid renderer.
//!
//! ```text
//! hybrid render [SCENE] [-o out.png] [--size WxH] [--mode M] [--backend B] [--dump DIR] [--report FILE.json] [--time S]
//! hybrid inspect SCENE [--json]
//! hybrid view [SCENE] [--backend B] [--size WxH] [--mode M] [--budget N | --budget-ms MS] [--policy P] [--target-ms MS] [--script FILE]
//! hybrid bench SCENE [--size WxH] [--frames N] [--path-seconds S] [--fps F] [--modes M,..] [--out DIR] [--flip-every K] [--sweep-budget]
//! ```
//! Bad input (scene files, models, flags) prints one clear error and exits with code 2.

mod args;
mod bench;
mod dump;
mod inspect;
mod output;
mod render;
mod view;

use std::process::ExitCode;

use clap::Parser;

use crate::args::{Cli, Command};

/// Exit code for bad input (unreadable/invalid scene, model or flag).
pub const EXIT_BAD_INPUT: u8 = 2;
/// Exit code for failures that are not the user's input (e.g. an output file that cannot be written).
pub const EXIT_FAILURE: u8 = 1;

/// An error that ends the command, with its exit code.
#[derive(Debug)]
pub struct CliError {
    pub code: u8,
    pub message: String,
    /// A rich report (source snippet) to print after the message, if any.
    pub detail: Option<miette::Report>,
}

impl CliError {
    pub fn bad_input(message: impl Into<String>) -> Self {
        Self { code: EXIT_BAD_INPUT, message: message.into(), detail: None }
    }
    pub fn failure(message: impl Into<String>) -> Self {
        Self { code: EXIT_FAILURE, message: message.into(), detail: None }
    }
}

impl From<hybrid_scene::SceneError> for CliError {
    fn from(e: hybrid_scene::SceneError) -> Self {
        let message = e.to_string();
        let detail = e.source_code.is_some().then(|| miette::Report::new(e));
        Self { code: EXIT_BAD_INPUT, message, detail }
    }
}

fn main() -> ExitCode {
    // Before anything else, while this is the only thread (it sets an environment variable).
    hybrid_gpu::context::quiet_window_system_probe();
    let cli = Cli::parse();
    let filter = tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn"));
    tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).init();
    // The CPU kernels' instruction-set path (`HYBRID_ISA` forces one; a bad value is bad input).
    if let Err(e) = hybrid_cpu::isa::init_from_env() {
        eprintln!("error: {e}");
        return ExitCode::from(EXIT_BAD_INPUT);
    }
    let result = match cli.command {
        Command::Render(a) => render::run(a),
        Command::Inspect(a) => inspect::run(a),
        Command::Bench(a) => bench::run(a),
        Command::View(a) => view::run(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // Once: the diagnostic with its source snippet when there is one (it carries the
            // same message), else the plain line.
            match e.detail {
                Some(d) => eprintln!("{d:?}"),
                None => eprintln!("error: {}", e.message),
            }
            ExitCode::from(e.code)
        }
    }
}
