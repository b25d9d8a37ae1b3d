//! Every message of the protocol, as one enum, and its binary encoding (bincode 2 behind this one module, so a
//! change of codec touches one file).

use super::error::ProtocolError;
use crate::accumulation::LitMask;
use crate::geometry::BvhCacheUse;
use crate::render::method::ParallelMethod;
use crate::render::settings::RenderSettings;
use crate::render::totals::RayTotals;
use crate::scene::description::SceneDescription;
use serde::{Deserialize, Serialize};

/// Bumped whenever a message changes shape; peers with another version are refused in the handshake.
/// 5: the totals count the light paths counted against photon maps. 6: snapshots carry the replicate sums.
/// 7: the coordinator may restrict workers to the tiles still above the target error (`ActiveTiles`).
/// 8: jobs say whether the worker chooses its light paths per pixel (`RenderSettings::adaptive_light`).
/// 9: and whether it chooses the camera paths' diffuse depth (`RenderSettings::adaptive_depth`).
/// 10: the coordinator announces the processes rendering the image when they change (`Share`), jobs carry
/// `--memory-limit`, and snapshots a CRC-32 of their delta.
/// 11: jobs may ask for a ray map (`Job::ray_map`), whose portions workers send (`RayMapPortion`).
/// 12: the coordinator tells the workers when a timed run stops (`StopAt`), and jobs carry a Mitsuba scene's
/// import options (`Job::mitsuba`).
/// 13: jobs carry the scene's description (`Job::scene`) instead of its file's text and import options.
/// 14: a snapshot's delta holds only the pixels rendered since the previous one (`delta::SPARSE_MAGIC`).
/// 16: files travel in pieces (`FilePiece`), so that a mesh larger than a frame can be sent.
/// 17: a worker says how long it took to build the scene (`WorkerInfo::scene_load_s`).
/// 18: a job may ask its worker to decide the lit mask (`Job::decide_lit_mask`), which it sends (`LitPixels`).
/// 19: a worker says what the BVH cache did for its scene (`WorkerInfo::bvh_cache`).
pub const PROTOCOL_VERSION: u32 = 19;

/// The most bytes of a file one `FilePiece` carries: far below the frame limit, and small enough that neither
/// end holds a second copy of a large mesh while it is sent.
pub const FILE_PIECE_BYTES: usize = 16 << 20;
const _: () = assert!(FILE_PIECE_BYTES + 4096 <= super::frame::DEFAULT_MAX_FRAME as usize);

/// Which end of a link a peer is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Role {
    Coordinator,
    Worker,
}

/// A file the scene references, by its path relative to the scene file and its content hash (SHA-256,
/// lower-case hex).
pub use crate::scene::description::FileRef;

/// How a worker lays out its threads.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EngineSpec {
    pub method: ParallelMethod,
    /// Threads per group for two-level.
    pub group_size: usize,
    /// Tile edge in pixels (None: the engine's default for its group count).
    pub tile_size: Option<u32>,
    pub phases_per_deal: Option<u32>,
    /// Cores to run on (None: every core the worker's machine has).
    pub cores: Option<Vec<usize>>,
    /// The NUMA node these cores belong to, when the coordinator chose them.
    pub numa_node: Option<u32>,
    /// The node's cores are a synthetic topology's, mapped onto real cores modulo their count.
    pub synthetic_topology: bool,
    /// Worker processes planned to render the image, and this one's index: the radius schedule of a pixel
    /// counts every process's phases, assuming they progress alike, until the coordinator announces the
    /// processes that really render (`Message::Share`; docs/distribution.md, "Radius schedule across
    /// processes").
    pub processes_per_pixel: u32,
    pub process_rank: u32,
    /// Phases the image already has from earlier sessions (a resumed run), added to the radius schedule's j.
    pub resumed_phases: u32,
    /// `--memory-limit`: the bytes this worker process may use, checked before its engine allocates.
    pub memory_limit: Option<u64>,
}

/// What a worker renders.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Job {
    /// The scene file's name, for messages.
    pub scene_name: String,
    /// The scene as the coordinator read it, whichever its format: the worker builds it with the files below.
    pub scene: SceneDescription,
    /// The files the scene references (`SceneDescription::files`); the worker asks for the ones it does not hold.
    pub files: Vec<FileRef>,
    /// The description's hash as the coordinator computed it; the worker checks the description against it.
    pub scene_hash: String,
    pub settings: RenderSettings,
    /// This worker's random stream: distinct for every worker of a job.
    pub stream: u64,
    pub engine: EngineSpec,
    /// Time between snapshots, in milliseconds.
    pub snapshot_interval_ms: u64,
    /// Record a ray map (`render --ray-map`) and send its portions to the coordinator.
    pub ray_map: Option<RayMapRequest>,
    /// Decide which pixels see a light once the scene is built, and send them (`Message::LitPixels`) before
    /// `Started`: the coordinator, which builds no BVH, asks this of its first planned worker.
    pub decide_lit_mask: bool,
}

