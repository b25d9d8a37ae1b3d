//! Recording: the render threads hand kept paths to a `Recorder`, which encodes them into portions; a
//! background thread compresses each full portion and appends it to the stream file, so that the render
//! threads never wait on zstd or the disk unless the writer falls a whole queue behind.

use super::format::{encode_path, MapHeader, PortionHeader, MAGIC, MAX_VERTICES, VERSION};
use super::path::{PathKind, RecordedPath};
use super::RayMapError;
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{sync_channel, SyncSender};
use std::sync::Mutex;
use std::thread::JoinHandle;

/// Raw bytes at which a portion is handed to the writer: small enough that a killed run loses little,
/// large enough for zstd to find the repetition between paths.
pub const PORTION_BYTES: usize = 1 << 20;
/// Portions that may wait for the writer before recording blocks (bounding the memory a slow disk costs).
const QUEUE: usize = 4;
/// zstd level: fast enough for one thread to keep up with recording every path of a two-core render.
const ZSTD_LEVEL: i32 = 3;

/// What a finished stream holds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StreamStats {
    pub paths: u64,
    pub segments: u64,
    /// Bytes before compression (path headers and vertices).
    pub raw_bytes: u64,
    /// Bytes of the file.
    pub file_bytes: u64,
}

/// A portion being filled.
#[derive(Default)]
struct Filling {
    raw: Vec<u8>,
    paths: u32,
    segments: u32,
}

/// Records a deterministic fraction of a render's paths into one stream file.
pub struct Recorder {
    threshold: u64,
    seed: u64,
    filling: Mutex<Filling>,
    sender: Mutex<Option<SyncSender<Filling>>>,
    writer: Mutex<Option<JoinHandle<Result<StreamStats, RayMapError>>>>,
    path: PathBuf,
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder").field("path", &self.path).field("threshold", &self.threshold).finish()
    }
}

/// The stream file of stream `n` in a map folder.
pub fn stream_file(dir: &Path, n: u32) -> PathBuf {
    dir.join(format!("stream-{n}.pfrm"))
}

impl Recorder {
    /// Creates the map folder `dir` if needed and stream `header.stream` in it, and starts its writer.
    pub fn create(dir: &Path, header: &MapHeader) -> Result<Self, RayMapError> {
        if !(header.fraction > 0.0 && header.fraction <= 1.0) {
            return Err(RayMapError::Fraction(header.fraction));
        }
        if header.objects.len() >= super::path::NO_OBJECT as usize {
            return Err(RayMapError::TooManyObjects(header.objects.len()));
        }
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
        let (sender, receiver) = sync_channel::<Filling>(QUEUE);
        let file_path = path.clone();
        let header_bytes = start.len() as u64;
        let writer = std::thread::Builder::new()
            .name("ray-map-writer".into())
            .spawn(move || {
                let io = |source| RayMapError::Io { path: file_path.display().to_string(), source };
                let mut stats = StreamStats { file_bytes: header_bytes, ..Default::default() };
                let mut compressor = zstd::bulk::Compressor::new(ZSTD_LEVEL).map_err(io)?;
                compressor.include_checksum(true).map_err(io)?;
                for portion in receiver {
                    let frame = compressor.compress(&portion.raw).map_err(io)?;
                    let header = PortionHeader {
                        compressed: frame.len() as u32,
                        raw: portion.raw.len() as u32,
                        paths: portion.paths,
                        segments: portion.segments,
                    };
                    file.write_all(&header.to_bytes()).map_err(io)?;
                    file.write_all(&frame).map_err(io)?;
                    stats.paths += portion.paths as u64;
                    stats.segments += portion.segments as u64;
                    stats.raw_bytes += portion.raw.len() as u64;
                    stats.file_bytes += (header.to_bytes().len() + frame.len()) as u64;
                }
                file.sync_all().map_err(io)?;
                Ok(stats)
            })
            .map_err(io)?;
        let threshold = if header.fraction >= 1.0 { u64::MAX } else { (header.fraction * 2f64.powi(64)) as u64 };
        Ok(Recorder {
            threshold,
            seed: header.seed,
            filling: Mutex::new(Filling::default()),
            sender: Mutex::new(Some(sender)),
            writer: Mutex::new(Some(writer)),
            path,
        })
    }

    /// True when the path number `item` of `kind` in `phase` is one of the recorded fraction: a hash of the
    /// seed and the path's numbers, so that the same run records the same paths on any number of threads.
    #[inline]
    pub fn keeps(&self, kind: PathKind, phase: u64, item: u64) -> bool {
        self.threshold == u64::MAX || mix(mix(mix(self.seed ^ (kind as u64) << 63) ^ phase) ^ item) < self.threshold
    }

    /// Adds a finished path to the stream; a full portion goes to the writer.
    pub fn record(&self, path: &RecordedPath) {
        if path.vertices.is_empty() {
            return;
        }
        let full = {
            let mut f = self.filling.lock().unwrap_or_else(|e| e.into_inner());
            encode_path(path, &mut f.raw);
            f.paths += 1;
            f.segments += (path.vertices.len().min(MAX_VERTICES) - 1) as u32;
            (f.raw.len() >= PORTION_BYTES).then(|| std::mem::take(&mut *f))
        };
        if let Some(portion) = full {
            self.send(portion);
        }
    }

    fn send(&self, portion: Filling) {
        let sender = self.sender.lock().unwrap_or_else(|e| e.into_inner());
        // A writer that stopped has its error waiting for `finish`; the portion is lost with it.
        if let Some(s) = sender.as_ref() {
            let _ = s.send(portion);
        }
    }

    /// Writes the last portion, waits for the writer and returns what the stream holds, or the writer's error.
    pub fn finish(&self) -> Result<StreamStats, RayMapError> {
        let last = std::mem::take(&mut *self.filling.lock().unwrap_or_else(|e| e.into_inner()));
        if last.paths > 0 {
            self.send(last);
        }
        drop(self.sender.lock().unwrap_or_else(|e| e.into_inner()).take());
        let handle = self.writer.lock().unwrap_or_else(|e| e.into_inner()).take();
        match handle {
            Some(h) => h.join().unwrap_or_else(|_| Err(RayMapError::WriterPanicked(self.path.display().to_string()))),
            None => Err(RayMapError::Finished(self.path.display().to_string())),
        }
    }

    /// The stream file.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// SplitMix64's finaliser: a well-mixed 64-bit hash step.
#[inline]
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}
