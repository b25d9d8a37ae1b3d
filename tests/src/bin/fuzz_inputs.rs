//! `fuzz-inputs`: feeds generated protocol frames, snapshot deltas, checkpoints and scene files (with their OBJ
//! meshes) to the decoders and loaders a peer or a file on disk reaches, and reports how many were refused,
//! how many panicked, and the process's peak memory. Inputs are valid ones with proptest-generated edits (bit
//! flips, overwritten bytes and words, insertions, deletions, truncations, replaced numbers), or plain random
//! bytes; the same seed gives the same inputs. Exits non-zero if any input panicked.
//!
//! `cargo run --release -p end-to-end --bin fuzz-inputs -- --inputs 1000000`

use anyhow::{bail, Context, Result};
use clap::Parser;
use photonfarm::accumulation::delta::{apply_delta, encode_delta, encode_delta_of, Compression, PixelRuns};
use photonfarm::accumulation::{Accumulator, AuxLayer, AuxLayout, LitMask};
use photonfarm::color::Rgb;
use photonfarm::geometry::BvhCacheUse;
use photonfarm::protocol::frame::{read_frame, write_frame};
use photonfarm::protocol::message::{decode, encode};
use photonfarm::protocol::{
    EngineSpec, FilePiece, FileRef, Job, LitPixels, Message, RayMapPortion, RayMapRequest, Role, Share, Snapshot,
    WorkerInfo,
};
use photonfarm::render::checkpoint::Checkpoint;
use photonfarm::render::method::ParallelMethod;
use photonfarm::render::{Method, RayTotals, RenderSettings};
use photonfarm::sampling::REPLICATES;
use photonfarm::scene::Scene;
use proptest::prelude::*;
use proptest::sample::Index;
use proptest::strategy::ValueTree;
use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};
use std::collections::BTreeMap;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;
use std::time::Instant;

