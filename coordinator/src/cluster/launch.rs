//! Starting a distributed render: the NUMA nodes, one local worker process per node, the remote workers, and
//! the job each of them gets.

use super::network::{Blocklist, FileStore, NetworkPlan, Planned, Timing};
use super::numa_nodes::{self, NumaNode, NumaNodes};
use super::{Cluster, Member};
use anyhow::{bail, Context, Result};
use photonfarm::protocol::auth::SECRET_ENV;
use photonfarm::protocol::tls::{Tls, Transport};
use photonfarm::protocol::{EngineSpec, FileRef, Job, RayMapRequest, Role, Secret};
use photonfarm::ray_map::Recorder;
use photonfarm::render::method::Grouping;
use photonfarm::render::{Method, RenderSettings};
use photonfarm::scene::description::SceneDescription;
use photonfarm::scene::Scene;
use std::net::{SocketAddr, TcpListener};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::time::Duration;

/// What a distributed render takes from the command line.
#[derive(Clone, Debug)]
pub struct LaunchOptions {
    /// A method that runs worker processes: combination or three-level.
    pub method: Method,
    pub scene_path: PathBuf,
    /// A synthetic description or an hwloc XML file to take the NUMA nodes from instead of this machine's.
    pub topology: Option<String>,
    /// `worker serve` daemons to dial, as HOST:PORT.
    pub remote_workers: Vec<String>,
    /// Where workers may dial in (`worker join ADDR`).
    pub listen: Option<SocketAddr>,
    /// Start no local worker.
    pub remote_only: bool,
    /// The shared secret for remote workers (otherwise the environment's).
    pub secret_file: Option<PathBuf>,
    /// Allow remote links without a secret and without TLS.
    pub insecure: bool,
    /// The key folder of `coordinator keys init`: remote links run over TLS with its certificates.
    pub tls_dir: Option<PathBuf>,
    /// Seconds of silence after which a worker is presumed hung.
    pub worker_timeout_s: f64,
    /// Lost links after which a host's workers are refused for the rest of the job.
    pub max_worker_failures: u32,
    /// Seconds between a worker's snapshots (remote workers lengthen it on slow links).
    pub snapshot_interval_s: f64,
    /// Most threads per group where workers run two-level.
    pub group_size: usize,
    pub tile_size: Option<u32>,
    pub phases_per_deal: u32,
    /// The fraction of paths each worker records into the run's ray map (`--ray-map`).
    pub ray_map_fraction: Option<f64>,
    /// `--memory-limit`: what each worker process may use.
    pub memory_limit: Option<u64>,
}

impl LaunchOptions {
    /// True when workers render from the run's start (local ones, or `--worker` daemons it dials): they then
    /// decide the lit mask (`Job::decide_lit_mask`) and the coordinator builds no BVH. A coordinator that only
    /// listens decides the mask itself, since its clock runs before any worker joins.
    pub fn starts_with_workers(&self) -> bool {
        !self.remote_only || !self.remote_workers.is_empty()
    }
}

/// What a resumed run continues from.
pub struct Resume {
    pub session: u32,
    pub sums: photonfarm::accumulation::Accumulator,
    pub totals: photonfarm::render::RayTotals,
}

/// The `worker` program next to this one.
pub fn worker_program() -> Result<PathBuf> {
    let exe = std::env::current_exe().context("cannot find this program's path")?;
    let path = exe.with_file_name(format!("worker{}", std::env::consts::EXE_SUFFIX));
    if !path.is_file() {
        bail!(
            "the worker program is missing: expected it at {} (build it with `cargo build --release`)",
            path.display()
        );
    }
    Ok(path)
}

