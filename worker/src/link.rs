//! The worker's end of a coordinator link: handshake, job, the files it lacks, then snapshots out and
//! acknowledgements, heartbeats and the stop request in, until the job ends or the link fails.

use crate::files::{Arrivals, FileCache};
use crate::job::{self, JobEvent};
use photonfarm::accumulation::delta::Compression;
use photonfarm::accumulation::LitMask;
use photonfarm::protocol::auth::{handshake, Peer};
use photonfarm::protocol::{
    Connection, Job, LitPixels, Message, ProtocolError, RayMapPortion, Role, Secret, WorkerInfo,
};
use photonfarm::ray_map::{Portion, PortionSink};
use photonfarm::render::session::Deadline;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::mpsc;

/// How a worker behaves on its links.
#[derive(Clone, Debug)]
pub struct LinkOptions {
    /// The name the worker gives in its handshake.
    pub name: String,
    pub secret: Secret,
    /// A heartbeat is sent when nothing else was sent for this long.
    pub heartbeat: Duration,
    /// The coordinator is presumed gone when nothing arrived for this long.
    pub peer_timeout: Duration,
    /// Render this many times slower than possible (1 = full speed): a straggler for tests.
    pub slowdown: f64,
}

impl LinkOptions {
    /// Defaults: heartbeats every second, the coordinator presumed gone after 15 s of silence.
    pub fn new(name: String, secret: Secret) -> Self {
        LinkOptions {
            name,
            secret,
            heartbeat: Duration::from_secs(1),
            peer_timeout: Duration::from_secs(15),
            slowdown: 1.0,
        }
    }
}

/// How a job ended.
#[derive(Debug)]
pub struct JobOutcome {
    pub coordinator: String,
    /// The job's scene file name (empty when the link ended before a job arrived).
    pub job: String,
    pub snapshots_sent: u64,
    pub snapshots_acked: u64,
}

/// Why a link ended without finishing its job.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    #[error(transparent)]
    Protocol(#[from] ProtocolError),
    #[error("the job failed: {0}")]
    Job(String),
}

