//! Command-line interface. Flag names are a contract: scripts depend on them.

use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
use clap::{Parser, Subcommand, ValueEnum};
use photonfarm::render::Method;
use std::path::PathBuf;

/// photonfarm: physically based rendering with progressive backward photon mapping.
#[derive(Parser, Debug)]
#[command(name = "coordinator", version, about)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Render a scene file and write image.exr, preview.png and run.json into an output folder.
    Render(Box<RenderArgs>),
    /// Run every parallel method at several thread counts for a fixed time and print the paper's Table-1 rows.
    Bench(BenchArgs),
    /// Render a long reference image of a scene into scenes/references/, for the true error of every run.
    Reference(ReferenceArgs),
    /// Draw charts (SVG and PNG) of a bench folder's results.csv and series.csv into DIR/charts/.
    Charts(ChartsArgs),
    /// Keys for encrypted links to remote workers.
    #[command(subcommand)]
    Keys(KeysCommand),
    /// Ray maps recorded by `render --ray-map`: select paths by their optical events and show them.
    #[command(subcommand)]
    Rays(RaysCommand),
}

#[derive(Subcommand, Debug)]
pub enum RaysCommand {
    /// Select the recorded paths that satisfy an expression of optical events, and write an overlay PNG over
    /// the render's preview, the paths as OBJ polylines, and a report (JSON and a table).
    Select(RaysSelectArgs),
    /// For a scene with a lens in front of a sensor: rank the pairs of lens surfaces at which ghost camera
    /// paths took their first two reflections, by their share of the recorded ghost light, with footprints.
    Ghosts(RaysGhostsArgs),
}

#[derive(clap::Args, Debug)]
pub struct RaysGhostsArgs {
    /// The map: a render's output folder, its raymap/ folder, or one stream file.
    pub map: PathBuf,
    /// How many pairs to list (with a footprint PNG each).
    #[arg(long, default_value_t = 10, value_name = "N")]
    pub top: usize,
    /// Output folder (default: ghosts/ next to the map's raymap/ folder).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
}

/// How `rays select` colours the paths it draws.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum PathColour {
    /// The path's own colour: its wavelength, or the colour of its weight.
    Natural,
    /// Each segment by the event at its end (reflect red, refract cyan, diffuse green, emission yellow, …).
    Event,
}