/// Launches the local workers and the network, and returns the cluster with a description of its layout.
pub fn launch(
    options: &LaunchOptions,
    scene: &Scene,
    settings: RenderSettings,
    dir: &Path,
    resume: Option<Resume>,
    ray_map: Option<Arc<Recorder>>,
) -> Result<(Cluster, String)> {
    let timing = check(options)?;
    let nodes = numa_nodes::detect(options.topology.as_deref(), &worker::machine::all_cores())?;
    let remote_secret = remote_secret(options)?;
    let remote_transport = remote_transport(options)?;
    let request = options.ray_map_fraction.filter(|_| ray_map.is_some()).map(|fraction| RayMapRequest { fraction });
    let template = JobTemplate::new(options, scene, settings, &nodes, resume.as_ref(), request)?;
    let (members, jobs) = plan_workers(options, &nodes, &template);
    if members.is_empty() && options.listen.is_none() {
        bail!("--remote-only needs --worker HOST:PORT or --listen ADDR");
    }
    let local_secret = Secret::random();
    let any_local = members.iter().any(|m| matches!(m.planned, Planned::Local { .. }));
    let local = if any_local { Some(listen("127.0.0.1:0".parse()?, "a loopback port for the workers")?) } else { None };
    let public = options.listen.map(|addr| listen(addr, &addr.to_string())).transpose()?;
    let children = match &local {
        Some(listener) => start_local_workers(&members, listener.local_addr()?.port(), &local_secret, dir)?,
        None => Vec::new(),
    };
    let layout = describe(options, &members, &nodes);
    let plan = NetworkPlan {
        planned: members.iter().map(|m| m.planned.clone()).collect(),
        jobs,
        join_template: template.join_job(),
        files: Arc::new(template.store.clone()),
        local: local.map(|l| (l, local_secret)),
        public: public.map(|l| (l, remote_secret.clone())),
        remote_secret,
        remote_transport,
        timing,
        blocklist: Arc::new(Blocklist::new(options.max_worker_failures)),
        ray_map,
    };
    let initial = resume.map(|r| (r.sums, r.totals));
    let aux = photonfarm::accumulation::AuxLayout::for_scene(scene, settings.spectral_bands);
    let size = (scene.camera.width, scene.camera.height);
    let lit_from = template.decide_lit_mask.then_some(0);
    let cluster = Cluster::start(members, plan, children, size, aux, settings, initial, lit_from)?;
    Ok((cluster, layout))
}

/// Refuses options no worker could run with, and gives the links' timing.
fn check(options: &LaunchOptions) -> Result<Timing> {
    if !options.method.is_distributed() {
        bail!("--method {} runs no worker processes", options.method);
    }
    // The group size is checked here, before any worker starts, rather than by every worker.
    options.method.layout().grouping.split(1, options.group_size)?;
    if !(options.snapshot_interval_s.is_finite() && options.snapshot_interval_s > 0.0) {
        bail!("--snapshot-interval must be a positive number of seconds");
    }
    if options.max_worker_failures == 0 {
        bail!("--max-worker-failures must be at least 1");
    }
    if !(options.worker_timeout_s.is_finite() && options.worker_timeout_s >= 2.0) {
        bail!("--worker-timeout must be at least 2 seconds (workers send a heartbeat every second)");
    }
    Ok(Timing { heartbeat: Duration::from_secs(1), peer_timeout: Duration::from_secs_f64(options.worker_timeout_s) })
}

/// True when every link to remote workers stays on this machine (`--worker` and `--listen` addresses on
/// loopback): such links need neither a secret nor TLS.
fn loopback_only(options: &LaunchOptions) -> bool {
    let is_loopback = |w: &String| {
        use std::net::ToSocketAddrs;
        w.to_socket_addrs().map(|mut a| a.all(|a| a.ip().is_loopback())).unwrap_or(false)
    };
    options.remote_workers.iter().all(is_loopback) && options.listen.is_none_or(|l| l.ip().is_loopback())
}

fn remote_secret(options: &LaunchOptions) -> Result<Secret> {
    let insecure_allowed = options.insecure || loopback_only(options);
    Ok(Secret::resolve(options.secret_file.as_deref(), options.tls_dir.as_deref(), insecure_allowed)?)
}

/// TLS with the `--tls-dir` keys; plaintext only on loopback or with an explicit `--insecure`.
fn remote_transport(options: &LaunchOptions) -> Result<Transport> {
    if let Some(dir) = &options.tls_dir {
        return Ok(Transport::Tls(Tls::load(dir, Role::Coordinator)?));
    }
    if options.insecure || loopback_only(options) {
        return Ok(Transport::Plain);
    }
    bail!(
        "links to workers on other machines are encrypted: give --tls-dir DIR with the keys of `coordinator keys \
         init DIR` (and the workers their copy), or --insecure to send scenes and images in the clear"
    )
}

/// What every worker's job shares: the scene, its meshes, the settings and the engine of each process.
struct JobTemplate {
    scene_name: String,
    scene: SceneDescription,
    files: Vec<FileRef>,
    /// The meshes by content hash, for workers that ask for them.
    store: FileStore,
    scene_hash: String,
    settings: RenderSettings,
    engine: EngineSpec,
    /// Added to every worker's stream: a resumed run's streams never repeat an earlier session's.
    stream_base: usize,
    /// The nodes are a synthetic topology's, mapped onto the real cores.
    synthetic_nodes: bool,
    local_interval: Duration,
    /// Remote workers start at the local interval and lengthen it on slow links (see worker::link).
    remote_interval: Duration,
    ray_map: Option<RayMapRequest>,
    decide_lit_mask: bool,
}

