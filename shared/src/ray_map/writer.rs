//! Recording: render threads hand kept paths to a `Recorder`. Each thread fills portions of its own and
//! compresses each full one itself, so that compression grows with the threads that record; one writer thread
//! per process appends the compressed portions to the map's stream file, or hands them to another sink (a worker
//! process's link to its coordinator), so that no render thread waits on the disk or the network unless the
//! writer falls a whole queue behind.

use super::format::{encode_path, MapHeader, PortionHeader, MAGIC, MAX_VERTICES, VERSION};
use super::path::{PathKind, RecordedPath};
use super::RayMapError;
use std::cell::RefCell;
use std::collections::VecDeque;
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Condvar, Mutex, PoisonError};
use std::thread::JoinHandle;

/// Raw bytes at which a portion is compressed and handed to the writer: small enough that a killed run loses
/// little, large enough for zstd to find the repetition between paths.
pub const PORTION_BYTES: usize = 1 << 20;
/// Compressed bytes that may wait for the writer before a recording thread waits for it (bounding the memory a
/// slow disk or link costs).
const WAITING_BYTES: usize = 8 << 20;
/// Compressed bytes received from other processes (`Recorder::append_portion`) that may wait for the writer
/// before further ones are dropped: only a disk that stalls for long fills it, and the receiver never waits.
const RECEIVED_BYTES: usize = 256 << 20;
/// zstd level: fast enough for a recording thread to compress its own portions at little cost to its rendering.
const ZSTD_LEVEL: i32 = 3;
/// Portions being filled: one per recording thread, up to this many threads (more share them).
const SHARDS: usize = 64;

/// What a finished stream holds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StreamStats {
    pub paths: u64,
    pub segments: u64,
    /// Bytes before compression (path headers and vertices).
    pub raw_bytes: u64,
    /// Bytes of the file (or handed to the sink), headers included.
    pub file_bytes: u64,
    /// Portions received from other processes that were dropped because the writer was too far behind, and the
    /// paths they held.
    pub dropped_portions: u64,
    pub dropped_paths: u64,
}

/// A compressed portion: its header and its zstd frame, as a stream file holds them.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Portion {
    pub header: PortionHeader,
    pub frame: Vec<u8>,
}

/// Where a recorder's writer thread puts the compressed portions, in the order they were finished.
pub trait PortionSink: Send + 'static {
    /// Appends one portion.
    fn append(&mut self, portion: Portion) -> std::io::Result<()>;
    /// Called after the last portion (a file is synced to disk).
    fn finish(&mut self) -> std::io::Result<()> {
        Ok(())
    }
    /// What the sink writes to, for messages: a file's path, a link's peer.
    fn name(&self) -> String;
    /// The stream file it writes, if it writes one.
    fn file(&self) -> Option<&Path> {
        None
    }
    /// Bytes it wrote before any portion (a stream file's header).
    fn header_bytes(&self) -> u64 {
        0
    }
}

/// A stream file of a map folder, its header written.
struct StreamFile {
    file: File,
    path: PathBuf,
    header_bytes: u64,
}

impl StreamFile {
    /// Creates the map folder `dir` if needed and stream `header.stream` in it, with the header written.
    fn create(dir: &Path, header: &MapHeader) -> Result<Self, RayMapError> {
        let path = stream_file(dir, header.stream);
        let io = |source| RayMapError::Io { path: path.display().to_string(), source };
        std::fs::create_dir_all(dir).map_err(|source| RayMapError::Io { path: dir.display().to_string(), source })?;
        let mut file = File::create(&path).map_err(io)?;
        let json = serde_json::to_vec(header).expect("a map header serialises");
        let mut start = Vec::with_capacity(16 + json.len());
        start.extend_from_slice(MAGIC);
        start.extend_from_slice(&VERSION.to_le_bytes());
        start.extend_from_slice(&(json.len() as u32).to_le_bytes());
        start.extend_from_slice(&json);
        file.write_all(&start).map_err(io)?;
        Ok(StreamFile { file, path, header_bytes: start.len() as u64 })
    }
}

impl PortionSink for StreamFile {
    fn append(&mut self, portion: Portion) -> std::io::Result<()> {
        self.file.write_all(&portion.header.to_bytes())?;
        self.file.write_all(&portion.frame)
    }

    fn finish(&mut self) -> std::io::Result<()> {
        self.file.sync_all()
    }

    fn name(&self) -> String {
        self.path.display().to_string()
    }