#[derive(clap::Args, Debug)]
pub struct RaysSelectArgs {
    /// The map: a render's output folder, its raymap/ folder, or one stream file.
    pub map: PathBuf,
    /// The selection, e.g. "reflect(s3) >= 1 and reflect(s5) and not hits(mount2)" (docs/ray-maps.md).
    #[arg(long = "where", value_name = "EXPR")]
    pub expr: String,
    /// Keep at most N selected paths for the overlay, the glTF and OBJ files and the report (all are counted).
    #[arg(long, default_value_t = 1000, value_name = "N")]
    pub limit: usize,
    /// Draw at most N of the kept paths in the overlay: the heaviest.
    #[arg(long, default_value_t = 200, value_name = "N")]
    pub draw: usize,
    /// Do not write selection.glb (the scene's geometry with the paths).
    #[arg(long)]
    pub no_glb: bool,
    /// Output folder (default: selection/ next to the map's raymap/ folder).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// How the overlay colours the paths.
    #[arg(long, value_enum, default_value = "event")]
    pub colour: PathColour,
    /// Threads that decompress and test portions (default: every core).
    #[arg(long)]
    pub threads: Option<usize>,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

#[derive(Subcommand, Debug)]
pub enum KeysCommand {
    /// Make a job CA, a certificate and key for the coordinator and for the workers, and a shared secret in
    /// DIR (`--tls-dir DIR` on both sides). Copy ca.pem, worker.pem, worker.key and secret to the workers'
    /// machines.
    Init {
        /// A new or empty folder.
        dir: PathBuf,
    },
}

#[derive(clap::Args, Debug)]
pub struct ReferenceArgs {
    /// The scene file, e.g. scenes/cornell.toml.
    pub scene: PathBuf,
    /// Seconds to render.
    #[arg(long)]
    pub time: f64,
    /// The estimator: the path tracer (default), or a PBPM method where the path tracer cannot converge.
    #[arg(long, value_parser = method_parser(), default_value = "path")]
    pub method: Method,
    /// NUMA layout for combination and three-level (see `render --topology`).
    #[arg(long)]
    pub topology: Option<String>,
    /// Seed, kept apart from the bench's (1, 2, …) so the reference's noise is independent of the runs'.
    #[arg(long, default_value_t = 1000)]
    pub seed: u64,
    /// A PBPM reference's initial photon radius in pixel footprints (`render --radius-scale`): smaller than the
    /// scene's where its photon discs blur a sharp caustic, so that the reference's own bias stays below its
    /// noise.
    #[arg(long)]
    pub radius_scale: Option<f32>,
    /// Folder for <scene>-<path|pbpm>.exr and .json.
    #[arg(long, default_value = "scenes/references")]
    pub out: PathBuf,
    /// Replace an existing reference.
    #[arg(long)]
    pub force: bool,
}

#[derive(clap::Args, Debug)]
pub struct ChartsArgs {
    /// The bench output folder holding results.csv and series.csv.
    pub dir: PathBuf,
}

#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    /// Seconds per run.
    #[arg(long, default_value_t = 40.0)]
    pub time: f64,
    /// Phases per run: each run stops once every pixel has this many (`render --phases`), or at --time if that
    /// comes first, so that the runs compare at equal work rather than equal time.
    #[arg(long, value_name = "N")]
    pub phases: Option<u64>,
    /// Every method on both scenes for 8 s, once: under five minutes on 2 cores.
    #[arg(long)]
    pub quick: bool,
    /// Scenes by name in scenes/ (their references in scenes/references/ give the true error).
    #[arg(long, value_delimiter = ',', default_value = "cornell,caustic")]
    pub scenes: Vec<String>,
    /// Methods to run.
    #[arg(
        long,
        value_parser = method_parser(),
        value_delimiter = ',',
        default_value = "path,pbpm,sync,async,two-level,combination,three-level"
    )]
    pub methods: Vec<Method>,
    /// Thread counts to run each parallel method at (default 1, 2, 4, … and every core); the distributed
    /// methods run one worker per synthetic NUMA node of one core, as many nodes as threads.
    #[arg(long, value_delimiter = ',')]
    pub threads: Option<Vec<usize>>,
    /// Most threads per group for two-level (1, 2 or 4); two threads or more always make at least two groups.
    #[arg(long, default_value_t = 2)]
    pub group_size: usize,
    /// Cores to pin to (default: every core this process may use).
    #[arg(long, value_name = "LIST")]
    pub cores: Option<String>,
    /// Runs per configuration (seeds seed, seed + 1, …), interleaved so that a drifting machine affects every
    /// method alike; the report gives the mean and the range.
    #[arg(long, default_value_t = 1)]
    pub repeats: u32,
    /// Job seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Time to a target error instead of the error at equal time: every configuration runs twice, with adaptive
    /// tiles and with --uniform, each until δ unlit is at or below D (or --time passes), and the report gives
    /// both times. D for every scene, or per scene, e.g. cornell=0.03,caustic=0.08.
    #[arg(long, value_name = "D|SCENE=D,…")]
    pub target_error: Option<String>,
    /// With --target-error, the adaptive runs' tile edge in pixels (`render --adaptive-tile`).
    #[arg(long, value_name = "PX")]
    pub adaptive_tile: Option<u32>,
    /// Output folder for results.csv and report.md (default: a new folder under out/).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Serve a page of the runs done and to do and of the charts, redrawn after every run, on ADDR (default
    /// 127.0.0.1 and a free port). Any address but loopback needs a secret (--secret-file or $PHOTONFARM_SECRET).
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = "127.0.0.1:0")]
    pub serve: Option<std::net::SocketAddr>,
    /// File with the secret the page asks for on a non-loopback --serve address (otherwise $PHOTONFARM_SECRET).
    #[arg(long, value_name = "FILE")]
    pub secret_file: Option<PathBuf>,
}

/// `--method`'s parser: the library's methods by name, each with its summary in the help.
fn method_parser() -> impl TypedValueParser<Value = Method> {
    PossibleValuesParser::new(Method::ALL.map(|m| PossibleValue::new(m.name()).help(m.summary())))
        .try_map(|name| name.parse::<Method>())
}

/// Which pixels δ is computed over for --target-error and the progress display.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ErrorOverArg {
    /// Pixels that see no light, directly or through specular surfaces (a mask decided before the render).
    Unlit,
    /// All pixels (the paper's eq. 6).
    All,
}

/// A `--define NAME=VALUE`.
fn parse_define(text: &str) -> Result<(String, String), String> {
    match text.split_once('=') {
        Some((name, value)) if !name.is_empty() => Ok((name.to_string(), value.to_string())),
        _ => Err(format!("\"{text}\" is not NAME=VALUE")),
    }
}

