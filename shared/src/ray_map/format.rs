//! The ray map's file format, version 1 (docs/ray-maps.md describes it byte by byte).
//!
//! A stream file is `MAGIC`, the version (u32), the header's length (u32) and the header (JSON, `MapHeader`),
//! then portions. A portion is `PORTION_MAGIC`, its compressed length, raw length, path count and segment
//! count (u32 each) and one zstd frame with a content checksum. The raw bytes are the paths one after the other:
//! a path header (`CAMERA_PATH_BYTES` or `LIGHT_PATH_BYTES`, holding the origin) and `VERTEX_BYTES` per
//! segment, little-endian throughout.

use super::events::Events;
use super::path::{PathKind, RecordedPath, Vertex, NO_OBJECT};
use serde::{Deserialize, Serialize};

/// The first bytes of a stream file.
pub const MAGIC: &[u8; 8] = b"PFRAYMAP";
/// The format version this library writes and reads.
pub const VERSION: u32 = 1;
/// The first bytes of a portion.
pub const PORTION_MAGIC: &[u8; 4] = b"PRTN";
/// Bytes before a portion's compressed frame.
pub const PORTION_HEADER_BYTES: usize = 20;
/// Bytes of a camera path's header: vertex count and kind (u16, the kind in the top bit), phase, item (u32
/// each), wavelength (f32), weight (3 × f32: a spectral path's colour may have a negative channel), origin
/// (3 × f32).
pub const CAMERA_PATH_BYTES: usize = 2 + 4 + 4 + 4 + 12 + 12;
/// Bytes of a light path's header: a camera path's, then its emitter (u32) and the origin's normal (u32).
pub const LIGHT_PATH_BYTES: usize = CAMERA_PATH_BYTES + 8;
/// Bytes of every vertex after the origin (one per segment): point (3 × f32), normal (u32), object (u16),
/// primitive (u32), events (u8).
pub const VERTEX_BYTES: usize = 12 + 4 + 2 + 4 + 1;
/// Where a vertex's normal, object, primitive and events start in its bytes (its point starts at 0).
const NORMAL_AT: usize = 12;
const OBJECT_AT: usize = 16;
const PRIMITIVE_AT: usize = 18;
const EVENTS_AT: usize = 22;
const _: () = assert!(EVENTS_AT + 1 == VERTEX_BYTES);
/// Most vertices a path may have (its count has 15 bits).
pub const MAX_VERTICES: usize = (1 << 15) - 1;
/// The kind's bit in the vertex count.
const LIGHT_BIT: u16 = 1 << 15;
/// The largest header or raw portion a reader accepts, so that a corrupt length cannot ask for all memory.
pub const MAX_BLOCK_BYTES: usize = 1 << 30;

/// What a stream's header tells about the render it was recorded from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MapHeader {
    /// The scene file as the render was given it.
    pub scene: String,
    /// The scene's SHA-256 (`Scene::hash`).
    pub scene_hash: String,
    pub width: u32,
    pub height: u32,
    /// Object names by object index (a vertex's `object`).
    pub objects: Vec<String>,
    /// Emitter names by emitter index (a light path's `source`): emitting objects by their name, `[[lights]]`
    /// entries as `lights[i]`.
    pub emitters: Vec<String>,
    /// The render's method.
    pub method: String,
    pub seed: u64,
    /// The fraction of paths recorded.
    pub fraction: f64,
    /// Which stream of the map this is (one per worker; 0 for an in-process render).
    pub stream: u32,
}

/// Appends `path`'s bytes to `out`: its origin as `RecordedPath::begin` made it (the rest of vertex 0 is
/// implied by the kind), at most `MAX_VERTICES` vertices. A path without vertices is not written.
pub fn encode_path(path: &RecordedPath, out: &mut Vec<u8>) {
    let Some(origin) = path.vertices.first() else { return };
    let count = path.vertices.len().min(MAX_VERTICES) as u16;
    let light = path.kind == PathKind::Light;
    out.extend_from_slice(&(count | if light { LIGHT_BIT } else { 0 }).to_le_bytes());
    out.extend_from_slice(&path.phase.to_le_bytes());
    out.extend_from_slice(&path.item.to_le_bytes());
    out.extend_from_slice(&path.wavelength_nm.to_le_bytes());
    for w in path.weight {
        out.extend_from_slice(&w.to_le_bytes());
    }
    for c in origin.point {
        out.extend_from_slice(&c.to_le_bytes());
    }
    if light {
        out.extend_from_slice(&path.source.to_le_bytes());
        out.extend_from_slice(&origin.normal.to_le_bytes());
    }
    for v in &path.vertices[1..count as usize] {
        for c in v.point {
            out.extend_from_slice(&c.to_le_bytes());
        }
        out.extend_from_slice(&v.normal.to_le_bytes());
        out.extend_from_slice(&v.object.to_le_bytes());
        out.extend_from_slice(&v.primitive.to_le_bytes());
        out.push(v.events.0);
    }
}

