//! The coordinator's network thread: it accepts the workers it started (and any that join), dials remote
//! ones, hands each its job and files, forwards their messages to the main thread as events and sends the
//! main thread's acknowledgements and stop requests back. One tokio task per worker link.

use photonfarm::protocol::auth::{handshake, Peer};
use photonfarm::protocol::tls::Transport;
use photonfarm::protocol::{
    Connection, FilePiece, Job, LitPixels, Message, MessageWriter, ProtocolError, RayMapPortion, Role, Secret, Share,
    Snapshot, WorkerInfo, FILE_PIECE_BYTES,
};
use photonfarm::ray_map::format::PortionHeader;
use photonfarm::ray_map::{Portion, Recorder};
use photonfarm::render::session::Deadline;
use std::collections::BTreeMap;
use std::net::{IpAddr, SocketAddr};
use std::path::PathBuf;
use std::sync::mpsc as std_mpsc;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::mpsc;

/// What the network thread tells the main thread. `worker` indexes the cluster's worker list.
#[derive(Debug)]
pub enum Event {
    /// A worker joined through `--listen` and was given index `worker`.
    Joined {
        worker: usize,
        name: String,
        address: String,
    },
    Connected {
        worker: usize,
        address: String,
    },
    /// The pixels that see a light, as the worker decided them (before its `Started`).
    LitPixels {
        worker: usize,
        lit: LitPixels,
    },
    Started {
        worker: usize,
        info: WorkerInfo,
    },
    Snapshot {
        worker: usize,
        snapshot: Snapshot,
        frame_bytes: u64,
    },
    Finished {
        worker: usize,
    },
    /// The link ended before the worker finished.
    Lost {
        worker: usize,
        reason: String,
    },
    /// A connection was refused before it became a worker (bad secret, version, …).
    Refused {
        address: String,
        reason: String,
    },
}

/// What the main thread asks of the network thread.
#[derive(Debug)]
pub enum Control {
    Ack {
        worker: usize,
        seq: u64,
    },
    StopAll,
    /// End the worker's link, telling it why (its snapshot was refused).
    Drop {
        worker: usize,
        reason: String,
    },
    /// Every worker, and every worker that starts later, renders only these tiles (adaptive tiles).
    ActiveTiles {
        tile: u32,
        flags: Arc<Vec<bool>>,
    },
    /// The worker's share of the image's phases among the workers rendering it now.
    Share {
        worker: usize,
        share: Share,
    },
    /// Every worker, and every worker that starts later, stops at this deadline (a timed run).
    StopAt(Deadline),
}

/// Failures of worker links per host address in this job, as render-farm managers keep them: a host whose
/// workers failed `max` times is refused for the rest of the job, so that a worker that keeps crashing and
/// rejoining stops costing the run a set-up each time.
#[derive(Debug)]
pub struct Blocklist {
    max: u32,
    failures: std::sync::Mutex<BTreeMap<IpAddr, u32>>,
}

impl Blocklist {
    /// A blocklist that refuses an address after `max` failures (at least 1).
    pub fn new(max: u32) -> Self {
        Blocklist { max: max.max(1), failures: Default::default() }
    }

    /// Counts one failure of `ip`; returns its failures so far.
    pub fn fail(&self, ip: IpAddr) -> u32 {
        let mut f = self.failures.lock().unwrap_or_else(|p| p.into_inner());
        let n = f.entry(ip).or_insert(0);
        *n += 1;
        *n
    }

    /// Failures of `ip` so far.
    pub fn failures(&self, ip: IpAddr) -> u32 {
        self.failures.lock().unwrap_or_else(|p| p.into_inner()).get(&ip).copied().unwrap_or(0)
    }

    /// Failures after which an address is refused.
    pub fn max(&self) -> u32 {
        self.max
    }

    /// Why `ip` is refused, if it is.
    pub fn refusal(&self, ip: IpAddr) -> Option<String> {
        let n = self.failures(ip);
        (n >= self.max).then(|| {
            format!(
                "workers from {ip} failed {n} times in this job (--max-worker-failures {}): refused for the rest of it",
                self.max
            )
        })
    }
}

/// Files the job references, by hash, read from disk when a worker asks.
pub type FileStore = BTreeMap<String, PathBuf>;

/// Timing of a link.
#[derive(Clone, Copy, Debug)]
pub struct Timing {
    pub heartbeat: Duration,
    /// A worker is presumed hung when nothing arrived for this long.
    pub peer_timeout: Duration,
}