/// Serves one job over `conn` (whichever side dialled).
pub async fn serve_job(
    mut conn: Connection,
    opts: &LinkOptions,
    cache: &mut FileCache,
) -> Result<JobOutcome, LinkError> {
    let peer: Peer = handshake(&mut conn, Role::Worker, &opts.name, &opts.secret).await?;
    let job = match conn.read_within(Duration::from_secs(60), "Job").await? {
        Message::Job(job) => job,
        Message::Refused { reason } => return Err(ProtocolError::Refused(reason).into()),
        other => return Err(ProtocolError::Unexpected { expected: "Job", got: other.kind().into() }.into()),
    };
    // Tiles the coordinator restricts the job to (adaptive tiles), handed to the engine thread before a round.
    let tiles: Arc<job::PendingTiles> = Arc::default();
    // The processes rendering the image, as the coordinator announces them, likewise.
    let share: Arc<job::PendingShare> = Arc::default();
    // When a timed run stops, likewise.
    let deadline: Arc<job::PendingDeadline> = Arc::default();
    if fetch_files(&mut conn, &job, cache, &tiles, &deadline).await? == Fetched::Stopped {
        // The run ended while this worker was still being set up: nothing rendered, nothing lost.
        conn.write(&Message::Finished).await?;
        drain_until_closed(&mut conn).await;
        return Ok(JobOutcome {
            coordinator: peer.name,
            job: job.scene_name.clone(),
            snapshots_sent: 0,
            snapshots_acked: 0,
        });
    }
    let meshes = match cache.take(&job.files) {
        Ok(m) => m,
        Err(path) => {
            let reason = format!("the scene's file {path} was not received");
            conn.write(&Message::Failed { reason: reason.clone() }).await?;
            return Err(LinkError::Job(reason));
        }
    };
    let job = Arc::new(*job);
    let loading_since = Instant::now();
    let scene = {
        let loading = job.clone();
        let mut load = tokio::task::spawn_blocking(move || {
            let scene = job::load_scene(&loading, &meshes);
            let loaded_s = loading_since.elapsed().as_secs_f64();
            // The coordinator builds no BVH: the worker decides which pixels see a light, as it would have.
            let lit = match &scene {
                Ok(scene) if loading.decide_lit_mask => {
                    let deciding = Instant::now();
                    let mask = LitMask::of_scene(scene, loading.settings.max_depth);
                    Some(LitPixels::of(&mask, deciding.elapsed().as_secs_f64()))
                }
                _ => None,
            };
            (scene, meshes, loaded_s, lit)
        });
        // A large mesh takes longer to read and build than the coordinator waits for a silent worker: the
        // heartbeats go on meanwhile. What the coordinator sends waits in the link until the engine runs.
        let mut tick = tokio::time::interval(opts.heartbeat);
        loop {
            tokio::select! {
                loaded = &mut load => {
                    let (scene, meshes, loaded_s, lit) =
                        loaded.map_err(|e| LinkError::Job(format!("the scene loader panicked: {e}")))?;
                    cache.give_back(&job.files, meshes);
                    if let Some(lit) = lit {
                        conn.write(&Message::LitPixels(lit)).await?;
                    }
                    break (scene, loaded_s);
                }
                _ = tick.tick() => conn.write(&Message::Heartbeat).await?,
            }
        }
    };
    let (scene, scene_load_s) = scene;
    let scene = match scene {
        Ok(s) => s,
        Err(reason) => {
            conn.write(&Message::Failed { reason: reason.clone() }).await?;
            return Err(LinkError::Job(reason));
        }
    };
    let bvh_cache = scene.geometry.bvh_cache().clone();

    let stop = Arc::new(AtomicBool::new(false));
    // Snapshot interval: the job's, lengthened so that sending a snapshot (until it is acknowledged) takes at
    // most 5% of the link's time. On this machine the link is free: a send's time is the two processes' work
    // on a core the renderer shares, which a snapshot of only the pixels rendered since the previous one does
    // not lower by waiting longer, and a longer interval would hold back the previews and δ.
    let floor_ms = job.snapshot_interval_ms.max(1);
    let adapts = !conn.peer.ip().is_loopback();
    let interval_ms = Arc::new(AtomicU64::new(floor_ms));
    // How long the latest snapshot took until it was acknowledged: sent with the next one, and read by the
    // engine to stop rendering that much before a deadline.
    let send_ms = Arc::new(AtomicU64::new(0));
    let (events_tx, mut events) = mpsc::unbounded_channel();
    // The ray map's portions, from the recorder's writer thread: a bounded channel, so that a slow link makes
    // the recorder wait rather than the worker's memory grow.
    let (ray_map, mut portions) = match job.ray_map {
        Some(_) => {
            let (tx, rx) = mpsc::channel(PORTIONS_IN_FLIGHT);
            (Some(Box::new(LinkSink { portions: tx, peer: conn.peer.to_string() }) as Box<dyn PortionSink>), Some(rx))
        }
        None => (None, None),
    };
    let engine = {
        let (job, stop, slowdown) = (job.clone(), stop.clone(), opts.slowdown);
        let (interval_ms, send_ms) = (interval_ms.clone(), send_ms.clone());
        let (tiles, share, deadline) = (tiles.clone(), share.clone(), deadline.clone());
        // On this machine the link is free and the worker's time is not: compress fast.
        let compression = Compression::for_peer(conn.peer);
        // The engine's events name the job and the worker.
        let span = tracing::info_span!("job", job = %job.scene_name, worker = %opts.name);
        std::thread::Builder::new()
            .name("job".into())
            .spawn(move || {
                let _span = span.enter();
                let control = job::Control {
                    stop: &stop,
                    interval_ms: &interval_ms,
                    send_ms: &send_ms,
                    tiles: &tiles,
                    share: &share,
                    deadline: &deadline,
                    ray_map,
                };
                job::run(&scene, &job, control, slowdown, compression, |e| events_tx.send(e).is_ok())
            })
            .map_err(|e| LinkError::Job(format!("cannot start the engine thread: {e}")))?
    };
    // Whatever ends the link, the engine stops.
    struct StopOnDrop(Arc<AtomicBool>);
    impl Drop for StopOnDrop {
        fn drop(&mut self) {
            self.0.store(true, Ordering::Release);
        }
    }
    let _stop_guard = StopOnDrop(stop.clone());

    let (reader, mut writer) = conn.split();
    let (mut incoming, reader_task) = reader.forward();
    let (mut sent, mut acked, mut last_seq) = (0u64, 0u64, 0u64);
    let mut finished = false;
    // The snapshot sent last and when its sending began, until it is acknowledged.
    let mut in_flight: Option<(u64, Instant)> = None;
    let mut last_sent = Instant::now();
    let mut last_heard = Instant::now();
    let mut tick = tokio::time::interval(Duration::from_millis(200));
    let result = loop {
        if finished && acked >= last_seq {
            break Ok(());
        }
        tokio::select! {
            event = events.recv(), if !finished => {
                let message = match event {
                    Some(JobEvent::Started(info)) => {
                        Message::Started(WorkerInfo { scene_load_s, bvh_cache: bvh_cache.clone(), ..info })
                    }
                    Some(JobEvent::Snapshot(mut s)) => {
                        sent += 1;
                        last_seq = s.seq;
                        s.previous_send_ms = send_ms.load(Ordering::Relaxed);
                        // A send is timed until its acknowledgement: the write alone returns as soon as the
                        // kernel's socket buffer holds the frame, which on a slow link can be megabytes early.
                        in_flight = Some((s.seq, Instant::now()));
                        writer.write(&Message::Snapshot(s)).await?;
                        last_sent = Instant::now();
                        continue;
                    }
                    Some(JobEvent::Finished) => {
                        // The recorder finished before the engine said so: its last portions are all waiting.
                        if let Some(rx) = &mut portions {
                            while let Some(p) = rx.recv().await {
                                writer.write(&portion_message(p)).await?;
                            }
                        }
                        finished = true;
                        Message::Finished
                    }
                    Some(JobEvent::Failed(reason)) => {
                        let _ = writer.write(&Message::Failed { reason: reason.clone() }).await;
                        break Err(LinkError::Job(reason));
                    }
                    None => break Err(LinkError::Job("the engine thread ended without finishing".into())),
                };
                writer.write(&message).await?;
                last_sent = Instant::now();
            }
            Some(p) = next_portion(&mut portions), if !finished => {
                writer.write(&portion_message(p)).await?;
                last_sent = Instant::now();
            }
            message = incoming.recv() => {
                last_heard = Instant::now();
                match message.map(|(m, _)| m) {
                    Some(Ok(Message::Ack { seq })) => {
                        acked = acked.max(seq);
                        if let Some((_, t)) = in_flight.filter(|(s, _)| seq >= *s) {
                            let took_ms = t.elapsed().as_millis() as u64;
                            send_ms.store(took_ms, Ordering::Relaxed);
                            if adapts {
                                interval_ms.store(floor_ms.max(20 * took_ms), Ordering::Relaxed);
                            }
                            in_flight = None;
                        }
                    }
                    Some(Ok(Message::Stop)) => stop.store(true, Ordering::Release),
                    Some(Ok(Message::ActiveTiles { tile, flags })) => {
                        *tiles.lock().unwrap_or_else(|e| e.into_inner()) = Some((tile, flags));
                    }
                    Some(Ok(Message::Share(s))) => {
                        *share.lock().unwrap_or_else(|e| e.into_inner()) = Some(s);
                    }
                    Some(Ok(Message::StopAt { in_ms, slack_ms })) => {
                        *deadline.lock().unwrap_or_else(|e| e.into_inner()) = Some(stop_at(in_ms, slack_ms));
                    }
                    Some(Ok(Message::Heartbeat)) => {}
                    Some(Ok(other)) => {
                        break Err(ProtocolError::Unexpected { expected: "Ack, Stop, StopAt, ActiveTiles, Share or Heartbeat", got: other.kind().into() }.into())
                    }
                    // After `Finished` the coordinator may close once it has what it needs.
                    Some(Err(ProtocolError::Closed)) | None if finished => break Ok(()),
                    Some(Err(e)) => break Err(e.into()),
                    None => break Err(ProtocolError::Closed.into()),
                }
            }
            _ = tick.tick() => {
                if last_heard.elapsed() > opts.peer_timeout {
                    break Err(ProtocolError::Timeout(opts.peer_timeout, "the coordinator").into());
                }
                if last_sent.elapsed() >= opts.heartbeat {
                    writer.write(&Message::Heartbeat).await?;
                    last_sent = Instant::now();
                }
            }
        }
    };
    stop.store(true, Ordering::Release);
    // Nobody takes portions any more: a recorder still sending one gets an error rather than waiting forever.
    drop(portions);
    reader_task.abort();
    if result.is_ok() {
        let _ = writer.shutdown().await;
    }
    drop(events);
    // The engine notices the stop flag within a round; its thread holds no lock the link needs.
    let _ = tokio::task::spawn_blocking(move || engine.join()).await;
    result.map(|()| JobOutcome {
        coordinator: peer.name,
        job: job.scene_name.clone(),
        snapshots_sent: sent,
        snapshots_acked: acked,
    })
}

