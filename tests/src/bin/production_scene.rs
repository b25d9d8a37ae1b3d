//! `production-scene`: writes a generated room of production size (tests/src/room.rs) into a folder: `room.toml`
//! and `room/sphere.obj`, a bumpy sphere of about N triangles. `scripts/production-sizes` renders such rooms.
//!
//! `cargo run --release -p end-to-end --bin production-scene -- DIR --triangles 1000000 --width 1920 --height 1080`

use anyhow::{Context, Result};
use clap::Parser;
use end_to_end::room::{write_room, RoomSpec};
use std::path::PathBuf;

#[derive(Parser)]
#[command(name = "production-scene", about = "Write a generated room with a large mesh into a folder")]
struct Cli {
    /// The folder to write into (created if missing).
    dir: PathBuf,
    /// About this many triangles in the room's sphere.
    #[arg(long, default_value_t = 1_000_000)]
    triangles: u64,
    #[arg(long, default_value_t = 1920)]
    width: u32,
    #[arg(long, default_value_t = 1080)]
    height: u32,
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    anyhow::ensure!(cli.width > 0 && cli.height > 0, "--width and --height must be at least 1");
    anyhow::ensure!(cli.triangles > 0, "--triangles must be at least 1");
    let spec = RoomSpec { triangles: cli.triangles, width: cli.width, height: cli.height };
    let room =
        write_room(&cli.dir, spec).with_context(|| format!("cannot write the room into {}", cli.dir.display()))?;
    let bytes = std::fs::metadata(&room.mesh)?.len();
    println!(
        "{}: {} × {} pixels, {} triangles ({:.0} MB of OBJ)",
        room.scene.display(),
        cli.width,
        cli.height,
        room.triangles,
        bytes as f64 / 1e6
    );
    Ok(())
}
