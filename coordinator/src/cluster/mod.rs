//! The distributed renderer (paper §5, docs/distribution.md): worker processes, one per NUMA node and any remote ones,
//! render independently; the coordinator merges their snapshots into one set of sums and computes δ over them.
//! It is a `Progressive` like the in-process engines, so the same run loop, outputs and record serve it.

pub mod launch;
pub mod network;
pub mod numa_nodes;

use anyhow::{Context, Result};
use network::{Blocklist, Control, Event, NetworkPlan, Planned};
use photonfarm::accumulation::delta::apply_delta;
use photonfarm::accumulation::{Accumulator, AuxLayout, LitMask};
use photonfarm::protocol::{Share, Snapshot};
use photonfarm::render::record::{WorkerRecord, WorkerState};
use photonfarm::render::session::{Deadline, Progressive};
use photonfarm::render::{ActiveTiles, RayTotals, RenderSettings};
use std::collections::VecDeque;
use std::net::IpAddr;
use std::process::Child;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::mpsc::UnboundedSender;

/// The coordinator's view of one worker: its record (with its state) and the last snapshot merged.
#[derive(Clone, Debug)]
pub struct WorkerView {
    pub record: WorkerRecord,
    last_seq: u64,
    /// The host its link comes from, for the blocklist (None for the workers this coordinator starts).
    ip: Option<IpAddr>,
}

/// A running distributed render.
pub struct Cluster {
    /// The job's scene file name, for the log.
    job: String,
    /// The merged sums, shared with a save reading them on a thread of its own (`shared_sums`); snapshots that
    /// arrive meanwhile wait in `deferred`.
    sums: Arc<Accumulator>,
    /// Events held back while a save reads the sums: the snapshots, and the ends of links that followed one,
    /// in the order they came.
    deferred: VecDeque<Event>,
    /// Totals of earlier sessions (a resumed run).
    base_totals: RayTotals,
    settings: RenderSettings,
    workers: Vec<WorkerView>,
    events: Receiver<Event>,
    control: Option<UnboundedSender<Control>>,
    network: Option<std::thread::JoinHandle<()>>,
    children: Vec<Child>,
    blocklist: Arc<Blocklist>,
    /// New workers may still join (`--listen`).
    accepts_joins: bool,
    /// `collect` ran: the workers were stopped and may exit on their own.
    collected: bool,
    /// The deadline the workers were told.
    announced_deadline: Option<Deadline>,
    /// The worker whose job asks it to decide the lit mask, if any.
    lit_from: Option<usize>,
    /// The lit mask that worker decided, and its seconds, until the run takes it (after the wait for it).
    lit: Option<(LitMask, f64)>,
    started: Instant,
}

/// A worker the cluster starts with.
pub struct Member {
    pub planned: Planned,
    pub name: String,
    pub numa_node: Option<u32>,
    pub cores: Vec<usize>,
}

impl Cluster {
    /// Starts the network thread over `plan` and takes ownership of the local worker processes. `aux` is the
    /// scene's auxiliary layers, which every worker's snapshots carry; `lit_from` the worker whose job asks it
    /// to decide the lit mask, if any.
    #[allow(clippy::too_many_arguments)]
    pub fn start(
        members: Vec<Member>,
        plan: NetworkPlan,
        children: Vec<Child>,
        (width, height): (u32, u32),
        aux: AuxLayout,
        settings: RenderSettings,
        initial: Option<(Accumulator, RayTotals)>,
        lit_from: Option<usize>,
    ) -> Result<Self> {
        let (sums, base_totals) = match initial {
            Some((s, t)) => {
                anyhow::ensure!((s.width, s.height) == (width, height), "the checkpoint is for another image size");
                anyhow::ensure!(
                    *s.aux.layout() == aux,
                    "the checkpoint's auxiliary layers are not the ones this version gives the scene"
                );
                (s, t)
            }
            None => (Accumulator::with_aux(width, height, aux), RayTotals::default()),
        };
        let accepts_joins = plan.public.is_some();
        let job = plan.join_template.scene_name.clone();
        let blocklist = plan.blocklist.clone();
        let (events_tx, events) = std::sync::mpsc::channel();
        let (control_tx, control_rx) = tokio::sync::mpsc::unbounded_channel();
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .context("cannot start the network runtime")?;
        let network = std::thread::Builder::new()
            .name("network".into())
            .spawn(move || runtime.block_on(network::run(plan, events_tx, control_rx)))
            .context("cannot start the network thread")?;
        let workers = members
            .into_iter()
            .map(|m| WorkerView {
                record: WorkerRecord {
                    name: m.name,
                    address: match &m.planned {
                        Planned::Local { .. } => "local".into(),
                        Planned::Remote { address } => address.clone(),
                    },
                    numa_node: m.numa_node,
                    cores: m.cores,
                    state: WorkerState::Connecting,
                    ..WorkerRecord::default()
                },
                last_seq: 0,
                ip: None,
            })
            .collect();
        Ok(Cluster {
            job,
            sums: Arc::new(sums),
            deferred: VecDeque::new(),
            base_totals,
            settings,
            workers,
            events,
            control: Some(control_tx),
            network: Some(network),
            children,
            blocklist,
            accepts_joins,
            collected: false,
            announced_deadline: None,
            lit_from,
            lit: None,
            started: Instant::now(),
        })
    }