    fn file(&self) -> Option<&Path> {
        Some(&self.path)
    }

    fn header_bytes(&self) -> u64 {
        self.header_bytes
    }
}

/// A portion being filled.
#[derive(Default)]
struct Filling {
    raw: Vec<u8>,
    paths: u32,
    segments: u32,
}

/// One thread's filling, on a cache line of its own so that threads recording at once do not share one.
#[repr(align(128))]
#[derive(Default)]
struct Shard(Mutex<Filling>);

/// The compressed portions waiting for the writer, counted in bytes.
#[derive(Default)]
struct Queue {
    state: Mutex<QueueState>,
    /// Signalled when a portion arrives or the queue closes.
    ready: Condvar,
    /// Signalled when the writer takes a portion.
    room: Condvar,
}

#[derive(Default)]
struct QueueState {
    portions: VecDeque<Portion>,
    bytes: usize,
    closed: bool,
}

impl Queue {
    fn lock(&self) -> std::sync::MutexGuard<'_, QueueState> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Adds `portion` once fewer than `WAITING_BYTES` wait (at once when none waits); false once closed.
    fn push_waiting(&self, portion: Portion) -> bool {
        let mut s = self.lock();
        while !s.closed && s.bytes > 0 && s.bytes + portion.frame.len() > WAITING_BYTES {
            s = self.room.wait(s).unwrap_or_else(PoisonError::into_inner);
        }
        self.push(s, portion)
    }

    /// Adds `portion` unless `limit` bytes would then wait, or the queue is closed: then gives it back.
    fn try_push(&self, portion: Portion, limit: usize) -> Result<(), Portion> {
        let s = self.lock();
        if s.closed || (s.bytes > 0 && s.bytes + portion.frame.len() > limit) {
            return Err(portion);
        }
        self.push(s, portion);
        Ok(())
    }

    fn push(&self, mut s: std::sync::MutexGuard<'_, QueueState>, portion: Portion) -> bool {
        if s.closed {
            return false;
        }
        s.bytes += portion.frame.len();
        s.portions.push_back(portion);
        self.ready.notify_one();
        true
    }

    /// The next portion, waiting for one; None once the queue is closed and empty.
    fn pop(&self) -> Option<Portion> {
        let mut s = self.lock();
        loop {
            if let Some(p) = s.portions.pop_front() {
                s.bytes -= p.frame.len();
                self.room.notify_all();
                return Some(p);
            }
            if s.closed {
                return None;
            }
            s = self.ready.wait(s).unwrap_or_else(PoisonError::into_inner);
        }
    }

    fn close(&self) {
        self.lock().closed = true;
        self.ready.notify_all();
        self.room.notify_all();
    }
}

/// Records a deterministic fraction of a render's paths into one stream of a map.
pub struct Recorder {
    threshold: u64,
    seed: u64,
    shards: Box<[Shard]>,
    queue: std::sync::Arc<Queue>,
    writer: Mutex<Option<JoinHandle<Result<StreamStats, RayMapError>>>>,
    /// What the sink writes to, and its stream file if it has one.
    name: String,
    file: Option<PathBuf>,
    /// The first error a recording thread met compressing a portion (the portion is lost with it).
    compression_error: Mutex<Option<RayMapError>>,
    dropped_portions: AtomicU64,
    dropped_paths: AtomicU64,
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder").field("sink", &self.name).field("threshold", &self.threshold).finish()
    }
}

/// The stream file of stream `n` in a map folder.
pub fn stream_file(dir: &Path, n: u32) -> PathBuf {
    dir.join(format!("stream-{n}.pfrm"))
}

thread_local! {
    /// This thread's shard, assigned when it first records: threads of a process get distinct shards.
    static SHARD: usize = {
        static NEXT: AtomicUsize = AtomicUsize::new(0);
        NEXT.fetch_add(1, Ordering::Relaxed) % SHARDS
    };
    /// This thread's zstd context, made once and reused from portion to portion.
    static COMPRESSOR: RefCell<Option<zstd::bulk::Compressor<'static>>> = const { RefCell::new(None) };
}

/// Compresses a filled portion with this thread's zstd context (with a content checksum).
fn compress(filling: &Filling) -> std::io::Result<Portion> {
    COMPRESSOR.with(|c| {
        let mut c = c.borrow_mut();
        let compressor = match &mut *c {
            Some(compressor) => compressor,
            None => {
                let mut compressor = zstd::bulk::Compressor::new(ZSTD_LEVEL)?;
                compressor.include_checksum(true)?;
                c.insert(compressor)
            }
        };
        let frame = compressor.compress(&filling.raw)?;
        let header = PortionHeader {
            compressed: frame.len() as u32,
            raw: filling.raw.len() as u32,
            paths: filling.paths,
            segments: filling.segments,
        };
        Ok(Portion { header, frame })
    })
}