/// One planned worker the coordinator waits for or dials.
#[derive(Clone, Debug)]
pub enum Planned {
    /// A local worker that will dial the local listener and give this name.
    Local { name: String },
    /// A `worker serve` daemon to dial.
    Remote { address: String },
}

/// Everything the network thread needs.
pub struct NetworkPlan {
    pub planned: Vec<Planned>,
    /// The job of worker i (streams differ).
    pub jobs: Vec<Job>,
    /// A job template for workers that join through `--listen` (its stream is set per joiner).
    pub join_template: Job,
    pub files: Arc<FileStore>,
    /// Listener the local workers dial, with their secret (a non-blocking std listener: the network thread
    /// adopts it).
    pub local: Option<(std::net::TcpListener, Secret)>,
    /// `--listen`, with the user's secret.
    pub public: Option<(std::net::TcpListener, Secret)>,
    /// Secret for `--worker` dials.
    pub remote_secret: Secret,
    /// Plaintext or TLS for `--listen` and `--worker` links (the local workers' links are plaintext loopback).
    pub remote_transport: Transport,
    pub timing: Timing,
    /// Addresses refused after repeated failures (shared with the main thread, which counts them).
    pub blocklist: Arc<Blocklist>,
    /// The run's ray map, which the workers' portions are appended to (`--ray-map`).
    pub ray_map: Option<Arc<Recorder>>,
}

type Links = BTreeMap<usize, mpsc::UnboundedSender<Control>>;

