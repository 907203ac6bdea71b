//! The `zwidth` command line: parse, call the library, print. Bad input
//! exits with code 2 and one line naming the problem; I/O failures exit 1.
//! Local engines are in `local`, the service and its client in `service`,
//! shared helpers in `common`.

mod agent;
mod command;
mod common;
mod identify;
mod local;
mod service;

use std::io::{BufRead, Write};

pub use crate::error::CliError;
pub use command::{BenchCommand, Cli, Command, DEFAULT_QUANTIZATION};
pub use common::{map_svg, map_table, read_samples};

pub fn run(cli: Cli, stdin: impl BufRead, stdout: &mut impl Write) -> Result<(), CliError> {
    if cli.command.is_service() {
        service::run(cli.command, stdout)
    } else {
        local::run(cli.command, stdin, stdout)
    }
}