/// A cursor over raw bytes that fails with what it was reading rather than panicking.
struct Bytes<'a> {
    data: &'a [u8],
    at: usize,
}

impl<'a> Bytes<'a> {
    fn take<const N: usize>(&mut self, what: &str) -> Result<[u8; N], String> {
        let end = self.at + N;
        let slice = self.data.get(self.at..end).ok_or_else(|| format!("it ends inside a path's {what}"))?;
        self.at = end;
        Ok(slice.try_into().expect("slice of length N"))
    }
    fn u32(&mut self, what: &str) -> Result<u32, String> {
        self.take::<4>(what).map(u32::from_le_bytes)
    }
    fn f32(&mut self, what: &str) -> Result<f32, String> {
        self.take::<4>(what).map(f32::from_le_bytes)
    }
}

/// One path of a portion's raw bytes, read in place: its header decoded, its vertices left as bytes, so that a
/// selection can test it without allocating and decode (`to_path`) only the paths it keeps.
#[derive(Clone, Copy, Debug)]
pub struct PathView<'a> {
    pub kind: PathKind,
    /// As `RecordedPath::source`.
    pub source: u32,
    pub phase: u32,
    pub item: u32,
    pub wavelength_nm: f32,
    pub weight: [f32; 3],
    origin: [f32; 3],
    origin_normal: u32,
    /// The vertices after the origin, `VERTEX_BYTES` each.
    vertex_bytes: &'a [u8],
}

impl<'a> PathView<'a> {
    /// The path's segments (its vertices after the origin).
    pub fn segments(&self) -> usize {
        self.vertex_bytes.len() / VERTEX_BYTES
    }

    /// The origin's events: the sensor for a camera path, emission for a light path.
    fn origin_events(&self) -> Events {
        match self.kind {
            PathKind::Camera => Events::SENSOR,
            PathKind::Light => Events::EMISSION,
        }
    }

    /// Each vertex's object and events, the origin first (on no object), without decoding the rest.
    #[inline]
    pub fn objects_and_events(&self) -> impl Iterator<Item = (u16, Events)> + 'a {
        let stored = self
            .vertex_bytes
            .chunks_exact(VERTEX_BYTES)
            .map(|v| (u16::from_le_bytes([v[OBJECT_AT], v[OBJECT_AT + 1]]), Events(v[EVENTS_AT])));
        std::iter::once((NO_OBJECT, self.origin_events())).chain(stored)
    }

    /// Each vertex's object, events and primitive (`Vertex::primitive`), the origin first (on no object and no
    /// primitive), without decoding the rest.
    #[inline]
    pub fn objects_events_primitives(&self) -> impl Iterator<Item = (u16, Events, u32)> + 'a {
        let stored = self.vertex_bytes.chunks_exact(VERTEX_BYTES).map(|v| {
            let primitive = [v[PRIMITIVE_AT], v[PRIMITIVE_AT + 1], v[PRIMITIVE_AT + 2], v[PRIMITIVE_AT + 3]];
            (u16::from_le_bytes([v[OBJECT_AT], v[OBJECT_AT + 1]]), Events(v[EVENTS_AT]), u32::from_le_bytes(primitive))
        });
        std::iter::once((NO_OBJECT, self.origin_events(), u32::MAX)).chain(stored)
    }

    /// The last vertex's events.
    #[inline]
    pub fn last_events(&self) -> Events {
        match self.vertex_bytes.len().checked_sub(VERTEX_BYTES) {
            Some(at) => Events(self.vertex_bytes[at + EVENTS_AT]),
            None => self.origin_events(),
        }
    }

    /// The path decoded, exactly as `decode_paths` returns it.
    pub fn to_path(&self) -> RecordedPath {
        let mut vertices = Vec::with_capacity(1 + self.segments());
        let origin = Vertex {
            point: self.origin,
            normal: self.origin_normal,
            object: NO_OBJECT,
            primitive: u32::MAX,
            events: self.origin_events(),
        };
        vertices.push(origin);
        for v in self.vertex_bytes.chunks_exact(VERTEX_BYTES) {
            let f = |i: usize| f32::from_le_bytes([v[i], v[i + 1], v[i + 2], v[i + 3]]);
            let u = |i: usize| u32::from_le_bytes([v[i], v[i + 1], v[i + 2], v[i + 3]]);
            vertices.push(Vertex {
                point: [f(0), f(4), f(8)],
                normal: u(NORMAL_AT),
                object: u16::from_le_bytes([v[OBJECT_AT], v[OBJECT_AT + 1]]),
                primitive: u(PRIMITIVE_AT),
                events: Events(v[EVENTS_AT]),
            });
        }
        RecordedPath {
            kind: self.kind,
            source: self.source,
            phase: self.phase,
            item: self.item,
            wavelength_nm: self.wavelength_nm,
            weight: self.weight,
            vertices,
        }
    }
}