/// Portions of the ray map that may wait for the link before the recorder's writer waits.
const PORTIONS_IN_FLIGHT: usize = 4;

/// The recorder's sink in a worker: its writer thread hands each compressed portion to the link.
struct LinkSink {
    portions: mpsc::Sender<Portion>,
    /// The coordinator's address, for messages.
    peer: String,
}

impl PortionSink for LinkSink {
    fn append(&mut self, portion: Portion) -> std::io::Result<()> {
        self.portions
            .blocking_send(portion)
            .map_err(|_| std::io::Error::new(std::io::ErrorKind::BrokenPipe, "the link to the coordinator has ended"))
    }

    fn name(&self) -> String {
        format!("the link to the coordinator at {}", self.peer)
    }
}

/// The next portion of the ray map; pending forever without a map or once its channel is closed, so that a
/// `select!` branch on it stays quiet.
async fn next_portion(portions: &mut Option<mpsc::Receiver<Portion>>) -> Option<Portion> {
    match portions {
        Some(rx) => match rx.recv().await {
            Some(p) => Some(p),
            None => {
                *portions = None;
                std::future::pending().await
            }
        },
        None => std::future::pending().await,
    }
}

/// The message that carries a portion.
fn portion_message(p: Portion) -> Message {
    let h = p.header;
    Message::RayMapPortion(RayMapPortion { raw_bytes: h.raw, paths: h.paths, segments: h.segments, frame: p.frame })
}