#[derive(clap::Args, Debug)]
pub struct RenderArgs {
    /// The scene file: TOML (e.g. scenes/cornell.toml) or Mitsuba 3 XML (`.xml`, docs/scenes.md).
    pub scene: PathBuf,
    /// Set a Mitsuba scene's `$NAME` parameter, overriding its <default> (Mitsuba's -D); repeatable.
    #[arg(long = "define", short = 'D', value_name = "NAME=VALUE", value_parser = parse_define)]
    pub defines: Vec<(String, String)>,
    /// Import what a Mitsuba scene has no exact counterpart for (another integrator, an unknown BSDF, a bump or
    /// normal map, a medium, hide_emitters) as the nearest thing photonfarm renders instead of refusing it,
    /// naming each substitution in the notes and the run record's flags.
    #[arg(long)]
    pub approximate: bool,
    /// Stop after this many seconds of rendering. Default when no stop rule is given: 30.
    #[arg(long, value_name = "SECONDS")]
    pub time: Option<f64>,
    /// Stop once every pixel has this many phases (parallel methods stop at the end of a round, so pixels
    /// may have a few more).
    #[arg(long, value_name = "N")]
    pub phases: Option<u64>,
    /// Stop once the relative error δ (see --error-over) is at or below D, e.g. 0.05.
    #[arg(long, value_name = "D")]
    pub target_error: Option<f64>,
    /// Pixels δ is measured over for --target-error and the progress bar.
    #[arg(long, value_enum, default_value = "unlit")]
    pub error_over: ErrorOverArg,
    /// With --target-error, render every tile every round: without it, a tile that already has the phases its
    /// share of the target asks for stops receiving them (adaptive tiles, docs/estimator.md).
    #[arg(long)]
    pub uniform: bool,
    /// Tile edge in pixels of adaptive tiles when it should differ from the masks' (--tile-size): smaller
    /// tiles retire more of a scene whose error is concentrated, but judge each tile from fewer pixels.
    #[arg(long, value_name = "PX")]
    pub adaptive_tile: Option<u32>,
    /// Output folder (created if missing). Default: a new folder under out/.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Estimator and parallel method.
    #[arg(long, value_parser = method_parser(), default_value = "three-level")]
    pub method: Method,
    /// NUMA layout for combination and three-level: an hwloc synthetic description such as
    /// "pack:1 numa:2 core:1 pu:1", or an hwloc XML file (default: this machine's). Cores of a description
    /// that is not this machine are mapped onto the real cores modulo their count.
    #[arg(long, value_name = "DESCRIPTION|XML")]
    pub topology: Option<String>,
    /// A `worker serve` daemon to render on as well (repeatable), e.g. --worker server:7879.
    #[arg(long = "worker", value_name = "HOST:PORT")]
    pub workers: Vec<String>,
    /// Accept workers that dial in (`worker join ADDR`) on this address, e.g. 0.0.0.0:7878.
    #[arg(long, value_name = "ADDR")]
    pub listen: Option<std::net::SocketAddr>,
    /// Start no local worker: render only on --worker and --listen workers.
    #[arg(long)]
    pub remote_only: bool,
    /// File with the shared secret for remote workers (otherwise $PHOTONFARM_SECRET).
    #[arg(long, value_name = "FILE")]
    pub secret_file: Option<PathBuf>,
    /// Allow links to other machines without TLS and without a secret: anyone who can reach the port can
    /// join or be driven, and scenes and images cross the network in the clear.
    #[arg(long)]
    pub insecure: bool,
    /// Key folder made by `coordinator keys init DIR`: links to remote workers run over mutually
    /// authenticated TLS with its certificates (required off loopback unless --insecure), and its secret
    /// serves when no other is given.
    #[arg(long, value_name = "DIR")]
    pub tls_dir: Option<PathBuf>,
    /// Continue the run whose output folder is DIR from its checkpoint (combination and three-level): its
    /// sums, phases, rays and time carry on, and results go to DIR unless --out is given. A checkpoint file
    /// instead of DIR (DIR/checkpoint-previous.bin, the one saved before the latest) continues from that file.
    #[arg(long, value_name = "DIR|FILE")]
    pub resume: Option<PathBuf>,
    /// A worker that sends nothing (not even a heartbeat) for this many seconds is presumed hung and dropped.
    #[arg(long, default_value_t = 15.0, value_name = "SECONDS")]
    pub worker_timeout: f64,
    /// After this many lost links from one host (crashes, hangs, refused snapshots), that host's workers are
    /// refused for the rest of the job.
    #[arg(long, default_value_t = 3, value_name = "N")]
    pub max_worker_failures: u32,
    /// Seconds between a local worker's snapshots.
    #[arg(long, default_value_t = 1.0, value_name = "SECONDS")]
    pub snapshot_interval: f64,
    /// Threads for the in-process parallel methods (default: every core of --cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Most threads per synchronous group for --method two-level and three-level: 1, 2 or 4. Two threads or
    /// more always make at least two groups (one group would be sync with masks).
    #[arg(long, default_value_t = 2)]
    pub group_size: usize,
    /// Cores to pin threads to, e.g. 0,1 or 0-3 (default: every core this process may use).
    #[arg(long, value_name = "LIST")]
    pub cores: Option<String>,
    /// Tile edge in pixels for the two-level masks (default 32; 64 beyond 16 groups).
    #[arg(long)]
    pub tile_size: Option<u32>,
    /// K: a synchronisation round ends when one group has finished K phases (4–8 in the paper).
    #[arg(long, default_value_t = 6)]
    pub phases_per_deal: u32,
    /// Job seed; the same seed and settings give bit-identical sums on one thread.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Override the scene's max_depth (total path segments).
    #[arg(long)]
    pub max_depth: Option<u32>,
    /// Override the scene's backward_diffuse_depth (1 or 2).
    #[arg(long)]
    pub backward_diffuse_depth: Option<u32>,
    /// Override the initial photon radius, in pixel footprints.
    #[arg(long)]
    pub radius_scale: Option<f32>,
    /// Override the number of light paths per phase, per pixel.
    #[arg(long)]
    pub light_paths_per_pixel: Option<f32>,
    /// Also write N wavelength bands of equal width over 380–780 nm as grey EXR layers (band_380-430nm, …):
    /// every path is then spectral from its first vertex, which costs an RGB scene colour noise.
    #[arg(long, value_name = "N")]
    pub spectral_output: Option<u32>,
    /// A reference EXR (layer "total", or a plain RGB EXR) to measure the true error against.
    #[arg(long, value_name = "EXR")]
    pub reference: Option<PathBuf>,
    /// Seconds from the end of one refresh of the output files during the run to the start of the next, and
    /// at least as long as the last refresh took (merges wait while one reads the sums).
    #[arg(long, default_value_t = 10.0, value_name = "SECONDS")]
    pub save_interval: f64,
    /// No progress bar (for logs and scripts).
    #[arg(long)]
    pub quiet: bool,
    /// Serve a live page of the run (image, error chart, workers, stop button) on ADDR (default 127.0.0.1 and
    /// a free port; the URL is printed). Any address but loopback needs the job's secret (--secret-file or
    /// $PHOTONFARM_SECRET).
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = "127.0.0.1:0")]
    pub serve: Option<std::net::SocketAddr>,
    /// Seconds the live page stays up after the run has written its outputs, so an open page shows the end.
    #[arg(long, default_value_t = 2.0, value_name = "SECONDS")]
    pub serve_linger: f64,
    /// Stream every layer to a running tev viewer after each merge: `tev` (at 127.0.0.1:14158) or
    /// `tev=HOST:PORT`. A tev that is not there is a warning, never a failed render.
    #[arg(long, value_name = "tev[=HOST:PORT]", value_parser = parse_display)]
    pub display: Option<Display>,
    /// Memory a rendering process may use, e.g. 2G or 500M: the memory in use after loading the scene plus the
    /// engine's buffers. The in-process parallel methods check it before they allocate (`async`, whose buffers
    /// grow with its threads, runs with fewer threads to fit and the record flags it; `sync` and `two-level`
    /// refuse to start); `pbpm` and `path` check it before their first phase; every worker of `combination`
    /// and `three-level` checks it for itself before its engine allocates, and a worker over it fails its
    /// job with the reason.
    #[arg(long, value_name = "SIZE", value_parser = parse_size)]
    pub memory_limit: Option<u64>,
    /// Record a fraction of the camera and light paths of every phase into raymap/ in the output folder, for
    /// `coordinator rays select` (methods pbpm and path).
    #[arg(long)]
    pub ray_map: bool,
    /// The fraction of paths --ray-map records, in (0, 1]: chosen by a hash of the seed and the path's numbers.
    #[arg(long, value_name = "F", default_value_t = 0.01, requires = "ray_map")]
    pub ray_map_fraction: f64,
}