/// Runs the network until the main thread drops its control sender.
pub async fn run(
    mut plan: NetworkPlan,
    events: std_mpsc::Sender<Event>,
    mut control: mpsc::UnboundedReceiver<Control>,
) {
    let job = plan.join_template.scene_name.clone();
    let adopt = |l: Option<(std::net::TcpListener, Secret)>| {
        l.and_then(|(l, s)| match TcpListener::from_std(l) {
            Ok(l) => Some((l, s)),
            Err(e) => {
                tracing::error!(job = %job, "cannot use a listener: {e}");
                None
            }
        })
    };
    let local = adopt(plan.local.take());
    let public = adopt(plan.public.take());
    let plan = Arc::new(plan);
    let (link_tx, mut link_rx) = mpsc::unbounded_channel::<(usize, mpsc::UnboundedSender<Control>)>();
    let mut links: Links = BTreeMap::new();
    let mut stopping = false;
    // The latest active tiles, for workers whose link starts after they were decided.
    let mut tiles: Option<(u32, Arc<Vec<bool>>)> = None;
    // The timed run's deadline, likewise.
    let mut stop_at: Option<Deadline> = None;
    // Shares announced before the worker's link was registered here.
    let mut shares: BTreeMap<usize, Share> = BTreeMap::new();
    // Remote daemons: dial them.
    for (i, p) in plan.planned.iter().enumerate() {
        if let Planned::Remote { address } = p {
            let (plan, events, link_tx, address) = (plan.clone(), events.clone(), link_tx.clone(), address.clone());
            tokio::spawn(async move {
                match dial(&address, &plan.remote_transport, &plan.remote_secret).await {
                    Ok((conn, _peer)) => {
                        let job = plan.jobs[i].clone();
                        drive(i, conn, job, plan, events, link_tx).await
                    }
                    Err(e) => {
                        let _ = events.send(Event::Lost { worker: i, reason: format!("cannot reach {address}: {e}") });
                    }
                }
            });
        }
    }
    if let Some((listener, secret)) = local {
        let (plan2, events, link_tx) = (plan.clone(), events.clone(), link_tx.clone());
        tokio::spawn(async move {
            loop {
                let Ok((stream, addr)) = listener.accept().await else { continue };
                let (plan, events, link_tx, secret) = (plan2.clone(), events.clone(), link_tx.clone(), secret.clone());
                tokio::spawn(async move {
                    let Some((conn, peer)) = accept(stream, addr, &Transport::Plain, &secret, &events).await else {
                        return;
                    };
                    let index =
                        plan.planned.iter().position(|p| matches!(p, Planned::Local { name } if *name == peer.name));
                    match index {
                        Some(i) => {
                            let job = plan.jobs[i].clone();
                            drive(i, conn, job, plan, events, link_tx).await
                        }
                        None => {
                            let _ = events.send(Event::Refused {
                                address: addr.to_string(),
                                reason: format!("no local worker is named '{}'", peer.name),
                            });
                        }
                    }
                });
            }
        });
    }
    if let Some((listener, secret)) = public {
        let (plan2, events, link_tx) = (plan.clone(), events.clone(), link_tx.clone());
        tokio::spawn(async move {
            let mut next = plan2.planned.len();
            loop {
                let Ok((stream, addr)) = listener.accept().await else { continue };
                if !addr.ip().is_loopback() && (secret.is_insecure() || !plan2.remote_transport.is_tls()) {
                    // `--insecure` was given explicitly for this listener; say so once per link.
                    let what = match (secret.is_insecure(), plan2.remote_transport.is_tls()) {
                        (true, false) => "without authentication or encryption",
                        (true, true) => "without authentication",
                        _ => "without encryption",
                    };
                    tracing::warn!(job = %plan2.join_template.scene_name, "accepting {addr} {what} (--insecure)");
                }
                let Some((mut conn, peer)) = accept(stream, addr, &plan2.remote_transport, &secret, &events).await
                else {
                    continue;
                };
                // Checked once the peer has authenticated, so only a worker of the job learns why.
                if let Some(reason) = plan2.blocklist.refusal(addr.ip()) {
                    let _ = conn.write(&Message::Refused { reason: reason.clone() }).await;
                    let _ = events.send(Event::Refused { address: addr.to_string(), reason });
                    continue;
                }
                let worker = next;
                next += 1;
                let _ = events.send(Event::Joined { worker, name: peer.name.clone(), address: addr.to_string() });
                let mut job = plan2.join_template.clone();
                job.stream = (job.stream & !0xffff) | worker as u64;
                let (plan, events, link_tx) = (plan2.clone(), events.clone(), link_tx.clone());
                tokio::spawn(async move { drive(worker, conn, job, plan, events, link_tx).await });
            }
        });
    }
    drop(link_tx);
    loop {
        tokio::select! {
            c = control.recv() => match c {
                Some(Control::Ack { worker, seq }) => {
                    if let Some(l) = links.get(&worker) {
                        let _ = l.send(Control::Ack { worker, seq });
                    }
                }
                Some(Control::StopAll) => {
                    stopping = true;
                    for l in links.values() {
                        let _ = l.send(Control::StopAll);
                    }
                }
                Some(Control::Drop { worker, reason }) => {
                    if let Some(l) = links.get(&worker) {
                        let _ = l.send(Control::Drop { worker, reason });
                    }
                }
                Some(Control::ActiveTiles { tile, flags }) => {
                    for l in links.values() {
                        let _ = l.send(Control::ActiveTiles { tile, flags: flags.clone() });
                    }
                    tiles = Some((tile, flags));
                }
                Some(Control::StopAt(d)) => {
                    for l in links.values() {
                        let _ = l.send(Control::StopAt(d));
                    }
                    stop_at = Some(d);
                }
                Some(Control::Share { worker, share }) => match links.get(&worker) {
                    Some(l) => {
                        let _ = l.send(Control::Share { worker, share });
                    }
                    None => {
                        shares.insert(worker, share);
                    }
                },
                None => return,
            },
            Some((worker, tx)) = link_rx.recv() => {
                if stopping {
                    let _ = tx.send(Control::StopAll);
                } else {
                    if let Some((tile, flags)) = &tiles {
                        let _ = tx.send(Control::ActiveTiles { tile: *tile, flags: flags.clone() });
                    }
                    if let Some(share) = shares.remove(&worker) {
                        let _ = tx.send(Control::Share { worker, share });
                    }
                    if let Some(d) = stop_at {
                        let _ = tx.send(Control::StopAt(d));
                    }
                }
                links.insert(worker, tx);
            }
        }
    }
}

async fn dial(address: &str, transport: &Transport, secret: &Secret) -> Result<(Connection, Peer), ProtocolError> {
    let stream = tokio::time::timeout(Duration::from_secs(10), TcpStream::connect(address))
        .await
        .map_err(|_| ProtocolError::Timeout(Duration::from_secs(10), "the connection"))??;
    let mut conn = transport.connect(stream).await?;
    let peer = handshake(&mut conn, Role::Coordinator, "coordinator", secret).await?;
    Ok((conn, peer))
}