impl JobTemplate {
    fn new(
        options: &LaunchOptions,
        scene: &Scene,
        settings: RenderSettings,
        nodes: &NumaNodes,
        resume: Option<&Resume>,
        ray_map: Option<RayMapRequest>,
    ) -> Result<Self> {
        let path = &options.scene_path;
        let base = path.parent().unwrap_or(Path::new("."));
        let session = resume.map_or(1, |r| r.session);
        let resumed_phases = resume.map_or(0, |r| {
            let n = r.sums.pixels.len().max(1) as u64;
            (r.sums.pixels.iter().map(|p| p.phases as u64).sum::<u64>() / n) as u32
        });
        let method =
            options.method.layout().parallel.context("a distributed method names the method of its workers")?;
        let interval = Duration::from_secs_f64(options.snapshot_interval_s);
        Ok(JobTemplate {
            scene_name: path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default(),
            scene: scene.description.clone(),
            files: scene.description.files.clone(),
            store: scene.mesh_files.iter().map(|(p, h)| (h.clone(), base.join(p))).collect(),
            scene_hash: scene.hash.clone(),
            settings,
            engine: EngineSpec {
                method,
                group_size: options.group_size,
                tile_size: options.tile_size,
                phases_per_deal: Some(options.phases_per_deal),
                cores: None,
                numa_node: None,
                synthetic_topology: false,
                processes_per_pixel: 1,
                process_rank: 0,
                resumed_phases,
                memory_limit: options.memory_limit,
            },
            stream_base: (session as usize - 1) << 16,
            synthetic_nodes: nodes.synthetic,
            local_interval: interval,
            remote_interval: interval,
            ray_map,
            decide_lit_mask: options.starts_with_workers(),
        })
    }

    /// The job of a worker joining through `--listen`, its stream set as it joins. It never decides the lit
    /// mask: the run's first planned worker does, or the coordinator.
    fn join_job(&self) -> Job {
        Job { decide_lit_mask: false, ..self.job(0, None, self.remote_interval) }
    }

    /// The job of the worker with random stream `stream`, on `node`'s cores (a local worker) or on every core
    /// of its machine.
    fn job(&self, stream: usize, node: Option<&NumaNode>, interval: Duration) -> Job {
        Job {
            scene_name: self.scene_name.clone(),
            scene: self.scene.clone(),
            files: self.files.clone(),
            scene_hash: self.scene_hash.clone(),
            settings: self.settings,
            stream: (self.stream_base + stream) as u64,
            engine: EngineSpec {
                cores: node.map(|n| n.cores.clone()),
                numa_node: node.map(|n| n.index),
                synthetic_topology: self.synthetic_nodes && node.is_some(),
                ..self.engine.clone()
            },
            snapshot_interval_ms: interval.as_millis() as u64,
            ray_map: self.ray_map,
            // One worker decides the mask: the others, each on every core of the machine, would only slow it.
            decide_lit_mask: self.decide_lit_mask && stream == 0,
        }
    }
}

/// The workers the run starts with, one local one per NUMA node (unless remote only) and the remote ones, with
/// their jobs.
fn plan_workers(options: &LaunchOptions, nodes: &NumaNodes, template: &JobTemplate) -> (Vec<Member>, Vec<Job>) {
    let mut members = Vec::new();
    let mut jobs = Vec::new();
    if !options.remote_only {
        for node in &nodes.nodes {
            let name = format!("node{}", node.index);
            jobs.push(template.job(members.len(), Some(node), template.local_interval));
            members.push(Member {
                planned: Planned::Local { name: name.clone() },
                name,
                numa_node: Some(node.index),
                cores: node.cores.clone(),
            });
        }
    }
    for address in &options.remote_workers {
        jobs.push(template.job(members.len(), None, template.remote_interval));
        members.push(Member {
            planned: Planned::Remote { address: address.clone() },
            name: address.clone(),
            numa_node: None,
            cores: vec![],
        });
    }
    // Every planned worker renders every pixel: a pixel's radius schedule counts the phases of them all.
    let processes_per_pixel = jobs.len().max(1) as u32;
    for (i, j) in jobs.iter_mut().enumerate() {
        j.engine.processes_per_pixel = processes_per_pixel;
        j.engine.process_rank = i as u32;
    }
    (members, jobs)
}