    fn send(&self, c: Control) {
        if let Some(tx) = &self.control {
            let _ = tx.send(c);
        }
    }

    fn set_state(&mut self, w: usize, state: WorkerState) {
        let r = &mut self.workers[w].record;
        if r.state.ended() {
            return;
        }
        if let WorkerState::Lost(why) = &state {
            tracing::warn!(job = %self.job, worker = %r.name, "lost ({why}); the run goes on with the others");
        }
        let was_rendering = r.state == WorkerState::Running;
        tracing::debug!(job = %self.job, worker = %r.name, "{state}");
        r.state = state;
        let rendering = r.state == WorkerState::Running;
        if matches!(r.state, WorkerState::Lost(_)) {
            self.count_failure(w);
        }
        if was_rendering != rendering {
            self.announce_share();
        }
    }

    /// Tells every rendering worker how many workers render the image now, its rank among them, and every
    /// pixel's merged phases, so that each numbers its phases as the pixel really receives them (the radius
    /// schedule; docs/distribution.md). Nothing is announced once the run is being collected.
    fn announce_share(&self) {
        if self.collected {
            return;
        }
        let rendering: Vec<usize> =
            (0..self.workers.len()).filter(|&w| self.workers[w].record.state == WorkerState::Running).collect();
        if rendering.is_empty() {
            return;
        }
        let merged_phases = Share::compress_phases(self.sums.pixels.iter().map(|p| p.phases));
        for (rank, &worker) in rendering.iter().enumerate() {
            let share =
                Share { processes: rendering.len() as u32, rank: rank as u32, merged_phases: merged_phases.clone() };
            self.send(Control::Share { worker, share });
        }
    }

    /// Counts a lost link against its host's address, shows the count on every worker from that host, and
    /// says so when the host is refused from now on.
    fn count_failure(&mut self, w: usize) {
        let Some(ip) = self.workers[w].ip else { return };
        let n = self.blocklist.fail(ip);
        for v in self.workers.iter_mut().filter(|v| v.ip == Some(ip)) {
            v.record.failures = n;
        }
        if n == self.blocklist.max() {
            tracing::warn!(
                job = %self.job,
                "workers from {ip} failed {n} times in this job: it is refused for the rest of it \
                 (--max-worker-failures)"
            );
        }
    }

    /// Handles one event, or holds it back while a save reads the sums (then a snapshot is acknowledged at once:
    /// its worker's next interval should not wait for the disk); true when a snapshot was merged.
    fn handle(&mut self, event: Event) -> bool {
        let ordered_after_snapshots =
            matches!(event, Event::Snapshot { .. } | Event::Finished { .. } | Event::Lost { .. });
        let saving = Arc::get_mut(&mut self.sums).is_none();
        if ordered_after_snapshots && (saving || !self.deferred.is_empty()) {
            if let Event::Snapshot { worker, snapshot, .. } = &event {
                self.send(Control::Ack { worker: *worker, seq: snapshot.seq });
            }
            self.deferred.push_back(event);
            return false;
        }
        self.apply(event)
    }

    /// Handles the events held back, once no save reads the sums; true when a snapshot was merged.
    fn catch_up(&mut self) -> bool {
        let mut merged = false;
        while Arc::get_mut(&mut self.sums).is_some() {
            let Some(event) = self.deferred.pop_front() else { break };
            merged |= self.apply(event);
        }
        merged
    }

