//! Starting a distributed render: the NUMA nodes, one local worker process per node, the remote workers, and
//! the job each of them gets.

use super::network::{FileStore, NetworkPlan, Planned, Timing};
use super::topology::{self, MachineTopology};
use super::{Cluster, Member};
use crate::cli::{MethodArg, RenderArgs};
use anyhow::{bail, Context, Result};
use photonfarm::protocol::auth::SECRET_ENV;
use photonfarm::protocol::{EngineSpec, FileRef, Job, Secret};
use photonfarm::render::{ParallelMethod, RenderSettings};
use photonfarm::scene::Scene;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::time::Duration;

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

fn inner_group_size_is_invalid(args: &RenderArgs) -> bool {
    args.method == MethodArg::ThreeLevel && ![1, 2, 4].contains(&args.group_size)
}

fn remote_secret(args: &RenderArgs) -> Result<Secret> {
    if let Some(f) = &args.secret_file {
        return Ok(Secret::from_file(f)?);
    }
    if let Some(s) = Secret::from_env()? {
        return Ok(s);
    }
    let is_loopback = |w: &String| {
        use std::net::ToSocketAddrs;
        w.to_socket_addrs().map(|mut a| a.all(|a| a.ip().is_loopback())).unwrap_or(false)
    };
    let loopback_only = args.workers.iter().all(is_loopback) && args.listen.is_none_or(|l| l.ip().is_loopback());
    if args.insecure || loopback_only {
        return Ok(Secret::insecure());
    }
    bail!(
        "remote workers need a shared secret: --secret-file FILE or ${SECRET_ENV} (or --insecure to allow anyone \
         who can reach the port)"
    )
}

/// What a resumed run continues from.
pub struct Resume {
    pub session: u32,
    pub sums: photonfarm::accumulation::Accumulator,
    pub totals: photonfarm::render::RayTotals,
}

