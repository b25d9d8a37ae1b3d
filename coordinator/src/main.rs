//! `coordinator`: photonfarm's main program. It loads a scene, renders it until a time, phase or error target,
//! and writes the image, its layers and the run record.

mod bench_command;
mod bench_tables;
mod charts;
mod cli;
mod cluster;
mod live;
mod output_folder;
mod reference_command;
mod render_command;

use clap::Parser;

fn main() -> std::process::ExitCode {
    let cli = cli::Cli::parse();
    let result = match cli.command {
        cli::Command::Render(args) => render_command::run(*args),
        cli::Command::Bench(args) => bench_command::run(args),
        cli::Command::Reference(args) => reference_command::run(args),
        cli::Command::Charts(args) => charts::run(args),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