/// A non-blocking listener (the network thread adopts it).
fn listen(addr: SocketAddr, what: &str) -> Result<TcpListener> {
    let l = TcpListener::bind(addr).with_context(|| format!("cannot listen on {what}"))?;
    l.set_nonblocking(true)?;
    Ok(l)
}

/// Starts one `worker join` process per local member, dialling the loopback `port`; each logs into
/// `dir/workers/NAME.log`.
fn start_local_workers(members: &[Member], port: u16, secret: &Secret, dir: &Path) -> Result<Vec<Child>> {
    let program = worker_program()?;
    let logs = dir.join("workers");
    std::fs::create_dir_all(&logs).with_context(|| format!("cannot create {}", logs.display()))?;
    let mut children = Vec::new();
    for m in members.iter().filter(|m| matches!(m.planned, Planned::Local { .. })) {
        let log_path = logs.join(format!("{}.log", m.name));
        let log = std::fs::File::create(&log_path).with_context(|| format!("cannot create {}", log_path.display()))?;
        let child = Command::new(&program)
            .args(["join", &format!("127.0.0.1:{port}"), "--name", &m.name])
            .env(SECRET_ENV, String::from_utf8_lossy(secret.expose_for_child()).into_owned())
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .with_context(|| format!("cannot start {}", program.display()))?;
        children.push(child);
    }
    Ok(children)
}

/// The layout in words, e.g. "2 worker processes (2 NUMA nodes of this machine), one synchronous group inside
/// each".
fn describe(options: &LaunchOptions, members: &[Member], nodes: &NumaNodes) -> String {
    let plural = |n: usize, suffix: &'static str| if n == 1 { "" } else { suffix };
    let origin = if options.remote_only {
        "remote only".to_string()
    } else {
        format!("{} NUMA node{} of {}", nodes.nodes.len(), plural(nodes.nodes.len(), "s"), nodes.source)
    };
    let remote = options.remote_workers.len();
    let inside = match options.method.layout().grouping {
        Grouping::GroupsOfSize => format!("two-level with groups of at most {}", options.group_size),
        _ => "one synchronous group".to_string(),
    };
    format!(
        "{} worker process{} ({origin}{}{}), {inside} inside each",
        members.len(),
        plural(members.len(), "es"),
        if remote == 0 { String::new() } else { format!(", {remote} remote") },
        if options.listen.is_some() { ", accepting joins" } else { "" },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn options(remote_only: bool, remote_workers: Vec<String>) -> LaunchOptions {
        LaunchOptions {
            method: Method::ThreeLevel,
            scene_path: Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell.toml"),
            topology: Some("pack:1 numa:2 core:1 pu:1".into()),
            remote_workers,
            listen: None,
            remote_only,
            secret_file: None,
            insecure: false,
            tls_dir: None,
            worker_timeout_s: 10.0,
            max_worker_failures: 3,
            snapshot_interval_s: 1.0,
            group_size: 1,
            tile_size: None,
            phases_per_deal: 4,
            ray_map_fraction: None,
            memory_limit: None,
        }
    }

    /// Whether each planned worker's job, then a joining worker's, asks it to decide the lit mask.
    fn deciders(options: &LaunchOptions) -> (Vec<bool>, bool) {
        let scene = Scene::load(&options.scene_path).unwrap();
        let nodes = numa_nodes::detect(options.topology.as_deref(), &[0, 1]).unwrap();
        let settings = RenderSettings::for_scene(&scene, options.method, 1);
        let template = JobTemplate::new(options, &scene, settings, &nodes, None, None).unwrap();
        let (_, jobs) = plan_workers(options, &nodes, &template);
        (jobs.iter().map(|j| j.decide_lit_mask).collect(), template.join_job().decide_lit_mask)
    }

    #[test]
    fn only_the_first_planned_worker_decides_the_lit_mask_and_a_listening_coordinator_decides_its_own() {
        // Two local workers and a remote one: the first local one decides, and no joining worker does.
        assert_eq!(deciders(&options(false, vec!["10.0.0.9:7878".into()])), (vec![true, false, false], false));
        // Only remote workers, dialled: the first of them.
        let dialled = options(true, vec!["10.0.0.9:7878".into(), "10.0.0.10:7878".into()]);
        assert!(dialled.starts_with_workers());
        assert_eq!(deciders(&dialled), (vec![true, false], false));
        // A coordinator that only listens has no worker when its clock starts, and decides the mask itself.
        let listening = options(true, vec![]);
        assert!(!listening.starts_with_workers());
        assert_eq!(deciders(&listening), (vec![], false));
    }
}