/// Worker → coordinator: the lit mask it decided (`accumulation::LitMask`), one bit per pixel
/// (`LitMask::to_bits`), and the seconds deciding it took.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LitPixels {
    pub width: u32,
    pub height: u32,
    pub samples_per_pixel: u32,
    pub bits: Vec<u8>,
    pub seconds: f64,
}

impl LitPixels {
    /// The message carrying `mask`, which took `seconds` to decide.
    pub fn of(mask: &LitMask, seconds: f64) -> Self {
        LitPixels {
            width: mask.width,
            height: mask.height,
            samples_per_pixel: mask.samples_per_pixel,
            bits: mask.to_bits(),
            seconds,
        }
    }

    /// The mask, refused unless it is one bit per pixel of a `width` × `height` image.
    pub fn mask(&self, width: u32, height: u32) -> Result<LitMask, ProtocolError> {
        if (self.width, self.height) != (width, height) {
            return Err(ProtocolError::Malformed(format!(
                "a lit mask of {} × {} pixels for an image of {width} × {height}",
                self.width, self.height
            )));
        }
        LitMask::from_bits(width, height, &self.bits, self.samples_per_pixel)
            .ok_or_else(|| ProtocolError::Malformed("the lit mask is not one bit per pixel".into()))
    }
}

/// What a job's ray map records.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RayMapRequest {
    /// The fraction of paths recorded, in (0, 1].
    pub fraction: f64,
}

/// One compressed portion of a worker's ray map, as the map's stream file holds it after its portion header
/// (docs/ray-maps.md describes the format): the coordinator appends it to the run's map.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RayMapPortion {
    /// Bytes of the paths before compression.
    pub raw_bytes: u32,
    pub paths: u32,
    pub segments: u32,
    /// One zstd frame with a content checksum.
    pub frame: Vec<u8>,
}

/// Coordinator → worker: bytes `offset..offset + bytes.len()` of a file of `size` bytes. A file's pieces come in
/// order and without gaps; an empty file is one empty piece.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FilePiece {
    /// The whole file's SHA-256 (lower-case hex), as the job names it.
    pub sha256: String,
    pub size: u64,
    pub offset: u64,
    pub bytes: Vec<u8>,
}

impl FilePiece {
    /// The pieces that carry `bytes` whole (one empty piece for an empty file).
    pub fn all_of(sha256: &str, bytes: &[u8]) -> Vec<FilePiece> {
        let size = bytes.len() as u64;
        let piece = |offset: usize, chunk: &[u8]| FilePiece {
            sha256: sha256.to_string(),
            size,
            offset: offset as u64,
            bytes: chunk.to_vec(),
        };
        if bytes.is_empty() {
            return vec![piece(0, &[])];
        }
        bytes.chunks(FILE_PIECE_BYTES).enumerate().map(|(i, c)| piece(i * FILE_PIECE_BYTES, c)).collect()
    }
}

/// What a worker reports once its engine runs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WorkerInfo {
    pub hostname: String,
    pub threads: usize,
    pub cores: Vec<usize>,
    pub numa_node: Option<u32>,
    /// What pinning the OS granted, in words (e.g. "2 of 2 threads pinned to cores 0,1").
    pub binding: String,
    /// e.g. "2 groups × 1 thread, tile masks, shared maps".
    pub layout: String,
    /// Seconds the worker took to build the scene from the files received (meshes read, their BVH built).
    pub scene_load_s: f64,
    /// What the BVH cache did for the worker's scene.
    pub bvh_cache: BvhCacheUse,
}

/// Phases a worker completed since its previous snapshot.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Snapshot {
    /// 1, 2, 3, … per worker and job: the coordinator applies each exactly once, in order.
    pub seq: u64,
    /// The worker's counters since its start (cumulative, so a lost snapshot cannot skew them).
    pub totals: RayTotals,
    /// Per-pixel sums added since the previous snapshot, over the pixels that changed (see
    /// `accumulation::delta`).
    pub delta: Vec<u8>,
    /// CRC-32 of `delta`: a delta damaged on its way (a plaintext link has only TCP's 16-bit checksum) is refused
    /// rather than merged.
    pub checksum: u32,
    /// The snapshot interval the worker uses now, and how long sending its previous snapshot took, from the
    /// start of the write to the acknowledgement (ms).
    pub interval_ms: u64,
    pub previous_send_ms: u64,
    /// The worker process's peak resident memory so far (bytes; 0 where the OS does not say).
    pub peak_memory_bytes: u64,
    /// Its estimate of that peak, made before its engine allocated (bytes).
    pub memory_estimate_bytes: u64,
    /// Phase values with a NaN or an infinity the worker has dropped so far.
    pub non_finite_dropped: u64,
}