#[derive(Parser)]
#[command(name = "fuzz-inputs", about = "Feed generated hostile inputs to photonfarm's decoders and loaders")]
struct Cli {
    /// Inputs in all, shared equally by the four kinds.
    #[arg(long, default_value_t = 100_000)]
    inputs: u64,
    /// Seed of the generator: the same seed gives the same inputs.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

/// One edit of a valid input.
#[derive(Clone, Debug)]
enum Edit {
    FlipBit(Index, u8),
    SetByte(Index, u8),
    /// A little-endian word of 4 or 8 bytes with a value decoders treat specially (0, all ones, a sign bit).
    SetWord(Index, u64, bool),
    Insert(Index, Vec<u8>),
    Delete(Index, usize),
    Truncate(Index),
}

fn edit() -> impl Strategy<Value = Edit> {
    let interesting = prop_oneof![
        Just(0u64),
        Just(1),
        Just(u32::MAX as u64),
        Just(u32::MAX as u64 - 1),
        Just(1 << 31),
        Just(u64::MAX),
        Just(1 << 63),
        Just(f64::INFINITY.to_bits()),
        Just(f64::NAN.to_bits()),
        Just(f64::MAX.to_bits()),
        Just((-1.0f64).to_bits()),
        any::<u64>(),
    ];
    prop_oneof![
        3 => (any::<Index>(), 0u8..8).prop_map(|(i, b)| Edit::FlipBit(i, b)),
        3 => (any::<Index>(), any::<u8>()).prop_map(|(i, b)| Edit::SetByte(i, b)),
        3 => (any::<Index>(), interesting, any::<bool>()).prop_map(|(i, v, wide)| Edit::SetWord(i, v, wide)),
        1 => (any::<Index>(), proptest::collection::vec(any::<u8>(), 1..16)).prop_map(|(i, b)| Edit::Insert(i, b)),
        1 => (any::<Index>(), 1usize..64).prop_map(|(i, n)| Edit::Delete(i, n)),
        1 => any::<Index>().prop_map(Edit::Truncate),
    ]
}

fn apply(bytes: &mut Vec<u8>, e: &Edit) {
    if bytes.is_empty() {
        if let Edit::Insert(_, b) = e {
            bytes.extend_from_slice(b);
        }
        return;
    }
    let n = bytes.len();
    match e {
        Edit::FlipBit(i, b) => bytes[i.index(n)] ^= 1 << b,
        Edit::SetByte(i, b) => bytes[i.index(n)] = *b,
        Edit::SetWord(i, v, wide) => {
            let word = if *wide { v.to_le_bytes().to_vec() } else { (*v as u32).to_le_bytes().to_vec() };
            let at = i.index(n);
            let end = (at + word.len()).min(n);
            bytes[at..end].copy_from_slice(&word[..end - at]);
        }
        Edit::Insert(i, b) => {
            let at = i.index(n + 1);
            bytes.splice(at..at, b.iter().copied());
        }
        Edit::Delete(i, len) => {
            let at = i.index(n);
            bytes.drain(at..(at + len).min(n));
        }
        Edit::Truncate(i) => bytes.truncate(i.index(n)),
    }
}

/// A generated input: the index of a valid seed input and the edits made to it, or random bytes.
#[derive(Clone, Debug)]
enum Input {
    Edited { seed: Index, edits: Vec<Edit> },
    Random(Vec<u8>),
}

fn input() -> impl Strategy<Value = Input> {
    prop_oneof![
        6 => (any::<Index>(), proptest::collection::vec(edit(), 1..6)).prop_map(|(seed, edits)| Input::Edited { seed, edits }),
        1 => proptest::collection::vec(any::<u8>(), 0..256).prop_map(Input::Random),
    ]
}

fn materialise(input: &Input, seeds: &[Vec<u8>]) -> Vec<u8> {
    match input {
        Input::Random(b) => b.clone(),
        Input::Edited { seed, edits } => {
            let mut b = seeds[seed.index(seeds.len())].clone();
            for e in edits {
                apply(&mut b, e);
            }
            b
        }
    }
}

const SCENE: &str = r#"
[render]
max_depth = 6

[camera]
type = "pinhole"
position = [0.0, 0.5, -3.0]
look_at = [0.0, 0.5, 0.0]
up = [0.0, 1.0, 0.0]
fov_y_deg = 45.0
width = 16
height = 12

[materials.white]
type = "diffuse"
albedo = [0.7, 0.7, 0.7]

[materials.glass]
type = "dielectric"
ior = 1.5

[[objects]]
name = "floor"
mesh = "floor.obj"
material = "white"

[[objects]]
name = "ball"
sphere = { center = [0.0, 0.4, 0.0], radius = 0.3 }
material = "glass"

[[objects]]
name = "lamp"
quad = { corner = [-0.3, 1.2, -0.3], edge1 = [0.6, 0.0, 0.0], edge2 = [0.0, 0.0, 0.6] }
material = "white"
emission = [4.0, 4.0, 4.0]

[[lights]]
type = "point"
position = [0.5, 1.0, -0.5]
intensity = [1.0, 1.0, 1.0]
"#;

const OBJ: &str = "v -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 1 0\n\
                   f 1/1/1 2/2/1 3/3/1\nf 1/1/1 3/3/1 4/4/1\n";

/// Numbers a scene file's values are replaced with.
const NUMBERS: &[&str] = &[
    "0",
    "-1",
    "1e39",
    "-1e39",
    "nan",
    "inf",
    "-inf",
    "4294967296",
    "65536",
    "100000",
    "1e-45",
    "0.0",
    "[]",
    "0.5",
    "2",
    "1e-3",
    "3.0",
    "-0.0",
];

fn sums(width: u32, height: u32, layout: &AuxLayout, phases: u32, shift: f32) -> Accumulator {
    let mut a = Accumulator::with_aux(width, height, layout.clone());
    for i in 0..(width * height) as usize {
        for j in 0..phases {
            let v = Rgb::splat(shift + (i as f32 * 0.37 + j as f32 * 1.3).sin().abs());
            a.add_phase(i, &[v, v * 0.5, v * 0.25, Rgb::ZERO], 1, j as usize % REPLICATES);
            let part: Vec<f32> = (0..layout.channels()).map(|c| v.x * 0.1 * (c + 1) as f32).collect();
            a.aux.add_phase(i, &part);
        }
    }
    a
}

/// What one kind of input gave.
#[derive(Default)]
struct Tally {
    inputs: u64,
    accepted: u64,
    refused: u64,
    panics: u64,
    first_panic: Option<String>,
}

impl Tally {
    fn record(&mut self, index: u64, outcome: std::thread::Result<bool>) {
        self.inputs += 1;
        match outcome {
            Ok(true) => self.accepted += 1,
            Ok(false) => self.refused += 1,
            Err(p) => {
                self.panics += 1;
                if self.first_panic.is_none() {
                    let what = p
                        .downcast_ref::<String>()
                        .cloned()
                        .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                        .unwrap_or_default();
                    self.first_panic = Some(format!("input {index}: {what}"));
                }
            }
        }
    }
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    if cli.inputs == 0 {
        bail!("--inputs must be at least 1");
    }
    let rss_at_start = photonfarm::render::memory::current_rss_bytes().unwrap_or(0);
    let started = Instant::now();
    // Panics are counted, not printed one by one.
    std::panic::set_hook(Box::new(|_| {}));