/// Whether the job's files all arrived, or the coordinator stopped the run first.
#[derive(Debug, PartialEq, Eq)]
enum Fetched {
    All,
    Stopped,
}

/// Reads what the coordinator still sends after this worker said `Finished` (files it had asked for, a last
/// heartbeat) until the coordinator closes the link, so that closing first does not reset a link the
/// coordinator is still writing to; gives up after a few seconds.
async fn drain_until_closed(conn: &mut Connection) {
    let deadline = Instant::now() + Duration::from_secs(10);
    while let Ok(Ok(_)) = tokio::time::timeout(deadline.saturating_duration_since(Instant::now()), conn.read()).await {}
}

/// The deadline of a `StopAt` received now. Milliseconds beyond any real run (a forged or corrupt message)
/// saturate to no deadline a run would reach.
fn stop_at(in_ms: u64, slack_ms: u64) -> Deadline {
    let ms = |m: u64| Duration::from_millis(m.min(u32::MAX as u64));
    let now = std::time::Instant::now();
    Deadline { at: now + ms(in_ms), slack: ms(slack_ms) }
}

/// Asks for the job's files that are not in `cache` and assembles each from its pieces, checked against its
/// hash. A stop request that arrives first ends the job normally; active tiles and a stop time that arrive
/// meanwhile are kept for the engine.
async fn fetch_files(
    conn: &mut Connection,
    job: &Job,
    cache: &mut FileCache,
    tiles: &job::PendingTiles,
    deadline: &job::PendingDeadline,
) -> Result<Fetched, ProtocolError> {
    let mut missing: Vec<String> = job.files.iter().map(|f| f.sha256.clone()).filter(|h| !cache.contains(h)).collect();
    missing.sort();
    missing.dedup();
    if missing.is_empty() {
        return Ok(Fetched::All);
    }
    conn.write(&Message::NeedFiles { hashes: missing.clone() }).await?;
    let mut arrivals = Arrivals::expecting(&missing);
    while !arrivals.is_done() {
        match conn.read_within(Duration::from_secs(120), "FilePiece").await? {
            Message::FilePiece(piece) => {
                if let Some((sha256, bytes)) = arrivals.receive(piece)? {
                    cache.insert(sha256, bytes);
                }
            }
            Message::Stop => return Ok(Fetched::Stopped),
            Message::ActiveTiles { tile, flags } => {
                *tiles.lock().unwrap_or_else(|e| e.into_inner()) = Some((tile, flags));
            }
            Message::StopAt { in_ms, slack_ms } => {
                *deadline.lock().unwrap_or_else(|e| e.into_inner()) = Some(stop_at(in_ms, slack_ms));
            }
            Message::Heartbeat => {}
            Message::Refused { reason } => return Err(ProtocolError::Refused(reason)),
            other => return Err(ProtocolError::Unexpected { expected: "FilePiece", got: other.kind().into() }),
        }
    }
    Ok(Fetched::All)
}