/// The paths of a portion's raw bytes in order, read in place (`path_views`).
pub struct PathViews<'a> {
    bytes: Bytes<'a>,
    paths: usize,
    left: usize,
    done: bool,
}

/// The `paths` paths of a portion's raw bytes, in order, read in place. The first thing wrong (a path cut
/// short, a path without vertices, bytes after the last path) is an error item that ends the iteration.
pub fn path_views(raw: &[u8], paths: usize) -> PathViews<'_> {
    PathViews { bytes: Bytes { data: raw, at: 0 }, paths, left: paths, done: false }
}

impl<'a> PathViews<'a> {
    fn next_path(&mut self) -> Result<PathView<'a>, String> {
        let b = &mut self.bytes;
        let tagged = u16::from_le_bytes(b.take::<2>("vertex count")?);
        let count = (tagged & !LIGHT_BIT) as usize;
        let kind = if tagged & LIGHT_BIT != 0 { PathKind::Light } else { PathKind::Camera };
        if count == 0 {
            return Err(format!("a path without vertices at byte {}", b.at - 2));
        }
        let (phase, item) = (b.u32("phase")?, b.u32("item")?);
        let wavelength_nm = b.f32("wavelength")?;
        let weight = [b.f32("weight")?, b.f32("weight")?, b.f32("weight")?];
        let origin = [b.f32("origin")?, b.f32("origin")?, b.f32("origin")?];
        let (source, origin_normal) = match kind {
            PathKind::Camera => (item, 0),
            PathKind::Light => (b.u32("emitter")?, b.u32("origin normal")?),
        };
        let len = (count - 1) * VERTEX_BYTES;
        let Some(vertex_bytes) = b.data.get(b.at..b.at + len) else {
            return Err(format!("a path of {count} vertices ends after {} bytes", b.data.len() - b.at));
        };
        b.at += len;
        Ok(PathView { kind, source, phase, item, wavelength_nm, weight, origin, origin_normal, vertex_bytes })
    }
}

impl<'a> Iterator for PathViews<'a> {
    type Item = Result<PathView<'a>, String>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        if self.left == 0 {
            self.done = true;
            let after = self.bytes.data.len() - self.bytes.at;
            return (after != 0).then(|| Err(format!("{after} bytes follow the portion's {} paths", self.paths)));
        }
        self.left -= 1;
        let path = self.next_path();
        self.done = path.is_err();
        Some(path)
    }
}

/// Decodes a portion's raw bytes into `paths` paths; the error says what is wrong.
pub fn decode_paths(raw: &[u8], paths: usize) -> Result<Vec<RecordedPath>, String> {
    let mut out = Vec::with_capacity(paths.min(raw.len() / CAMERA_PATH_BYTES + 1));
    for view in path_views(raw, paths) {
        out.push(view?.to_path());
    }
    Ok(out)
}

/// A portion's header: the lengths and counts before its frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PortionHeader {
    pub compressed: u32,
    pub raw: u32,
    pub paths: u32,
    pub segments: u32,
}

impl PortionHeader {
    /// The header's bytes.
    pub fn to_bytes(self) -> [u8; PORTION_HEADER_BYTES] {
        let mut b = [0u8; PORTION_HEADER_BYTES];
        b[..4].copy_from_slice(PORTION_MAGIC);
        for (i, v) in [self.compressed, self.raw, self.paths, self.segments].into_iter().enumerate() {
            b[4 + 4 * i..8 + 4 * i].copy_from_slice(&v.to_le_bytes());
        }
        b
    }

    /// Reads a header, or says why these bytes are not one.
    pub fn from_bytes(b: &[u8; PORTION_HEADER_BYTES]) -> Result<Self, String> {
        if &b[..4] != PORTION_MAGIC {
            return Err("no portion starts here (bad magic)".into());
        }
        let at = |i: usize| u32::from_le_bytes(b[4 + 4 * i..8 + 4 * i].try_into().expect("4 bytes"));
        let h = PortionHeader { compressed: at(0), raw: at(1), paths: at(2), segments: at(3) };
        if h.raw as usize > MAX_BLOCK_BYTES || h.compressed as usize > MAX_BLOCK_BYTES {
            return Err(format!("a portion claims {} bytes ({} compressed), beyond any portion", h.raw, h.compressed));
        }
        if (h.paths as usize) * CAMERA_PATH_BYTES + (h.segments as usize) * VERTEX_BYTES > h.raw as usize {
            return Err(format!("{} paths of {} segments cannot fit in {} bytes", h.paths, h.segments, h.raw));
        }
        Ok(h)
    }
}