    // Valid inputs of every kind, to edit.
    let meshes: BTreeMap<String, Vec<u8>> = [("floor.obj".to_string(), OBJ.as_bytes().to_vec())].into();
    let scene = Scene::from_toml_with_meshes(SCENE, Path::new("fuzz.toml"), &meshes).context("the seed scene")?;
    let settings = RenderSettings::for_scene(&scene, Method::ThreeLevel, 1);
    let ghost = AuxLayout::new(vec![AuxLayer { name: "ghost".into(), channels: 3 }]);
    let layout = AuxLayout::for_scene(&scene, 0);
    let (w, h) = (scene.camera.width, scene.camera.height);
    let base = sums(w, h, &layout, 2, 0.1);
    let mut current = base.clone();
    current.merge(&sums(w, h, &layout, 3, 0.4));
    let delta = encode_delta(&current, &base, Compression::Fast);
    let delta_small = encode_delta(&current, &base, Compression::Small);
    let ghost_delta = encode_delta(&sums(w, h, &ghost, 1, 0.2), &Accumulator::with_aux(w, h, ghost), Compression::Fast);
    // A snapshot of every other row, as a worker sends the pixels its rounds rendered.
    let rows: Vec<bool> = (0..(w * h) as usize).map(|i| (i / w as usize).is_multiple_of(2)).collect();
    let sparse = encode_delta_of(&current, &base, &PixelRuns::from_flags(&rows), Compression::Fast);
    let raw = zstd::bulk::decompress(&delta, 1 << 24).context("the seed delta")?;
    let sparse_raw = zstd::bulk::decompress(&sparse, 1 << 24).context("the seed sparse delta")?;
    let delta_seeds = vec![delta.clone(), delta_small, ghost_delta, sparse];
    let raw_seeds = [raw, sparse_raw];