/// Where `--display` sends the layers.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Display {
    /// tev's address, HOST:PORT.
    Tev(String),
}

/// Parses `--display`: `tev` or `tev=HOST:PORT`.
pub fn parse_display(text: &str) -> Result<Display, String> {
    match text.split_once('=') {
        None if text == "tev" => Ok(Display::Tev(crate::live::tev::DEFAULT_ADDRESS.to_string())),
        Some(("tev", address))
            if address.rsplit_once(':').is_some_and(|(h, p)| !h.is_empty() && p.parse::<u16>().is_ok()) =>
        {
            Ok(Display::Tev(address.to_string()))
        }
        Some(("tev", address)) => Err(format!("'{address}' is not HOST:PORT (e.g. tev=127.0.0.1:14158)")),
        _ => Err(format!("'{text}' is not a display: the one there is is tev, as `tev` or `tev=HOST:PORT`")),
    }
}

/// Parses a size in bytes with an optional K, M, G or T suffix (powers of 1024; "B", "iB" accepted), e.g. 2G.
pub fn parse_size(text: &str) -> Result<u64, String> {
    let t = text.trim();
    let upper = t.to_ascii_uppercase();
    let number = upper.trim_end_matches('B').trim_end_matches('I');
    let (digits, unit) = match number.char_indices().last() {
        Some((i, c)) if c.is_ascii_alphabetic() => (&number[..i], c),
        _ => (number, ' '),
    };
    let scale: f64 = match unit {
        ' ' => 1.0,
        'K' => 1024.0,
        'M' => 1024.0 * 1024.0,
        'G' => 1024.0 * 1024.0 * 1024.0,
        'T' => 1024.0 * 1024.0 * 1024.0 * 1024.0,
        _ => return Err(format!("'{t}' has an unknown unit (use K, M, G or T, e.g. 2G)")),
    };
    let value: f64 = digits.trim().parse().map_err(|_| format!("'{t}' is not a size (e.g. 2G or 500M)"))?;
    if !(value.is_finite() && value > 0.0) {
        return Err(format!("'{t}' is not a positive size"));
    }
    Ok((value * scale) as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_method_is_a_value_of_method_with_its_name() {
        for m in Method::ALL {
            let cli = Cli::try_parse_from(["coordinator", "render", "scene.toml", "--method", m.name()]).unwrap();
            let Command::Render(args) = cli.command else { panic!("not a render") };
            assert_eq!(args.method, m);
        }
        let bench = Cli::try_parse_from(["coordinator", "bench", "--methods", "sync,three-level"]).unwrap();
        let Command::Bench(args) = bench.command else { panic!("not a bench") };
        assert_eq!(args.methods, [Method::Sync, Method::ThreeLevel]);
        let default = Cli::try_parse_from(["coordinator", "bench"]).unwrap();
        let Command::Bench(args) = default.command else { panic!("not a bench") };
        assert_eq!(args.methods.len(), Method::ALL.len());
        let e = Cli::try_parse_from(["coordinator", "render", "s.toml", "--method", "fast"]).unwrap_err();
        assert!(e.to_string().contains("two-level"), "{e}");
    }

    #[test]
    fn display_takes_tev_with_or_without_an_address_and_refuses_anything_else() {
        assert_eq!(parse_display("tev"), Ok(Display::Tev("127.0.0.1:14158".into())));
        assert_eq!(parse_display("tev=viewer:9000"), Ok(Display::Tev("viewer:9000".into())));
        for bad in ["", "tev=", "tev=host", "tev=:80", "tev=host:port", "pbrt", "window=1"] {
            assert!(parse_display(bad).is_err(), "{bad}");
        }
        let cli = Cli::try_parse_from(["coordinator", "render", "s.toml", "--serve"]).unwrap();
        let Command::Render(args) = cli.command else { panic!("not a render") };
        assert_eq!(args.serve, Some("127.0.0.1:0".parse().unwrap()));
    }

    #[test]
    fn sizes_parse_with_binary_units_and_bad_ones_are_refused() {
        assert_eq!(parse_size("2G"), Ok(2 << 30));
        assert_eq!(parse_size("500M"), Ok(500 << 20));
        assert_eq!(parse_size("1.5GiB"), Ok(3 << 29));
        assert_eq!(parse_size("4096"), Ok(4096));
        assert_eq!(parse_size("64kb"), Ok(64 << 10));
        for bad in ["", "G", "-1G", "2X", "lots"] {
            assert!(parse_size(bad).is_err(), "{bad}");
        }
    }
}