#[cfg(test)]
mod tests {
    use super::*;
    use photonfarm::protocol::auth::handshake;
    use photonfarm::protocol::{EngineSpec, FilePiece, FileRef};
    use photonfarm::render::method::ParallelMethod;
    use photonfarm::render::{Method, RenderSettings};
    use photonfarm::scene::description::SceneDescription;
    use photonfarm::scene::Scene;
    use std::collections::BTreeMap;
    use std::path::Path;
    use tokio::net::{TcpListener, TcpStream};

    /// Cornell's job, whose meshes a new worker must ask for.
    fn cornell_job() -> (Job, BTreeMap<String, Vec<u8>>) {
        let scenes = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
        let path = scenes.join("cornell.toml");
        let scene = Scene::load(&path).unwrap();
        let files: Vec<FileRef> =
            scene.mesh_files.iter().map(|(p, h)| FileRef { path: p.clone(), sha256: h.clone() }).collect();
        let store = scene.mesh_files.iter().map(|(p, h)| (h.clone(), std::fs::read(scenes.join(p)).unwrap())).collect();
        let job = Job {
            scene_name: "cornell.toml".into(),
            scene: scene.description.clone(),
            files,
            scene_hash: scene.hash.clone(),
            settings: RenderSettings::for_scene(&scene, Method::ThreeLevel, 1),
            stream: 0,
            engine: EngineSpec {
                method: ParallelMethod::TwoLevel,
                group_size: 1,
                tile_size: None,
                phases_per_deal: Some(6),
                cores: None,
                numa_node: None,
                synthetic_topology: false,
                processes_per_pixel: 1,
                process_rank: 0,
                resumed_phases: 0,
                memory_limit: None,
            },
            snapshot_interval_ms: 1000,
            ray_map: None,
            decide_lit_mask: false,
        };
        (job, store)
    }

    /// Cornell's job at 16 × 16 pixels, its description read from a copy of the scene and its meshes in a
    /// folder that is removed before the job is sent: the description and the files it names are all that is
    /// left of the scene.
    fn cornell_job_without_its_file() -> (Job, BTreeMap<String, Vec<u8>>) {
        let scenes = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
        let options = Default::default();
        let (original, _) = SceneDescription::read(&scenes.join("cornell.toml"), &options).unwrap();
        let dir = std::env::temp_dir().join(format!("photonfarm-worker-description-{}", std::process::id()));
        for name in std::iter::once("cornell.toml").chain(original.files.iter().map(|f| f.path.as_str())) {
            std::fs::create_dir_all(dir.join(name).parent().unwrap()).unwrap();
            std::fs::copy(scenes.join(name), dir.join(name)).unwrap();
        }
        let path = dir.join("cornell.toml");
        let (mut desc, files) = SceneDescription::read(&path, &options).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        assert!(!path.exists());
        (desc.camera.width, desc.camera.height) = (16, 16);
        let store = desc.files.iter().map(|f| (f.sha256.clone(), files[&f.path].clone())).collect();
        let (mut job, _) = cornell_job();
        job.scene_hash = desc.hash();
        job.files = desc.files.clone();
        job.scene = desc;
        job.snapshot_interval_ms = 100;
        (job, store)
    }

    #[test]
    fn a_worker_renders_from_the_description_where_the_scene_file_is_absent_and_sends_its_lit_mask_first() {
        let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
        runtime.block_on(async {
            let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
            let addr = listener.local_addr().unwrap();
            let (mut job, store) = cornell_job_without_its_file();
            job.decide_lit_mask = true;
            let files = job.files.iter().map(|f| (f.path.clone(), store[&f.sha256].clone())).collect();
            let expected =
                LitMask::of_scene(&Scene::from_description(&job.scene, &files).unwrap(), job.settings.max_depth);
            assert!(expected.lit_count() > 0, "the light is in view");
            let sent = store.len();
            let coordinator = tokio::spawn(async move {
                let (s, _) = listener.accept().await.unwrap();
                let mut c = Connection::new(s).unwrap();
                handshake(&mut c, Role::Coordinator, "c", &Secret::insecure()).await.unwrap();
                c.write(&Message::Job(Box::new(job))).await.unwrap();
                let (mut asked, mut snapshots, mut lit) = (0, 0, None);
                loop {
                    match c.read().await.unwrap() {
                        Message::NeedFiles { hashes } => {
                            for h in hashes {
                                asked += 1;
                                for piece in FilePiece::all_of(&h, &store[&h]) {
                                    c.write(&Message::FilePiece(piece)).await.unwrap();
                                }
                            }
                        }
                        Message::Snapshot(snapshot) => {
                            snapshots += 1;
                            c.write(&Message::Ack { seq: snapshot.seq }).await.unwrap();
                            if snapshots == 1 {
                                c.write(&Message::Stop).await.unwrap();
                            }
                        }
                        Message::LitPixels(l) => lit = Some(l.mask(16, 16).unwrap()),
                        Message::Started(_) => assert_eq!(lit.as_ref(), Some(&expected), "the mask, before Started"),
                        Message::Heartbeat => {}
                        Message::Finished => return (asked, snapshots),
                        Message::Failed { reason } => panic!("the worker failed: {reason}"),
                        other => panic!("unexpected {}", other.kind()),
                    }
                }
            });
            let conn = Connection::new(TcpStream::connect(addr).await.unwrap()).unwrap();
            let opts = LinkOptions::new("w".into(), Secret::insecure());
            let outcome = serve_job(conn, &opts, &mut FileCache::for_one_job()).await.expect("a normal end");
            let (asked, snapshots) = coordinator.await.unwrap();
            // Every mesh came from the coordinator, and the worker rendered with them.
            assert_eq!(asked, sent);
            assert!(snapshots >= 1 && outcome.snapshots_sent >= 1, "{snapshots} snapshots");
        });
    }