    let job = Job {
        scene_name: "fuzz.toml".into(),
        scene: scene.description.clone(),
        files: vec![FileRef { path: "floor.obj".into(), sha256: scene.mesh_files[0].1.clone() }],
        scene_hash: scene.hash.clone(),
        settings,
        stream: 3,
        engine: EngineSpec {
            method: ParallelMethod::TwoLevel,
            group_size: 2,
            tile_size: Some(16),
            phases_per_deal: Some(4),
            cores: Some(vec![0, 1]),
            numa_node: Some(0),
            synthetic_topology: true,
            processes_per_pixel: 2,
            process_rank: 1,
            resumed_phases: 0,
            memory_limit: Some(1 << 30),
        },
        snapshot_interval_ms: 1000,
        ray_map: Some(RayMapRequest { fraction: 0.01 }),
        decide_lit_mask: true,
    };
    let messages = [
        Message::Hello { version: 5, role: Role::Worker, nonce: [7; 32], name: "w".into() },
        Message::Proof { mac: [1; 32] },
        Message::Refused { reason: "no".into() },
        Message::Job(Box::new(job)),
        Message::NeedFiles { hashes: vec![scene.mesh_files[0].1.clone()] },
        Message::FilePiece(FilePiece::all_of(&scene.mesh_files[0].1, OBJ.as_bytes()).remove(0)),
        Message::LitPixels(LitPixels::of(
            &LitMask::from_flags(w, h, (0..w * h).map(|i| i % 5 == 0).collect(), 16),
            0.25,
        )),
        Message::Started(WorkerInfo {
            hostname: "h".into(),
            threads: 2,
            cores: vec![0, 1],
            numa_node: None,
            binding: "b".into(),
            layout: "l".into(),
            scene_load_s: 1.5,
            bvh_cache: BvhCacheUse::Unwritten("disk full".into()),
        }),
        Message::Snapshot(Snapshot {
            seq: 1,
            totals: RayTotals::default(),
            checksum: Snapshot::checksum_of(&delta),
            delta,
            interval_ms: 1000,
            previous_send_ms: 3,
            peak_memory_bytes: 1 << 20,
            memory_estimate_bytes: 1 << 20,
            non_finite_dropped: 0,
        }),
        Message::Ack { seq: 9 },
        Message::Heartbeat,
        Message::Stop,
        Message::Finished,
        Message::Failed { reason: "x".into() },
        Message::ActiveTiles { tile: 32, flags: vec![true, false, true, true] },
        Message::Share(Share {
            processes: 3,
            rank: 2,
            merged_phases: Share::compress_phases(base.pixels.iter().map(|p| p.phases)),
        }),
        Message::RayMapPortion(RayMapPortion { raw_bytes: 64, paths: 1, segments: 1, frame: vec![0x28, 0xb5, 0x2f] }),
        Message::StopAt { in_ms: 30_000, slack_ms: 600 },
    ];
    let runtime = tokio::runtime::Builder::new_current_thread().build()?;
    let mut frame_seeds = Vec::new();
    for m in &messages {
        let body = encode(m)?;
        let mut framed = Vec::new();
        runtime.block_on(write_frame(&mut framed, &body, u32::MAX))?;
        frame_seeds.push(framed);
    }
    let checkpoint =
        Checkpoint::new(&current, &scene.hash, Method::ThreeLevel, settings, 1, 3.5, RayTotals::default(), &[]);
    let dir = std::env::temp_dir().join(format!("photonfarm-fuzz-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    checkpoint.save(&dir.join("checkpoint.bin"), &current)?;
    let checkpoint_seeds = vec![std::fs::read(dir.join("checkpoint.bin"))?];
    std::fs::remove_dir_all(&dir).ok();
    let scene_seeds = vec![SCENE.as_bytes().to_vec()];
    let obj_seeds = vec![OBJ.as_bytes().to_vec()];

    let mut seed = [0u8; 32];
    seed[..8].copy_from_slice(&cli.seed.to_le_bytes());
    let mut runner = TestRunner::new_with_rng(Config::default(), TestRng::from_seed(RngAlgorithm::ChaCha, &seed));
    let strategy = input();
    let next = |runner: &mut TestRunner| match strategy.new_tree(runner) {
        Ok(tree) => tree.current(),
        Err(_) => Input::Random(Vec::new()),
    };
    let number = (any::<Index>(), any::<Index>());

    let (mut frames, mut deltas, mut checkpoints, mut scenes) =
        (Tally::default(), Tally::default(), Tally::default(), Tally::default());
    for i in 0..cli.inputs {
        match i % 4 {
            0 => {
                let bytes = materialise(&next(&mut runner), &frame_seeds);
                frames.record(
                    i,
                    catch_unwind(|| {
                        let mut r = &bytes[..];
                        let mut any_ok = false;
                        while let Ok(Some(body)) = runtime.block_on(read_frame(&mut r, 1 << 20)) {
                            any_ok |= match decode(&body) {
                                // A worker decodes an announced share's phases for its image.
                                Ok(Message::Share(s)) => s.merged_phases(base.pixels.len()).is_ok(),
                                // The coordinator reads a worker's lit mask for its image.
                                Ok(Message::LitPixels(l)) => l.mask(w, h).is_ok(),
                                decoded => decoded.is_ok(),
                            };
                        }
                        any_ok
                    }),
                );
            }
            1 => {
                // Every other one edits the uncompressed layout, to reach the checks behind the decompression.
                let bytes = if i % 8 == 1 {
                    let raw =
                        materialise(&next(&mut runner), if i % 16 == 1 { &raw_seeds[..1] } else { &raw_seeds[1..] });
                    zstd::bulk::compress(&raw, -5)?
                } else {
                    materialise(&next(&mut runner), &delta_seeds)
                };
                let mut target = base.clone();
                deltas.record(i, catch_unwind(AssertUnwindSafe(|| apply_delta(&bytes, &mut target).is_ok())));
            }
            2 => {
                let mut bytes = materialise(&next(&mut runner), &checkpoint_seeds);
                // Every edit fails the checksum: every other input gets its checksum recomputed after the edit, to
                // reach the checks behind it.
                if i % 8 == 2 && bytes.len() >= 4 {
                    let body = bytes.len() - 4;
                    let sum = crc32fast::hash(&bytes[..body]).to_le_bytes();
                    bytes[body..].copy_from_slice(&sum);
                }
                // The scene is only read (with the `embree` feature it holds cells, so the compiler cannot see that).
                let decode = AssertUnwindSafe(|| Checkpoint::from_bytes(&bytes, &scene, "fuzz").is_ok());
                checkpoints.record(i, catch_unwind(decode));
            }
            _ => {
                // Byte edits of the text mostly end in a TOML syntax error: half the scene inputs keep the text
                // whole but for one number, and half of those the mesh too, to reach the checks behind the parser.
                let (text_input, obj_input) = (next(&mut runner), next(&mut runner));
                let k = i / 4;
                let whole = k % 4 < 2;
                let mut text = if whole { scene_seeds[0].clone() } else { materialise(&text_input, &scene_seeds) };
                let obj = if k % 4 == 0 { obj_seeds[0].clone() } else { materialise(&obj_input, &obj_seeds) };
                // Replace one number of the scene by a value its checks must refuse or bear.
                let (at, with) = number.new_tree(&mut runner).map_err(|e| anyhow::anyhow!("{e}"))?.current();
                let digits: Vec<usize> = (0..text.len()).filter(|&k| text[k].is_ascii_digit()).collect();
                if !digits.is_empty() {
                    let in_number = |c: u8| c.is_ascii_digit() || c == b'.' || c == b'-';
                    let mut start = digits[at.index(digits.len())];
                    while start > 0 && in_number(text[start - 1]) {
                        start -= 1;
                    }
                    let end = (start..text.len()).find(|&k| !in_number(text[k])).unwrap_or(text.len());
                    let replacement = NUMBERS[with.index(NUMBERS.len())].as_bytes();
                    text.splice(start..end, replacement.iter().copied());
                }
                let text = String::from_utf8_lossy(&text).into_owned();
                let meshes: BTreeMap<String, Vec<u8>> = [("floor.obj".to_string(), obj)].into();
                scenes.record(
                    i,
                    catch_unwind(|| Scene::from_toml_with_meshes(&text, Path::new("fuzz.toml"), &meshes).is_ok()),
                );
            }
        }
    }
    let mb = |b: u64| b as f64 / (1 << 20) as f64;
    let peak = photonfarm::render::memory::peak_rss_bytes().unwrap_or(0);
    println!("{} inputs (seed {}) in {:.1} s", cli.inputs, cli.seed, started.elapsed().as_secs_f64());
    let mut panics = 0;
    for (name, t) in
        [("frames", &frames), ("snapshot deltas", &deltas), ("checkpoints", &checkpoints), ("scene files", &scenes)]
    {
        println!(
            "{name:>16}: {:>8} inputs, {:>8} accepted, {:>8} refused, {} panics{}",
            t.inputs,
            t.accepted,
            t.refused,
            t.panics,
            t.first_panic.as_ref().map(|p| format!(" (first: {p})")).unwrap_or_default()
        );
        panics += t.panics;
    }
    println!("peak memory: {:.1} MiB (resident at start: {:.1} MiB)", mb(peak), mb(rss_at_start));
    if panics > 0 {
        bail!("{panics} inputs panicked");
    }
    Ok(())
}