/// Coordinator → worker: which processes render the image from now on, sent to every rendering worker when one
/// starts or is lost, so that each counts a pixel's phases over all of them (`pbpm::ProcessShare`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Share {
    /// Workers rendering the image, and this one's rank among them.
    pub processes: u32,
    pub rank: u32,
    /// Each pixel's phases merged at the coordinator (every worker's, lost ones' and earlier sessions'
    /// included), row-major, as little-endian u32 compressed with zstd.
    pub merged_phases: Vec<u8>,
}

impl Share {
    /// Compresses the merged phases of every pixel, for `Share`s that differ only in their rank.
    pub fn compress_phases(phases: impl Iterator<Item = u32>) -> Vec<u8> {
        let raw: Vec<u8> = phases.flat_map(u32::to_le_bytes).collect();
        zstd::bulk::compress(&raw, 1).expect("zstd compression of an in-memory buffer cannot fail")
    }

    /// The merged phases of an image of `pixels` pixels; refused if they are not exactly that many.
    pub fn merged_phases(&self, pixels: usize) -> Result<Vec<u32>, ProtocolError> {
        let raw = zstd::bulk::decompress(&self.merged_phases, pixels * 4)
            .map_err(|e| ProtocolError::Malformed(format!("the announced phases do not decompress: {e}")))?;
        if raw.len() != pixels * 4 {
            return Err(ProtocolError::Malformed(format!(
                "the announced phases cover {} pixels, the image has {pixels}",
                raw.len() / 4
            )));
        }
        Ok(raw.chunks_exact(4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect())
    }
}

/// The protocol's messages.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Message {
    /// Each side's first message.
    Hello { version: u32, role: Role, nonce: [u8; 32], name: String },
    /// Proof of the shared secret over the handshake (see `auth`).
    Proof { mac: [u8; 32] },
    /// The handshake or the job was refused, with the reason.
    Refused { reason: String },
    /// Coordinator → worker: the job.
    Job(Box<Job>),
    /// Worker → coordinator: hashes of the files it needs.
    NeedFiles { hashes: Vec<String> },
    /// Coordinator → worker: a piece of a file it asked for.
    FilePiece(FilePiece),
    /// Worker → coordinator: which pixels see a light, when the job asks (`Job::decide_lit_mask`).
    LitPixels(LitPixels),
    /// Worker → coordinator: the engine runs.
    Started(WorkerInfo),
    /// Worker → coordinator: completed phases.
    Snapshot(Snapshot),
    /// Coordinator → worker: snapshot `seq` is merged.
    Ack { seq: u64 },
    /// Either way, when nothing else was sent for a while.
    Heartbeat,
    /// Coordinator → worker: finish the current round, send a last snapshot, then `Finished`.
    Stop,
    /// Worker → coordinator: the last snapshot was sent.
    Finished,
    /// Worker → coordinator: the job cannot run (bad scene, missing file, …).
    Failed { reason: String },
    /// Coordinator → worker: render only these tiles from the next round on (adaptive tiles, decided from the
    /// merged sums): one flag per `tile`-pixel tile of the image, row-major. A worker never told renders every
    /// tile.
    ActiveTiles { tile: u32, flags: Vec<bool> },
    /// Coordinator → worker: the processes rendering the image changed; number the phases accordingly from the
    /// next round on.
    Share(Share),
    /// Worker → coordinator: a portion of the worker's ray map. A worker sends its last portions before
    /// `Finished`.
    RayMapPortion(RayMapPortion),
    /// Coordinator → worker: the run stops `in_ms` milliseconds after this message was sent; start no phase
    /// that would end more than `slack_ms` after that. A `Stop` still ends the job.
    StopAt { in_ms: u64, slack_ms: u64 },
}

impl Snapshot {
    /// The checksum `delta` must carry.
    pub fn checksum_of(delta: &[u8]) -> u32 {
        crc32fast::hash(delta)
    }
}

impl Message {
    /// The variant's name, for logs and errors (never the content: it may be large or secret).
    pub fn kind(&self) -> &'static str {
        match self {
            Message::Hello { .. } => "Hello",
            Message::Proof { .. } => "Proof",
            Message::Refused { .. } => "Refused",
            Message::Job(_) => "Job",
            Message::NeedFiles { .. } => "NeedFiles",
            Message::FilePiece(_) => "FilePiece",
            Message::LitPixels(_) => "LitPixels",
            Message::Started(_) => "Started",
            Message::Snapshot(_) => "Snapshot",
            Message::Ack { .. } => "Ack",
            Message::Heartbeat => "Heartbeat",
            Message::Stop => "Stop",
            Message::Finished => "Finished",
            Message::Failed { .. } => "Failed",
            Message::ActiveTiles { .. } => "ActiveTiles",
            Message::Share(_) => "Share",
            Message::RayMapPortion(_) => "RayMapPortion",
            Message::StopAt { .. } => "StopAt",
        }
    }
}