    /// Handles one event now; true when a snapshot was merged.
    fn apply(&mut self, event: Event) -> bool {
        match event {
            Event::Joined { worker, name, address } => {
                while self.workers.len() <= worker {
                    self.workers.push(WorkerView { record: WorkerRecord::default(), last_seq: 0, ip: None });
                }
                let ip = address.parse::<std::net::SocketAddr>().ok().map(|a| a.ip());
                let v = &mut self.workers[worker];
                v.record.name = name;
                v.record.address = address;
                v.ip = ip;
                v.record.failures = ip.map_or(0, |ip| self.blocklist.failures(ip));
            }
            Event::Connected { worker, address } => {
                let v = &mut self.workers[worker];
                if v.record.address == "local" {
                    v.record.address = address;
                } else if let Ok(a) = address.parse::<std::net::SocketAddr>() {
                    // A `--worker` daemon this coordinator dialled.
                    v.ip = Some(a.ip());
                }
            }
            Event::LitPixels { worker, lit } => {
                if self.lit_from == Some(worker) {
                    match lit.mask(self.sums.width, self.sums.height) {
                        Ok(mask) => self.lit = Some((mask, lit.seconds)),
                        Err(e) => {
                            let reason = format!("sent a lit mask that does not fit the image: {e}");
                            self.send(Control::Drop { worker, reason: reason.clone() });
                            self.set_state(worker, WorkerState::Lost(reason));
                        }
                    }
                }
            }
            Event::Started { worker, info } => {
                let r = &mut self.workers[worker].record;
                r.cores = info.cores;
                r.binding = info.binding;
                r.layout = format!("{} on {}", info.layout, info.hostname);
                if info.numa_node.is_some() {
                    r.numa_node = info.numa_node;
                }
                r.started_after_s = self.started.elapsed().as_secs_f64();
                r.scene_load_s = info.scene_load_s;
                r.bvh_cache = Some(info.bvh_cache);
                self.set_state(worker, WorkerState::Running);
            }
            Event::Snapshot { worker, snapshot, frame_bytes } => {
                let v = &mut self.workers[worker];
                if v.record.state.ended() {
                    return false;
                }
                if snapshot.seq != v.last_seq + 1 {
                    let reason = format!("snapshot {} arrived after {}", snapshot.seq, v.last_seq);
                    self.set_state(worker, WorkerState::Lost(reason));
                    return false;
                }
                let merged = if Snapshot::checksum_of(&snapshot.delta) == snapshot.checksum {
                    let sums = Arc::get_mut(&mut self.sums).expect("snapshots wait while a save reads the sums");
                    apply_delta(&snapshot.delta, sums).map_err(|e| e.to_string())
                } else {
                    Err("its delta does not match its checksum (damaged on the way)".to_string())
                };
                match merged {
                    Ok(summary) => {
                        let v = &mut self.workers[worker];
                        v.last_seq = snapshot.seq;
                        v.record.snapshots += 1;
                        v.record.snapshot_bytes += frame_bytes;
                        v.record.totals = snapshot.totals;
                        v.record.pixel_phases += summary.pixel_phases;
                        v.record.snapshot_interval_s = snapshot.interval_ms as f64 / 1000.0;
                        v.record.last_send_s = snapshot.previous_send_ms as f64 / 1000.0;
                        v.record.peak_memory_bytes =
                            (snapshot.peak_memory_bytes > 0).then_some(snapshot.peak_memory_bytes);
                        v.record.memory_estimate_bytes = Some(snapshot.memory_estimate_bytes);
                        v.record.non_finite_dropped = snapshot.non_finite_dropped;
                        self.send(Control::Ack { worker, seq: snapshot.seq });
                        return true;
                    }
                    Err(e) => {
                        let reason = format!("refused its snapshot: {e}");
                        self.send(Control::Drop { worker, reason: reason.clone() });
                        self.set_state(worker, WorkerState::Lost(reason));
                    }
                }
            }
            Event::Finished { worker } => self.set_state(worker, WorkerState::Finished),
            Event::Lost { worker, reason } => self.set_state(worker, WorkerState::Lost(reason)),
            Event::Refused { address, reason } => {
                tracing::warn!(job = %self.job, "refused a connection from {address}: {reason}");
            }
        }
        false
    }

    fn all_ended(&self) -> bool {
        self.workers.iter().all(|w| w.record.state.ended())
    }