impl Recorder {
    /// Creates the map folder `dir` if needed and stream `header.stream` in it, and starts its writer.
    pub fn create(dir: &Path, header: &MapHeader) -> Result<Self, RayMapError> {
        check(header)?;
        Self::with_sink(Box::new(StreamFile::create(dir, header)?), header)
    }

    /// A recorder of the paths `header`'s seed and fraction keep, whose writer hands the portions to `sink`
    /// (which writes the map's header itself, if it needs one).
    pub fn with_sink(mut sink: Box<dyn PortionSink>, header: &MapHeader) -> Result<Self, RayMapError> {
        check(header)?;
        let (name, file) = (sink.name(), sink.file().map(Path::to_path_buf));
        let queue = std::sync::Arc::new(Queue::default());
        let writer = {
            let (queue, writer_name) = (queue.clone(), name.clone());
            std::thread::Builder::new()
                .name("ray-map-writer".into())
                .spawn(move || {
                    let io = |source| RayMapError::Io { path: writer_name.clone(), source };
                    let mut stats = StreamStats { file_bytes: sink.header_bytes(), ..Default::default() };
                    let mut failed = None;
                    while let Some(portion) = queue.pop() {
                        // After a failure the writer still takes every portion, so that no recording thread
                        // waits for a writer that will not write; the error waits for `finish`.
                        if failed.is_some() {
                            continue;
                        }
                        let h = portion.header;
                        match sink.append(portion) {
                            Ok(()) => {
                                stats.paths += h.paths as u64;
                                stats.segments += h.segments as u64;
                                stats.raw_bytes += h.raw as u64;
                                stats.file_bytes += (h.to_bytes().len() + h.compressed as usize) as u64;
                            }
                            Err(e) => failed = Some(io(e)),
                        }
                    }
                    if let Some(e) = failed {
                        return Err(e);
                    }
                    sink.finish().map_err(io)?;
                    Ok(stats)
                })
                .map_err(|source| RayMapError::Io { path: name.clone(), source })?
        };
        let threshold = if header.fraction >= 1.0 { u64::MAX } else { (header.fraction * 2f64.powi(64)) as u64 };
        Ok(Recorder {
            threshold,
            seed: header.seed,
            shards: (0..SHARDS).map(|_| Shard::default()).collect(),
            queue,
            writer: Mutex::new(Some(writer)),
            name,
            file,
            compression_error: Mutex::new(None),
            dropped_portions: AtomicU64::new(0),
            dropped_paths: AtomicU64::new(0),
        })
    }

    /// True when the path number `item` of `kind` in `phase` is one of the recorded fraction: a hash of the
    /// seed and the path's numbers, so that the same run records the same paths on any number of threads.
    #[inline]
    pub fn keeps(&self, kind: PathKind, phase: u64, item: u64) -> bool {
        self.threshold == u64::MAX || mix(mix(mix(self.seed ^ (kind as u64) << 63) ^ phase) ^ item) < self.threshold
    }

    /// Adds a finished path to the calling thread's portion; a full portion is compressed on this thread and
    /// goes to the writer.
    pub fn record(&self, path: &RecordedPath) {
        if path.vertices.is_empty() {
            return;
        }
        let shard = &self.shards[SHARD.with(|s| *s)];
        let full = {
            let mut f = shard.0.lock().unwrap_or_else(PoisonError::into_inner);
            encode_path(path, &mut f.raw);
            f.paths += 1;
            f.segments += (path.vertices.len().min(MAX_VERTICES) - 1) as u32;
            (f.raw.len() >= PORTION_BYTES).then(|| std::mem::take(&mut *f))
        };
        if let Some(filling) = full {
            self.send(filling);
        }
    }

    /// Compresses a portion on the calling thread and queues it for the writer.
    fn send(&self, filling: Filling) {
        match compress(&filling) {
            // A closed queue means `finish` ran: a path recorded after it is not part of the map.
            Ok(portion) => {
                self.queue.push_waiting(portion);
            }
            Err(source) => {
                let mut e = self.compression_error.lock().unwrap_or_else(PoisonError::into_inner);
                e.get_or_insert(RayMapError::Io { path: self.name.clone(), source });
            }
        }
    }