async fn accept(
    stream: TcpStream,
    addr: SocketAddr,
    transport: &Transport,
    secret: &Secret,
    events: &std_mpsc::Sender<Event>,
) -> Option<(Connection, Peer)> {
    let result = async {
        let mut conn = transport.accept(stream).await?;
        let peer = handshake(&mut conn, Role::Coordinator, "coordinator", secret).await?;
        Ok::<_, ProtocolError>((conn, peer))
    }
    .await;
    match result {
        Ok(x) => Some(x),
        Err(e) => {
            let _ = events.send(Event::Refused { address: addr.to_string(), reason: e.to_string() });
            None
        }
    }
}

/// Sends the files a worker asked for; a hash that is not the job's ends the link.
async fn send_files(writer: &mut MessageWriter, hashes: Vec<String>, files: &FileStore) -> Result<(), String> {
    for h in hashes {
        let Some(path) = files.get(&h) else {
            let _ = writer.write(&Message::Refused { reason: format!("no file with hash {h} in this job") }).await;
            return Err(format!("the worker asked for a file that is not the job's ({h})"));
        };
        send_file(writer, &h, path).await?;
    }
    Ok(())
}

/// Streams one file from disk in pieces, so that neither the coordinator nor a frame holds it whole.
async fn send_file(writer: &mut MessageWriter, sha256: &str, path: &std::path::Path) -> Result<(), String> {
    use tokio::io::AsyncReadExt;
    let cannot = |e: std::io::Error| format!("cannot read {}: {e}", path.display());
    let mut file = tokio::fs::File::open(path).await.map_err(cannot)?;
    let size = file.metadata().await.map_err(cannot)?.len();
    let mut offset = 0u64;
    loop {
        let want = (size - offset).min(FILE_PIECE_BYTES as u64) as usize;
        let mut bytes = vec![0u8; want];
        file.read_exact(&mut bytes)
            .await
            .map_err(|e| format!("cannot read {} (did it change while it was being sent?): {e}", path.display()))?;
        let piece = FilePiece { sha256: sha256.to_string(), size, offset, bytes };
        writer.write(&Message::FilePiece(piece)).await.map_err(|e| e.to_string())?;
        offset += want as u64;
        if offset == size {
            return Ok(());
        }
    }
}

/// A worker's ray map portion as its map's stream holds it, or why it cannot be one.
fn received_portion(p: RayMapPortion) -> Result<Portion, String> {
    let compressed = u32::try_from(p.frame.len()).map_err(|_| "a ray map portion beyond 4 GiB".to_string())?;
    let header = PortionHeader { compressed, raw: p.raw_bytes, paths: p.paths, segments: p.segments };
    // The checks a reader makes of a portion's header, so that the map holds none it would refuse.
    PortionHeader::from_bytes(&header.to_bytes()).map_err(|e| format!("the worker sent a bad ray map portion: {e}"))?;
    Ok(Portion { header, frame: p.frame })
}