/// bincode's limit on what one message may claim to hold, so a forged length inside a frame cannot make the
/// decoder allocate more than a frame can carry.
const DECODE_LIMIT: usize = super::frame::DEFAULT_MAX_FRAME as usize;

fn config() -> impl bincode::config::Config {
    bincode::config::standard().with_limit::<DECODE_LIMIT>()
}

/// Encodes a message as a frame body.
pub fn encode(message: &Message) -> Result<Vec<u8>, ProtocolError> {
    bincode::serde::encode_to_vec(message, config()).map_err(|e| ProtocolError::Malformed(e.to_string()))
}

/// Decodes a frame body; the whole body must be one message.
pub fn decode(body: &[u8]) -> Result<Message, ProtocolError> {
    let (message, used) = bincode::serde::decode_from_slice::<Message, _>(body, config())
        .map_err(|e| ProtocolError::Malformed(e.to_string()))?;
    if used != body.len() {
        return Err(ProtocolError::Malformed(format!("{} bytes after the message", body.len() - used)));
    }
    Ok(message)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_round_trip() {
        let m = Message::Hello { version: 1, role: Role::Worker, nonce: [7; 32], name: "w".into() };
        assert_eq!(decode(&encode(&m).unwrap()).unwrap(), m);
        let m = Message::Ack { seq: 42 };
        assert_eq!(decode(&encode(&m).unwrap()).unwrap(), m);
        let m = Message::ActiveTiles { tile: 32, flags: vec![true, false, true] };
        assert_eq!(decode(&encode(&m).unwrap()).unwrap(), m);
        let m = Message::RayMapPortion(RayMapPortion { raw_bytes: 9, paths: 1, segments: 2, frame: vec![1, 2, 3] });
        assert_eq!(decode(&encode(&m).unwrap()).unwrap(), m);
        let m = Message::StopAt { in_ms: 60_000, slack_ms: 1_200 };
        assert_eq!(decode(&encode(&m).unwrap()).unwrap(), m);
        let m = Message::FilePiece(FilePiece { sha256: "ab".into(), size: 9, offset: 4, bytes: vec![1, 2] });
        assert_eq!(decode(&encode(&m).unwrap()).unwrap(), m);
    }

    #[test]
    fn a_file_s_pieces_cover_it_in_order_and_each_fits_a_frame() {
        let bytes: Vec<u8> = (0..2 * FILE_PIECE_BYTES + 5).map(|i| (i % 251) as u8).collect();
        let pieces = FilePiece::all_of("h", &bytes);
        assert_eq!(pieces.len(), 3);
        let mut joined = Vec::new();
        for p in &pieces {
            assert_eq!((p.size, p.offset), (bytes.len() as u64, joined.len() as u64));
            assert!(encode(&Message::FilePiece(p.clone())).unwrap().len() <= DECODE_LIMIT);
            joined.extend_from_slice(&p.bytes);
        }
        assert_eq!(joined, bytes);
        let empty = FilePiece::all_of("h", &[]);
        assert_eq!(empty, vec![FilePiece { sha256: "h".into(), size: 0, offset: 0, bytes: vec![] }]);
    }

    #[test]
    fn a_share_carries_every_pixel_s_merged_phases_and_is_refused_for_another_image() {
        let phases = [3u32, 0, 7, 4_000_000_000];
        let share = Share { processes: 2, rank: 1, merged_phases: Share::compress_phases(phases.into_iter()) };
        let m = Message::Share(share.clone());
        assert_eq!(decode(&encode(&m).unwrap()).unwrap(), m);
        assert_eq!(share.merged_phases(4).unwrap(), phases);
        assert!(share.merged_phases(3).is_err());
        assert!(share.merged_phases(5).is_err());
        let garbage = Share { merged_phases: vec![1, 2, 3], ..share };
        assert!(garbage.merged_phases(4).is_err());
    }

    #[test]
    fn trailing_bytes_and_unknown_variants_are_refused() {
        let mut body = encode(&Message::Heartbeat).unwrap();
        body.push(0);
        assert!(matches!(decode(&body), Err(ProtocolError::Malformed(_))));
        assert!(matches!(decode(&[200]), Err(ProtocolError::Malformed(_))));
    }

    #[test]
    fn a_forged_length_inside_a_message_does_not_allocate_it() {
        // NeedFiles (variant 4) claiming 2^60 strings: refused by the decode limit, not attempted.
        let mut body = vec![4u8, 0xff];
        body.extend_from_slice(&(1u64 << 60).to_le_bytes());
        assert!(matches!(decode(&body), Err(ProtocolError::Malformed(_))));
    }
}
