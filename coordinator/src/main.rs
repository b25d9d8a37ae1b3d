//! `coordinator`: photonfarm's main program. It loads a scene, renders it until a time, phase or error target,
//! and writes the image, its layers and the run record.

/// `println!` that never panics: a reader that closed stdout early (`| head`) must not stop the program
/// before it has written its files, so a failed write to stdout is ignored.
macro_rules! say {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout().lock(), $($arg)*);
    }};
}

mod bench;
mod cli;
mod cluster;
mod live;
mod output_folder;
mod rays;
mod reference_command;
mod render_command;

use clap::Parser;

fn main() -> std::process::ExitCode {
    let cli = cli::Cli::parse();
    worker::logging::init();
    let result = match cli.command {
        cli::Command::Render(args) => render_command::run(*args),
        cli::Command::Bench(args) => bench::run(args),
        cli::Command::Reference(args) => reference_command::run(args),
        cli::Command::Charts(args) => bench::charts::run(args),
        cli::Command::Keys(cli::KeysCommand::Init { dir }) => keys_init(&dir),
        cli::Command::Rays(cli::RaysCommand::Select(args)) => rays::select::select(args),
        cli::Command::Rays(cli::RaysCommand::Ghosts(args)) => rays::ghosts::ghosts(args),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

/// `coordinator keys init DIR`: the job CA's certificates and keys, and what to copy where.
fn keys_init(dir: &std::path::Path) -> anyhow::Result<()> {
    let files = photonfarm::protocol::tls::init_keys(dir)?;
    for f in &files {
        say!("wrote {}", f.display());
    }
    say!(
        "the coordinator takes --tls-dir {0}; copy ca.pem, worker.pem, worker.key and secret to a folder on each \
         worker machine and give `worker join|serve` --tls-dir with it. coordinator.key stays here; the CA's own \
         key was not kept, so a new job CA needs a new folder",
        dir.display()
    );
    Ok(())
}
