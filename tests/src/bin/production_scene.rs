//! `production-scene`: writes a generated room of production size (tests/src/room.rs) into a folder: `room.toml`
//! and `room/sphere.obj`, or with `--format ply` the same room as Mitsuba 3's `room.xml` and a binary
//! `room/sphere.ply`, a bumpy sphere of about N triangles. `scripts/production-sizes` renders such rooms.
//!
//! `cargo run --release -p end-to-end --bin production-scene -- DIR --triangles 1000000 --width 1920 --height 1080`

use anyhow::{Context, Result};
use clap::{Parser, ValueEnum};
use end_to_end::room::{write_room_as, MeshFormat, RoomSpec};
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
    /// The sphere's mesh format: obj with a TOML scene, ply (binary) with a Mitsuba 3 scene.
    #[arg(long, value_enum, default_value_t = Format::Obj)]
    format: Format,
}

/// `--format`'s values.
#[derive(Clone, Copy, ValueEnum)]
enum Format {
    Obj,
    Ply,
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    anyhow::ensure!(cli.width > 0 && cli.height > 0, "--width and --height must be at least 1");
    anyhow::ensure!(cli.triangles > 0, "--triangles must be at least 1");
    let spec = RoomSpec { triangles: cli.triangles, width: cli.width, height: cli.height };
    let (format, name) = match cli.format {
        Format::Obj => (MeshFormat::Obj, "OBJ"),
        Format::Ply => (MeshFormat::Ply, "PLY"),
    };
    let room = write_room_as(&cli.dir, spec, format)
        .with_context(|| format!("cannot write the room into {}", cli.dir.display()))?;
    let bytes = std::fs::metadata(&room.mesh).with_context(|| format!("cannot read {}", room.mesh.display()))?.len();
    println!(
        "{}: {} × {} pixels, {} triangles ({:.0} MB of {name})",
        room.scene.display(),
        cli.width,
        cli.height,
        room.triangles,
        bytes as f64 / 1e6
    );
    Ok(())
}