/// Launches the local workers and the network, and returns the cluster with a description of its layout.
pub fn launch(
    args: &RenderArgs,
    scene: &Scene,
    settings: RenderSettings,
    dir: &Path,
    resume: Option<Resume>,
) -> Result<(Cluster, String, MachineTopology)> {
    // Streams of a resumed run never repeat an earlier session's.
    let session = resume.as_ref().map_or(1, |r| r.session);
    let stream_base = (session as usize - 1) << 16;
    let phase_offset = resume.as_ref().map_or(0, |r| {
        let n = r.sums.pixels.len().max(1) as u64;
        (r.sums.pixels.iter().map(|p| p.phases as u64).sum::<u64>() / n) as u32
    });
    if inner_group_size_is_invalid(args) {
        bail!("the group size must be 1, 2 or 4, got {}", args.group_size);
    }
    let real_cores = worker::machine::all_cores();
    let machine = topology::detect(args.topology.as_deref(), &real_cores)?;
    let secret = remote_secret(args)?;
    let inner = if args.method == MethodArg::Combination { ParallelMethod::Sync } else { ParallelMethod::TwoLevel };
    let scene_text =
        std::fs::read_to_string(&args.scene).with_context(|| format!("cannot read {}", args.scene.display()))?;
    let base = args.scene.parent().unwrap_or(Path::new("."));
    let files: Vec<FileRef> =
        scene.mesh_files.iter().map(|(p, h)| FileRef { path: p.clone(), sha256: h.clone() }).collect();
    let store: FileStore = scene.mesh_files.iter().map(|(p, h)| (h.clone(), base.join(p))).collect();
    if !(args.snapshot_interval.is_finite() && args.snapshot_interval > 0.0) {
        bail!("--snapshot-interval must be a positive number of seconds");
    }
    if !(args.worker_timeout.is_finite() && args.worker_timeout >= 2.0) {
        bail!("--worker-timeout must be at least 2 seconds (workers send a heartbeat every second)");
    }
    let job = |stream: usize, cores: Option<Vec<usize>>, node: Option<u32>, interval: Duration| Job {
        scene_name: args.scene.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default(),
        scene_text: scene_text.clone(),
        files: files.clone(),
        scene_hash: scene.hash.clone(),
        settings,
        stream: (stream_base + stream) as u64,
        engine: EngineSpec {
            method: inner,
            group_size: args.group_size,
            tile_size: args.tile_size,
            phases_per_deal: Some(args.phases_per_deal),
            cores,
            numa_node: node,
            synthetic_topology: machine.synthetic && node.is_some(),
            radius_sharers: 1,
            radius_index: 0,
            phase_offset,
        },
        snapshot_interval_ms: interval.as_millis() as u64,
    };
    let local_interval = Duration::from_secs_f64(args.snapshot_interval);
    // Remote workers start at the same interval and lengthen it on slow links (see worker::link).
    let remote_interval = local_interval;
    let mut members = Vec::new();
    let mut jobs = Vec::new();
    if !args.remote_only {
        for node in &machine.nodes {
            let name = format!("node{}", node.index);
            jobs.push(job(members.len(), Some(node.cores.clone()), Some(node.index), local_interval));
            members.push(Member {
                planned: Planned::Local { name: name.clone() },
                name,
                numa_node: Some(node.index),
                cores: node.cores.clone(),
            });
        }
    }
    for w in &args.workers {
        jobs.push(job(members.len(), None, None, remote_interval));
        members.push(Member {
            planned: Planned::Remote { address: w.clone() },
            name: w.clone(),
            numa_node: None,
            cores: vec![],
        });
    }
    if members.is_empty() && args.listen.is_none() {
        bail!("--remote-only needs --worker HOST:PORT or --listen ADDR");
    }
    // Every planned worker renders the whole image: the radius schedule counts all their phases.
    let sharers = jobs.len().max(1) as u32;
    for (i, j) in jobs.iter_mut().enumerate() {
        j.engine.radius_sharers = sharers;
        j.engine.radius_index = i as u32;
    }
    let local_secret = Secret::random();
    let local = if members.iter().any(|m| matches!(m.planned, Planned::Local { .. })) {
        let l = std::net::TcpListener::bind("127.0.0.1:0").context("cannot open a loopback port for the workers")?;
        l.set_nonblocking(true)?;
        Some((l, local_secret.clone()))
    } else {
        None
    };
    let public = match args.listen {
        Some(addr) => {
            let l = std::net::TcpListener::bind(addr).with_context(|| format!("cannot listen on {addr}"))?;
            l.set_nonblocking(true)?;
            Some((l, secret.clone()))
        }
        None => None,
    };
    let mut children = Vec::new();
    if let Some((listener, _)) = &local {
        let port = listener.local_addr()?.port();
        let program = worker_program()?;
        let logs = dir.join("workers");
        std::fs::create_dir_all(&logs).with_context(|| format!("cannot create {}", logs.display()))?;
        for m in members.iter().filter(|m| matches!(m.planned, Planned::Local { .. })) {
            let log_path = logs.join(format!("{}.log", m.name));
            let log =
                std::fs::File::create(&log_path).with_context(|| format!("cannot create {}", log_path.display()))?;
            let child = Command::new(&program)
                .args(["join", &format!("127.0.0.1:{port}"), "--name", &m.name])
                .env(SECRET_ENV, String::from_utf8_lossy(local_secret.expose_for_child()).into_owned())
                .stdin(Stdio::null())
                .stdout(Stdio::null())
                .stderr(log)
                .spawn()
                .with_context(|| format!("cannot start {}", program.display()))?;
            children.push(child);
        }
    }
    let layout = format!(
        "{} worker process{} ({}{}{}), {} inside each",
        members.len(),
        if members.len() == 1 { "" } else { "es" },
        if args.remote_only {
            "remote only".to_string()
        } else {
            format!(
                "{} NUMA node{} of {}",
                machine.nodes.len(),
                if machine.nodes.len() == 1 { "" } else { "s" },
                machine.source
            )
        },
        if args.workers.is_empty() { String::new() } else { format!(", {} remote", args.workers.len()) },
        if args.listen.is_some() { ", accepting joins" } else { "" },
        if inner == ParallelMethod::Sync {
            "one synchronous group".to_string()
        } else {
            format!("two-level with groups of at most {}", args.group_size)
        },
    );
    let mut join_template = job(0, None, None, remote_interval);
    join_template.engine.synthetic_topology = false;
    let plan = NetworkPlan {
        planned: members.iter().map(|m| m.planned.clone()).collect(),
        jobs,
        join_template,
        files: Arc::new(store),
        local,
        public,
        remote_secret: secret,
        timing: Timing {
            heartbeat: Duration::from_secs(1),
            peer_timeout: Duration::from_secs_f64(args.worker_timeout),
        },
    };
    let initial = resume.map(|r| (r.sums, r.totals));
    let aux = photonfarm::accumulation::AuxLayout::for_scene(scene, settings.spectral_bands);
    let cluster =
        Cluster::start(members, plan, children, scene.camera.width, scene.camera.height, aux, settings, initial)?;
    Ok((cluster, layout, machine))
}