    /// Stops every worker and merges their last snapshots (waiting up to `limit`): after this the image is
    /// complete, and the run's wall time ends here.
    pub fn collect(&mut self, limit: Duration) {
        self.collected = true;
        self.send(Control::StopAll);
        let deadline = Instant::now() + limit;
        while (!self.all_ended() || !self.deferred.is_empty()) && Instant::now() < deadline {
            self.catch_up();
            match self.events.recv_timeout(Duration::from_millis(50)) {
                Ok(e) => {
                    self.handle(e);
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => break,
            }
        }
        for w in 0..self.workers.len() {
            if !self.workers[w].record.state.ended() {
                self.set_state(w, WorkerState::Lost(format!("did not finish within {limit:?} of the stop")));
            }
        }
    }

    /// Ends the network thread and lets the local worker processes exit, after `collect`.
    fn teardown(&mut self) {
        // Give the links a moment to deliver the last acknowledgements, so workers exit knowing their last
        // snapshot was merged; nothing they send now changes the image.
        let settle = Instant::now() + Duration::from_millis(300);
        while Instant::now() < settle {
            if let Ok(e) = self.events.recv_timeout(Duration::from_millis(50)) {
                self.handle(e);
            }
        }
        self.control = None;
        if let Some(n) = self.network.take() {
            let _ = n.join();
        }
        self.reap_children(Duration::from_secs(5));
    }

    fn reap_children(&mut self, limit: Duration) {
        let deadline = Instant::now() + limit;
        for c in &mut self.children {
            loop {
                match c.try_wait() {
                    Ok(Some(_)) => break,
                    Ok(None) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(20)),
                    _ => {
                        let _ = c.kill();
                        let _ = c.wait();
                        break;
                    }
                }
            }
        }
        self.children.clear();
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        if self.collected {
            self.teardown();
        }
        // Never leave worker processes behind, whatever ended the run.
        for c in &mut self.children {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

impl Progressive for Cluster {
    /// Waits for snapshots: returns once one was merged, or at the deadline, on interruption, or when every
    /// worker has ended. The workers are told the deadline, so that they start no phase that would end past it.
    fn step(&mut self, interrupted: &AtomicBool, deadline: Option<Deadline>) {
        if deadline != self.announced_deadline {
            if let Some(d) = deadline {
                self.send(Control::StopAt(d));
            }
            self.announced_deadline = deadline;
        }
        let deadline = deadline.map(|d| d.at);
        loop {
            if interrupted.load(Ordering::Relaxed) || deadline.is_some_and(|d| Instant::now() >= d) {
                return;
            }
            if self.catch_up() || !self.active() {
                return;
            }
            // Wake at the deadline itself: every millisecond past it is a millisecond the workers render for
            // nothing but the final collection.
            let wait = deadline.map_or(Duration::from_millis(50), |d| {
                d.saturating_duration_since(Instant::now()).min(Duration::from_millis(50))
            });
            match self.events.recv_timeout(wait) {
                Ok(e) => {
                    if self.handle(e) {
                        // Drain what else arrived, so one step merges everything that is waiting.
                        while let Ok(e) = self.events.try_recv() {
                            self.handle(e);
                        }
                        return;
                    }
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => return,
            }
        }
    }

    fn sums(&self) -> &Accumulator {
        &self.sums
    }

    fn shared_sums(&self) -> Option<Arc<Accumulator>> {
        Some(self.sums.clone())
    }

    fn totals(&self) -> RayTotals {
        let mut t = self.base_totals;
        for w in &self.workers {
            t += w.record.totals;
        }
        t
    }

    fn settings(&self) -> &RenderSettings {
        &self.settings
    }

    fn bytes_per_pixel(&self) -> f64 {
        // The coordinator's own sums; workers' memory is in their records.
        Accumulator::bytes_per_pixel(self.sums.aux.layout()) as f64
    }

    fn threads(&self) -> usize {
        self.workers.iter().map(|w| w.record.cores.len()).sum()
    }

    fn workers(&self) -> Option<Vec<WorkerRecord>> {
        Some(self.workers.iter().map(|w| w.record.clone()).collect())
    }

    fn active(&self) -> bool {
        self.accepts_joins || !self.all_ended()
    }

    fn finish(&mut self) {
        self.collect(Duration::from_secs(60));
    }

    fn set_active_tiles(&mut self, tiles: &ActiveTiles) {
        self.send(Control::ActiveTiles { tile: tiles.tile, flags: Arc::new(tiles.flags().to_vec()) });
    }

    fn take_lit_mask(&mut self) -> Option<(LitMask, f64)> {
        self.lit.take()
    }

    fn wait_until_rendering(&mut self, interrupted: &AtomicBool) {
        // A coordinator that only listens has no worker to wait for: its clock runs from the start. Otherwise
        // the clock waits for the lit mask too, which every figure over unlit pixels needs from the first step
        // on: another worker may start rendering while the one deciding it is still at it.
        let rendering = |c: &Cluster| {
            c.workers.iter().any(|w| matches!(w.record.state, WorkerState::Running | WorkerState::Finished))
        };
        let lit_settled = |c: &Cluster| {
            c.lit.is_some() || c.lit_from.is_none_or(|w| c.workers.get(w).is_none_or(|v| v.record.state.ended()))
        };
        let ready = |c: &Cluster| c.workers.is_empty() || c.all_ended() || (rendering(c) && lit_settled(c));
        while !ready(self) {
            if interrupted.load(Ordering::Relaxed) {
                return;
            }
            match self.events.recv_timeout(Duration::from_millis(50)) {
                Ok(e) => {
                    self.handle(e);
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => return,
            }
        }
    }
}