/// Serves one worker link: job, files, then its messages until it finishes, fails or goes silent.
async fn drive(
    worker: usize,
    conn: Connection,
    job: Job,
    plan: Arc<NetworkPlan>,
    events: std_mpsc::Sender<Event>,
    link_tx: mpsc::UnboundedSender<(usize, mpsc::UnboundedSender<Control>)>,
) {
    let address = conn.peer.to_string();
    let _ = events.send(Event::Connected { worker, address });
    let (control_tx, mut control) = mpsc::unbounded_channel();
    if link_tx.send((worker, control_tx)).is_err() {
        return;
    }
    let timing = plan.timing;
    let (reader, mut writer) = conn.split();
    let result: Result<(), String> = async {
        writer.write(&Message::Job(Box::new(job))).await.map_err(|e| e.to_string())?;
        let (mut incoming, reader_task) = reader.forward();
        let mut last_heard = Instant::now();
        let mut last_sent = Instant::now();
        let mut tick = tokio::time::interval(Duration::from_millis(250));
        let outcome = loop {
            tokio::select! {
                m = incoming.recv() => {
                    last_heard = Instant::now();
                    let Some((m, frame_bytes)) = m else { break Err("the link ended".to_string()) };
                    match m {
                        Ok(Message::NeedFiles { hashes }) => {
                            send_files(&mut writer, hashes, &plan.files).await?;
                            last_sent = Instant::now();
                            // While a large mesh was being sent, the worker's heartbeats waited in the queue
                            // behind it: its silence is counted from now.
                            last_heard = Instant::now();
                        }
                        Ok(Message::LitPixels(lit)) => { let _ = events.send(Event::LitPixels { worker, lit }); }
                        Ok(Message::Started(info)) => { let _ = events.send(Event::Started { worker, info }); }
                        Ok(Message::Snapshot(snapshot)) => { let _ = events.send(Event::Snapshot { worker, snapshot, frame_bytes }); }
                        Ok(Message::RayMapPortion(p)) => {
                            let Some(map) = &plan.ray_map else {
                                break Err("the worker sent a ray map portion, but the run records none".into());
                            };
                            // Queued for the map's writer thread without waiting: a slow disk never holds up the
                            // link (the recorder counts what it has to drop).
                            map.append_portion(received_portion(p)?);
                        }
                        Ok(Message::Finished) => break Ok(()),
                        Ok(Message::Failed { reason }) => break Err(format!("the worker failed: {reason}")),
                        Ok(Message::Heartbeat) => {}
                        Ok(other) => break Err(format!("unexpected {} from the worker", other.kind())),
                        Err(ProtocolError::Closed) => break Err("the worker closed the connection".into()),
                        Err(e) => break Err(e.to_string()),
                    }
                }
                c = control.recv() => {
                    let message = match c {
                        Some(Control::Ack { seq, .. }) => Message::Ack { seq },
                        Some(Control::StopAll) => Message::Stop,
                        Some(Control::ActiveTiles { tile, flags }) => Message::ActiveTiles { tile, flags: flags.to_vec() },
                        Some(Control::Share { share, .. }) => Message::Share(share),
                        // In milliseconds from now: the worker's clock need not agree with this one.
                        Some(Control::StopAt(d)) => Message::StopAt {
                            in_ms: d.at.saturating_duration_since(Instant::now()).as_millis() as u64,
                            slack_ms: d.slack.as_millis() as u64,
                        },
                        Some(Control::Drop { reason, .. }) => {
                            let _ = writer.write(&Message::Refused { reason: reason.clone() }).await;
                            break Err(reason);
                        }
                        None => break Err("the coordinator is shutting down".into()),
                    };
                    writer.write(&message).await.map_err(|e| e.to_string())?;
                    last_sent = Instant::now();
                }
                _ = tick.tick() => {
                    if last_heard.elapsed() > timing.peer_timeout {
                        break Err(format!("no message for {:?}: the worker is presumed hung", timing.peer_timeout));
                    }
                    if last_sent.elapsed() >= timing.heartbeat {
                        writer.write(&Message::Heartbeat).await.map_err(|e| e.to_string())?;
                        last_sent = Instant::now();
                    }
                }
            }
        };
        reader_task.abort();
        outcome
    }
    .await;
    match result {
        Ok(()) => {
            // Acknowledge the last snapshots the main thread merges after `Finished`: they were sent before it.
            let deadline = Instant::now() + Duration::from_secs(5);
            let _ = events.send(Event::Finished { worker });
            while let Ok(Some(c)) =
                tokio::time::timeout(deadline.saturating_duration_since(Instant::now()), control.recv()).await
            {
                if let Control::Ack { seq, .. } = c {
                    if writer.write(&Message::Ack { seq }).await.is_err() {
                        break;
                    }
                }
            }
            let _ = writer.shutdown().await;
        }
        Err(reason) => {
            let _ = events.send(Event::Lost { worker, reason });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use photonfarm::protocol::Connection;

    #[test]
    fn a_file_larger_than_a_piece_is_sent_as_the_pieces_that_carry_it() {
        let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
        runtime.block_on(async {
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("mesh.obj");
            let bytes: Vec<u8> = (0..FILE_PIECE_BYTES + 1000).map(|i| (i % 241) as u8).collect();
            std::fs::write(&path, &bytes).unwrap();
            let (a, b) = tokio::io::duplex(1 << 20);
            let peer: SocketAddr = "127.0.0.1:1".parse().unwrap();
            let (_, mut writer) = Connection::from_stream(a, peer).split();
            let mut reader = Connection::from_stream(b, peer);
            let files: FileStore = [("h".to_string(), path)].into();
            let receiving = tokio::spawn(async move {
                let mut pieces = Vec::new();
                while let Ok(Message::FilePiece(p)) = reader.read().await {
                    pieces.push(p);
                }
                pieces
            });
            send_files(&mut writer, vec!["h".into()], &files).await.unwrap();
            let refused = send_files(&mut writer, vec!["nothing".into()], &files).await;
            assert!(refused.unwrap_err().contains("not the job's"));
            drop(writer);
            let pieces = receiving.await.unwrap();
            assert_eq!(pieces, FilePiece::all_of("h", &bytes));
        });
    }
}