    /// Queues a portion compressed by another process (a worker's, received by its coordinator) for the writer,
    /// without waiting: when the writer is far behind (a stalled disk) the portion is dropped and counted in the
    /// stats instead, so that the caller never blocks. False when it was dropped.
    pub fn append_portion(&self, portion: Portion) -> bool {
        let paths = portion.header.paths as u64;
        match self.queue.try_push(portion, RECEIVED_BYTES) {
            Ok(()) => true,
            Err(_) => {
                self.dropped_portions.fetch_add(1, Ordering::Relaxed);
                self.dropped_paths.fetch_add(paths, Ordering::Relaxed);
                false
            }
        }
    }

    /// Compresses and queues every thread's last portion, waits for the writer and returns what the stream
    /// holds, or the first error met.
    pub fn finish(&self) -> Result<StreamStats, RayMapError> {
        for shard in self.shards.iter() {
            let last = std::mem::take(&mut *shard.0.lock().unwrap_or_else(PoisonError::into_inner));
            if last.paths > 0 {
                self.send(last);
            }
        }
        self.queue.close();
        let handle = self.writer.lock().unwrap_or_else(PoisonError::into_inner).take();
        let mut stats = match handle {
            Some(h) => h.join().unwrap_or_else(|_| Err(RayMapError::WriterPanicked(self.name.clone())))?,
            None => return Err(RayMapError::Finished(self.name.clone())),
        };
        if let Some(e) = self.compression_error.lock().unwrap_or_else(PoisonError::into_inner).take() {
            return Err(e);
        }
        stats.dropped_portions = self.dropped_portions.load(Ordering::Relaxed);
        stats.dropped_paths = self.dropped_paths.load(Ordering::Relaxed);
        Ok(stats)
    }

    /// The stream file, for a recorder that writes one.
    pub fn path(&self) -> Option<&Path> {
        self.file.as_deref()
    }
}

impl Drop for Recorder {
    /// A recorder dropped without `finish` (a run that failed) lets its writer end: the portions still being
    /// filled are lost with it.
    fn drop(&mut self) {
        self.queue.close();
    }
}

/// Refuses a header the map cannot record under.
fn check(header: &MapHeader) -> Result<(), RayMapError> {
    if !(header.fraction > 0.0 && header.fraction <= 1.0) {
        return Err(RayMapError::Fraction(header.fraction));
    }
    if header.objects.len() >= super::path::NO_OBJECT as usize {
        return Err(RayMapError::TooManyObjects(header.objects.len()));
    }
    Ok(())
}

/// SplitMix64's finaliser: a well-mixed 64-bit hash step.
#[inline]
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn portion(bytes: usize) -> Portion {
        Portion {
            header: PortionHeader { compressed: bytes as u32, raw: 0, paths: 1, segments: 0 },
            frame: vec![0; bytes],
        }
    }

    #[test]
    fn a_full_queue_refuses_received_portions_and_a_closed_one_takes_none() {
        let q = Queue::default();
        // The first portion is taken whatever its size, so that one larger than the limit cannot block forever.
        assert!(q.try_push(portion(300), 100).is_ok());
        assert!(q.try_push(portion(1), 100).is_err());
        assert_eq!(q.pop().map(|p| p.frame.len()), Some(300));
        assert!(q.try_push(portion(60), 100).is_ok() && q.try_push(portion(40), 100).is_ok());
        assert!(q.try_push(portion(1), 100).is_err());
        q.close();
        assert!(!q.push_waiting(portion(1)));
        assert_eq!([q.pop(), q.pop()].map(|p| p.map(|p| p.frame.len())), [Some(60), Some(40)]);
        assert!(q.pop().is_none());
    }

    #[test]
    fn a_recording_thread_waits_for_room_and_goes_on_once_the_writer_takes_a_portion() {
        let q = std::sync::Arc::new(Queue::default());
        assert!(q.push_waiting(portion(WAITING_BYTES)));
        let pushed = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let t = {
            let (q, pushed) = (q.clone(), pushed.clone());
            std::thread::spawn(move || {
                q.push_waiting(portion(10));
                pushed.store(true, Ordering::SeqCst);
            })
        };
        std::thread::sleep(std::time::Duration::from_millis(50));
        assert!(!pushed.load(Ordering::SeqCst), "the second portion did not wait");
        assert!(q.pop().is_some());
        t.join().unwrap();
        assert!(pushed.load(Ordering::SeqCst));
    }
}