    #[test]
    fn a_stop_that_arrives_while_the_files_are_being_sent_ends_the_job_normally() {
        let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
        runtime.block_on(async {
            let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
            let addr = listener.local_addr().unwrap();
            let (job, store) = cornell_job();
            // A coordinator whose run ends right after it sent the job: its Stop is on the wire before the
            // files the worker is about to ask for.
            let coordinator = tokio::spawn(async move {
                let (s, _) = listener.accept().await.unwrap();
                let mut c = Connection::new(s).unwrap();
                handshake(&mut c, Role::Coordinator, "c", &Secret::insecure()).await.unwrap();
                c.write(&Message::Job(Box::new(job))).await.unwrap();
                c.write(&Message::Stop).await.unwrap();
                loop {
                    match c.read().await.unwrap() {
                        Message::NeedFiles { hashes } => {
                            for h in hashes {
                                for piece in FilePiece::all_of(&h, &store[&h]) {
                                    c.write(&Message::FilePiece(piece)).await.unwrap();
                                }
                            }
                        }
                        other => return other.kind(),
                    }
                }
            });
            let conn = Connection::new(TcpStream::connect(addr).await.unwrap()).unwrap();
            let opts = LinkOptions::new("w".into(), Secret::insecure());
            let outcome = serve_job(conn, &opts, &mut FileCache::for_one_job()).await.expect("a normal end");
            assert_eq!((outcome.snapshots_sent, outcome.snapshots_acked), (0, 0));
            assert_eq!(coordinator.await.unwrap(), "Finished");
        });
    }

    #[test]
    fn active_tiles_that_do_not_fit_the_image_fail_the_job_with_the_reason() {
        let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
        runtime.block_on(async {
            let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
            let addr = listener.local_addr().unwrap();
            let (mut job, store) = cornell_job();
            (job.scene.camera.width, job.scene.camera.height) = (16, 16);
            job.scene_hash = job.scene.hash();
            let coordinator = tokio::spawn(async move {
                let (s, _) = listener.accept().await.unwrap();
                let mut c = Connection::new(s).unwrap();
                handshake(&mut c, Role::Coordinator, "c", &Secret::insecure()).await.unwrap();
                c.write(&Message::Job(Box::new(job))).await.unwrap();
                // A 16 × 16 image has one 32-pixel tile, not three.
                c.write(&Message::ActiveTiles { tile: 32, flags: vec![true, false, true] }).await.unwrap();
                loop {
                    match c.read().await.unwrap() {
                        Message::NeedFiles { hashes } => {
                            for h in hashes {
                                for piece in FilePiece::all_of(&h, &store[&h]) {
                                    c.write(&Message::FilePiece(piece)).await.unwrap();
                                }
                            }
                        }
                        Message::Failed { reason } => return reason,
                        Message::Started(_) | Message::Heartbeat => {}
                        other => panic!("unexpected {}", other.kind()),
                    }
                }
            });
            let conn = Connection::new(TcpStream::connect(addr).await.unwrap()).unwrap();
            let opts = LinkOptions::new("w".into(), Secret::insecure());
            assert!(serve_job(conn, &opts, &mut FileCache::for_one_job()).await.is_err());
            let reason = coordinator.await.unwrap();
            assert!(reason.contains("active tiles") && reason.contains("3 tile flags"), "{reason}");
        });
    }
}
