//! Deltas of the sums: per-pixel sums added between two moments, exact (f64), laid out plane by plane with the
//! bytes of each plane shuffled by significance so that zstd finds the repetition in exponents and counts.
//! The auxiliary layers' channels follow as further planes; the header names them, so that sums of another
//! layout are refused rather than misread. Workers send them in snapshots; checkpoints store the sums as deltas
//! from zero of consecutive pieces of the image.

use super::{Accumulator, AuxLayout, PixelSums};
use crate::sampling::REPLICATES;

/// The first bytes of every uncompressed delta of the whole image (its format version); checkpoints hold one.
pub const MAGIC: &[u8; 4] = b"PFD3";
/// The first bytes of an uncompressed delta of some pixels only (a snapshot of the tiles its rounds rendered):
/// after the header, the runs of pixels it holds, then the planes over those pixels alone.
pub const SPARSE_MAGIC: &[u8; 4] = b"PFD4";
/// f64 planes: 12 layer sums (4 layers × RGB), 5 squared-luminance sums, then the replicates' luminance sums.
const F64_PLANES: usize = 17 + REPLICATES;
/// The squared-luminance planes, which no sum of phases can make negative.
const SQUARE_PLANES: std::ops::Range<usize> = 12..17;
/// u32 planes: phases, camera rays, then the replicates' phases.
const U32_PLANES: usize = 2 + REPLICATES;
/// Bytes per pixel before compression: the u32 counts and the f64 planes (auxiliary planes not included).
const BYTES_PER_PIXEL: usize = 4 * U32_PLANES + 8 * F64_PLANES;

/// The header's description of the auxiliary layers: their count, then per layer its channels, the length of
/// its name and the name.
fn layout_bytes(layout: &AuxLayout) -> Vec<u8> {
    let mut out = vec![layout.layers().len() as u8];
    for l in layout.layers() {
        out.push(l.channels);
        out.push(l.name.len() as u8);
        out.extend_from_slice(l.name.as_bytes());
    }
    out
}

/// Layer names of a layout, for messages.
fn layout_names(layout: &AuxLayout) -> String {
    let names: Vec<&str> = layout.layers().iter().map(|l| l.name.as_str()).collect();
    format!("[{}]", names.join(", "))
}

fn f64_plane(p: &PixelSums, k: usize) -> f64 {
    match k {
        0..12 => p.sum[k / 3][k % 3],
        12..17 => p.sum_sq[k - 12],
        _ => p.replicate_sum[k - 17],
    }
}

fn f64_plane_mut(p: &mut PixelSums, k: usize) -> &mut f64 {
    match k {
        0..12 => &mut p.sum[k / 3][k % 3],
        12..17 => &mut p.sum_sq[k - 12],
        _ => &mut p.replicate_sum[k - 17],
    }
}

fn u32_plane(p: &PixelSums, k: usize) -> u32 {
    match k {
        0 => p.phases,
        1 => p.camera_rays,
        _ => p.replicate_phases[k - 2],
    }
}

fn u32_plane_mut(p: &mut PixelSums, k: usize) -> &mut u32 {
    match k {
        0 => &mut p.phases,
        1 => &mut p.camera_rays,
        _ => &mut p.replicate_phases[k - 2],
    }
}

/// How hard a delta is compressed: what counts on a loopback link is the worker's CPU time, on a network its
/// bandwidth.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Compression {
    /// zstd's fast mode (level −5): about half the bytes of level 1's saving at a fraction of its time.
    Fast,
    /// zstd level 1.
    Small,
}

impl Compression {
    /// Fast for a peer on this machine, small otherwise.
    pub fn for_peer(peer: std::net::SocketAddr) -> Self {
        if peer.ip().is_loopback() {
            Compression::Fast
        } else {
            Compression::Small
        }
    }

    fn level(self) -> i32 {
        match self {
            Compression::Fast => -5,
            Compression::Small => 1,
        }
    }
}

/// Pixels a delta holds: increasing, disjoint runs of consecutive pixel indices (row-major). A worker's
/// snapshot holds the pixels its rounds rendered since the previous one, so that its cost, and the merge's,
/// follow what changed rather than the image's size.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PixelRuns {
    /// (first pixel, pixels), each run starting at or after the previous one's end.
    runs: Vec<(u32, u32)>,
    pixels: usize,
}

impl PixelRuns {
    /// Every pixel of an image of `n` pixels.
    pub fn all(n: usize) -> Self {
        let runs = if n == 0 { Vec::new() } else { vec![(0, n as u32)] };
        PixelRuns { runs, pixels: n }
    }

    /// The pixels whose flag is set.
    pub fn from_flags(flags: &[bool]) -> Self {
        let mut runs: Vec<(u32, u32)> = Vec::new();
        let mut pixels = 0;
        let mut i = 0;
        while i < flags.len() {
            if !flags[i] {
                i += 1;
                continue;
            }
            let start = i;
            while i < flags.len() && flags[i] {
                i += 1;
            }
            runs.push((start as u32, (i - start) as u32));
            pixels += i - start;
        }
        PixelRuns { runs, pixels }
    }

    /// How many pixels the runs hold.
    pub fn pixel_count(&self) -> usize {
        self.pixels
    }

    /// The runs, as (first pixel, pixels).
    pub fn runs(&self) -> &[(u32, u32)] {
        &self.runs
    }

    /// The pixels' indices, in increasing order.
    pub fn indices(&self) -> impl Iterator<Item = usize> + '_ {
        self.runs.iter().flat_map(|&(s, l)| s as usize..s as usize + l as usize)
    }

    /// The runs cut into pieces of at most `CHUNK` pixels, each with its position among the runs' pixels: a
    /// piece's sums stay in the cache while every plane of it is written or read.
    fn pieces(&self) -> impl Iterator<Item = (usize, std::ops::Range<usize>)> + '_ {
        let mut at = 0;
        self.runs.iter().flat_map(move |&(s, l)| {
            let (s, l) = (s as usize, l as usize);
            let first = at;
            at += l;
            (0..l.div_ceil(CHUNK)).map(move |c| (first + c * CHUNK, s + c * CHUNK..s + ((c + 1) * CHUNK).min(l)))
        })
    }
}

/// Pixels per piece of a delta's planes (see `PixelRuns::pieces`): 1024 pixels' sums and their base are about
/// 400 KB.
const CHUNK: usize = 1024;

/// The pixels whose sums changed since some moment, each with the sums it had then: what a delta of those
/// pixels subtracts, kept for them alone rather than as a copy of the whole image (a worker's snapshots).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Changes {
    /// The pixels, in the order they were kept (increasing once sorted).
    pixels: Vec<u32>,
    /// Their sums and auxiliary sums then, in the same order.
    before: Vec<PixelSums>,
    before_aux: Vec<f64>,
}

impl Changes {
    /// Keeps pixel `i`'s sums as `sums` hold them now, before it changes; once per pixel.
    pub fn keep(&mut self, i: usize, sums: &Accumulator) {
        self.pixels.push(i as u32);
        self.before.push(sums.pixels[i]);
        self.before_aux.extend_from_slice(sums.aux.pixel(i));
    }

    /// How many pixels are kept.
    pub fn len(&self) -> usize {
        self.pixels.len()
    }

    /// Bytes held, as allocated.
    pub fn capacity_bytes(&self) -> usize {
        self.pixels.capacity() * 4
            + self.before.capacity() * std::mem::size_of::<PixelSums>()
            + self.before_aux.capacity() * 8
    }

    /// True when no pixel is kept.
    pub fn is_empty(&self) -> bool {
        self.pixels.is_empty()
    }

    /// The kept pixels, in the order they are kept.
    pub fn pixels(&self) -> impl Iterator<Item = usize> + '_ {
        self.pixels.iter().map(|&i| i as usize)
    }

    /// The kept pixels with the phases each had then.
    pub fn phases_before(&self) -> impl Iterator<Item = (usize, u32)> + '_ {
        self.pixels.iter().zip(&self.before).map(|(&i, b)| (i as usize, b.phases))
    }

    /// The same changes in increasing pixel order, as `runs` and `encode_changes` take them.
    pub fn into_sorted(self) -> Self {
        let mut order: Vec<usize> = (0..self.pixels.len()).collect();
        order.sort_unstable_by_key(|&k| self.pixels[k]);
        let channels = if self.pixels.is_empty() { 0 } else { self.before_aux.len() / self.pixels.len() };
        Changes {
            pixels: order.iter().map(|&k| self.pixels[k]).collect(),
            before: order.iter().map(|&k| self.before[k]).collect(),
            before_aux: order
                .iter()
                .flat_map(|&k| &self.before_aux[k * channels..(k + 1) * channels])
                .copied()
                .collect(),
        }
    }

    /// The kept pixels as runs (sorted changes only).
    pub fn runs(&self) -> PixelRuns {
        assert!(self.pixels.is_sorted_by(|a, b| a < b), "runs of unsorted changes");
        let mut runs: Vec<(u32, u32)> = Vec::new();
        for &i in &self.pixels {
            match runs.last_mut() {
                Some((s, l)) if *s + *l == i => *l += 1,
                _ => runs.push((i, 1)),
            }
        }
        PixelRuns { runs, pixels: self.pixels.len() }
    }
}

/// The sums a delta subtracts.
#[derive(Clone, Copy)]
enum Base<'a> {
    /// Sums of zeros.
    Zero,
    /// Sums of the whole image.
    Image(&'a Accumulator),
    /// The sums of the delta's pixels alone, in its order (sorted `Changes`).
    Kept(&'a Changes),
}

/// The delta `current − base` over the whole image, compressed (the dense format, which checkpoints hold).
/// Pixels with no new phase cost almost nothing after compression.
pub fn encode_delta(current: &Accumulator, base: &Accumulator, compression: Compression) -> Vec<u8> {
    encode(current, Base::Image(base), None, compression)
}

/// The delta from the sums `changes` kept to `current` over the changed pixels, compressed: the same bytes as
/// `encode_delta_of` from a base holding those sums.
pub fn encode_changes(current: &Accumulator, changes: &Changes, compression: Compression) -> Vec<u8> {
    let runs = changes.runs();
    assert!(
        runs.runs.last().is_none_or(|&(s, l)| (s as usize + l as usize) <= current.pixels.len()),
        "runs beyond the image"
    );
    assert_eq!(changes.before_aux.len(), changes.len() * current.aux.layout().channels(), "changes of other layers");
    encode(current, Base::Kept(changes), Some(&runs), compression)
}

/// The deltas `current − 0` of consecutive pieces of `piece_pixels` pixels covering the image, each compressed
/// on its own and handed to `out` in order (a checkpoint's sums): applied in turn to sums of zeros they give
/// `current` back exactly, and no more than one piece is ever encoded at once, whatever the image's size.
pub fn encode_whole_in_pieces<E>(
    current: &Accumulator,
    piece_pixels: usize,
    compression: Compression,
    mut out: impl FnMut(&[u8]) -> Result<(), E>,
) -> Result<(), E> {
    assert!(piece_pixels > 0, "pieces of no pixel");
    let n = current.pixels.len();
    for start in (0..n).step_by(piece_pixels) {
        let len = piece_pixels.min(n - start);
        let piece = PixelRuns { runs: vec![(start as u32, len as u32)], pixels: len };
        out(&encode(current, Base::Zero, Some(&piece), compression))?;
    }
    Ok(())
}

/// The delta `current − base` over `pixels` only, compressed: the sums of every other pixel must be the same in
/// both, as the receiver leaves them unchanged.
pub fn encode_delta_of(
    current: &Accumulator,
    base: &Accumulator,
    pixels: &PixelRuns,
    compression: Compression,
) -> Vec<u8> {
    assert!(
        pixels.runs.last().is_none_or(|&(s, l)| (s as usize + l as usize) <= current.pixels.len()),
        "runs beyond the image"
    );
    encode(current, Base::Image(base), Some(pixels), compression)
}

/// `current − base` over `pixels` (every pixel if None).
fn encode(current: &Accumulator, base: Base, pixels: Option<&PixelRuns>, compression: Compression) -> Vec<u8> {
    if let Base::Image(base) = base {
        assert_eq!(current.pixels.len(), base.pixels.len(), "a delta needs two sums of the same image");
        assert_eq!(current.aux.layout(), base.aux.layout(), "a delta needs two sums of the same layers");
    }
    let layout = layout_bytes(current.aux.layout());
    let aux_channels = current.aux.layout().channels();
    let n = current.pixels.len();
    let whole;
    let (magic, runs) = match pixels {
        Some(r) => (SPARSE_MAGIC, r),
        None => {
            whole = PixelRuns::all(n);
            (MAGIC, &whole)
        }
    };
    let m = runs.pixel_count();
    let run_bytes = if pixels.is_some() { 4 + 8 * runs.runs.len() } else { 0 };
    let mut raw = Vec::with_capacity(8 + layout.len() + run_bytes + (BYTES_PER_PIXEL + 8 * aux_channels) * m);
    raw.extend_from_slice(magic);
    raw.extend_from_slice(&(n as u32).to_le_bytes());
    raw.extend_from_slice(&layout);
    if pixels.is_some() {
        raw.extend_from_slice(&(runs.runs.len() as u32).to_le_bytes());
        for &(s, l) in &runs.runs {
            raw.extend_from_slice(&s.to_le_bytes());
            raw.extend_from_slice(&l.to_le_bytes());
        }
    }
    let body_start = raw.len();
    raw.resize(body_start + (BYTES_PER_PIXEL + 8 * aux_channels) * m, 0);
    let (counts, floats) = raw[body_start..].split_at_mut(4 * U32_PLANES * m);
    let c_aux = current.aux.values();
    let zero = PixelSums::default();
    // Byte b of value j of plane k goes to plane k's byte-b row at column j (a byte shuffle).
    for (j0, range) in runs.pieces() {
        let base_of = |j: usize| match base {
            Base::Zero => &zero,
            Base::Image(b) => &b.pixels[range.start + j],
            Base::Kept(c) => &c.before[j0 + j],
        };
        let pairs = current.pixels[range.clone()].iter().enumerate().map(|(j, c)| (c, base_of(j)));
        for k in 0..U32_PLANES {
            let plane = &mut counts[4 * m * k..4 * m * (k + 1)];
            for (j, (c, b)) in pairs.clone().enumerate() {
                for (byte, x) in (u32_plane(c, k) - u32_plane(b, k)).to_le_bytes().into_iter().enumerate() {
                    plane[byte * m + j0 + j] = x;
                }
            }
        }
        for k in 0..F64_PLANES {
            let plane = &mut floats[8 * m * k..8 * m * (k + 1)];
            for (j, (c, b)) in pairs.clone().enumerate() {
                for (byte, x) in (f64_plane(c, k) - f64_plane(b, k)).to_le_bytes().into_iter().enumerate() {
                    plane[byte * m + j0 + j] = x;
                }
            }
        }
        let aux_range = range.start * aux_channels..range.end * aux_channels;
        let c = &c_aux[aux_range.clone()];
        let b = match base {
            Base::Zero => None,
            Base::Image(b) => Some(&b.aux.values()[aux_range]),
            Base::Kept(k) => Some(&k.before_aux[j0 * aux_channels..(j0 + range.len()) * aux_channels]),
        };
        for k in 0..aux_channels {
            let plane = &mut floats[8 * m * (F64_PLANES + k)..8 * m * (F64_PLANES + k + 1)];
            for j in 0..range.len() {
                let v = c[j * aux_channels + k] - b.map_or(0.0, |b| b[j * aux_channels + k]);
                for (byte, x) in v.to_le_bytes().into_iter().enumerate() {
                    plane[byte * m + j0 + j] = x;
                }
            }
        }
    }
    zstd::bulk::compress(&raw, compression.level()).expect("zstd compression of an in-memory buffer cannot fail")
}

/// The most bytes a compressed delta of `pixels` pixels with the auxiliary layers `layout` can take
/// (zstd's bound for incompressible input).
pub fn max_delta_bytes(pixels: u64, layout: &AuxLayout) -> u64 {
    let raw = max_raw_bytes(pixels, layout);
    // zstd's documented bound: the input, plus 1/256 of it, plus a small constant for its frame.
    raw + raw / 256 + (128 << 10)
}

/// The most bytes a delta of `pixels` pixels can take before compression: a sparse one whose runs are single
/// pixels, every other one.
fn max_raw_bytes(pixels: u64, layout: &AuxLayout) -> u64 {
    let runs = pixels.div_ceil(2);
    8 + layout_bytes(layout).len() as u64
        + 4
        + 8 * runs
        + (BYTES_PER_PIXEL as u64 + 8 * layout.channels() as u64) * pixels
}

/// What a delta added.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct DeltaSummary {
    /// Pixel-phases added (Σ over pixels of new phases).
    pub pixel_phases: u64,
    /// Bytes of the delta before compression.
    pub raw_bytes: usize,
    /// The pixels it held.
    pub pixels: PixelRuns,
}

/// Why a delta was refused: it does not fit the sums it was applied to, or holds a value no sum can have.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct DeltaError(String);

/// The runs of a sparse delta's header (after the magic, the size and the layout), checked against an image of
/// `n` pixels, and the bytes they took.
fn read_runs(raw: &[u8], n: usize) -> Result<(PixelRuns, usize), DeltaError> {
    let short = || DeltaError(format!("the delta ends inside its list of pixels ({} bytes)", raw.len()));
    let count = u32::from_le_bytes(raw.get(..4).ok_or_else(short)?.try_into().expect("4 bytes")) as usize;
    let bytes = 4 + 8 * count;
    let table = raw.get(4..bytes).ok_or_else(short)?;
    let mut runs = Vec::with_capacity(count);
    let (mut end, mut pixels) = (0u64, 0usize);
    for r in table.chunks_exact(8) {
        let s = u32::from_le_bytes(r[..4].try_into().expect("4 bytes"));
        let l = u32::from_le_bytes(r[4..].try_into().expect("4 bytes"));
        if l == 0 || (s as u64) < end || s as u64 + l as u64 > n as u64 {
            return Err(DeltaError(format!(
                "the delta's pixels {s}..{} are empty, out of order or outside the image of {n} pixels",
                s as u64 + l as u64
            )));
        }
        end = s as u64 + l as u64;
        pixels += l as usize;
        runs.push((s, l));
    }
    Ok((PixelRuns { runs, pixels }, bytes))
}

/// Adds a delta to `sums` after checking all of it: the image size, the auxiliary layers, the pixels it holds,
/// finite numbers, non-negative squares. A refused delta leaves `sums` unchanged. Its cost follows the pixels
/// it holds, not the image's size.
pub fn apply_delta(bytes: &[u8], sums: &mut Accumulator) -> Result<DeltaSummary, DeltaError> {
    let n = sums.pixels.len();
    let layout = layout_bytes(sums.aux.layout());
    let aux_channels = sums.aux.layout().channels();
    let most = max_raw_bytes(n as u64, sums.aux.layout()).min(usize::MAX as u64) as usize;
    // The frame's own size when it states one within the bound: the buffer is then the delta's size, not the
    // whole image's bound. A frame that understates its size fails to decompress into it.
    let stated = zstd::zstd_safe::get_frame_content_size(bytes).ok().flatten().filter(|&s| s <= most as u64);
    let capacity = stated.map_or(most, |s| s as usize);
    let raw = zstd::bulk::decompress(bytes, capacity).map_err(|e| DeltaError(format!("cannot decompress: {e}")))?;
    let header = 8 + layout.len();
    let sparse = raw.get(..4) == Some(&SPARSE_MAGIC[..]);
    let size_error = |expected: usize| {
        DeltaError(format!(
            "expected a delta of {n} pixels with the auxiliary layers {} ({expected} bytes), got {} bytes",
            layout_names(sums.aux.layout()),
            raw.len()
        ))
    };
    if raw.len() < header || !(sparse || &raw[..4] == MAGIC) || raw[4..8] != (n as u32).to_le_bytes() {
        return Err(size_error(header + (BYTES_PER_PIXEL + 8 * aux_channels) * n));
    }
    if raw[8..header] != layout[..] {
        return Err(DeltaError(format!(
            "the delta's auxiliary layers are not the image's {}",
            layout_names(sums.aux.layout())
        )));
    }
    let (runs, run_bytes) = if sparse { read_runs(&raw[header..], n)? } else { (PixelRuns::all(n), 0) };
    let m = runs.pixel_count();
    let expected = header + run_bytes + (BYTES_PER_PIXEL + 8 * aux_channels) * m;
    if raw.len() != expected {
        return Err(size_error(expected));
    }
    let body = &raw[header + run_bytes..];
    let (counts, rest) = body.split_at(4 * m * U32_PLANES);
    let (planes, aux_planes) = rest.split_at(8 * m * F64_PLANES);
    let shuffled = Shuffled { counts, planes, aux_planes, m };
    // Every value is checked before any is added, so that a refused delta leaves the sums unchanged; values are
    // read from the shuffled bytes where they lie, a piece of pixels at a time, so a merge holds no decoded copy.
    for (j0, range) in runs.pieces() {
        check_piece(sums, &shuffled, j0, range)?;
    }
    let aux = sums.aux.values_mut();
    let mut pixel_phases = 0u64;
    for (j0, range) in runs.pieces() {
        for (j, i) in (j0..).zip(range) {
            for k in 0..aux_channels {
                aux[i * aux_channels + k] += shuffled.aux(k, j);
            }
            let p = &mut sums.pixels[i];
            pixel_phases += shuffled.count(0, j) as u64;
            // `check_piece` found no overflow; wrapping adds keep a release build from checking again.
            for k in 0..U32_PLANES {
                let c = u32_plane_mut(p, k);
                *c = c.wrapping_add(shuffled.count(k, j));
            }
            for k in 0..F64_PLANES {
                *f64_plane_mut(p, k) += shuffled.value(k, j);
            }
        }
    }
    Ok(DeltaSummary { pixel_phases, raw_bytes: expected, pixels: runs })
}

/// The planes of a delta's body over its `m` pixels, each value's bytes spread over its plane's byte rows.
struct Shuffled<'a> {
    counts: &'a [u8],
    planes: &'a [u8],
    aux_planes: &'a [u8],
    m: usize,
}

impl Shuffled<'_> {
    /// Byte b of value j of plane k lies in plane k's byte-b row at column j.
    fn gather<const N: usize>(bytes: &[u8], m: usize, k: usize, j: usize) -> [u8; N] {
        let plane = &bytes[N * m * k..N * m * (k + 1)];
        std::array::from_fn(|b| plane[b * m + j])
    }

    fn count(&self, k: usize, j: usize) -> u32 {
        u32::from_le_bytes(Self::gather(self.counts, self.m, k, j))
    }

    fn value(&self, k: usize, j: usize) -> f64 {
        f64::from_le_bytes(Self::gather(self.planes, self.m, k, j))
    }

    fn aux(&self, k: usize, j: usize) -> f64 {
        f64::from_le_bytes(Self::gather(self.aux_planes, self.m, k, j))
    }
}

/// Refuses a piece of a delta (its values from j0 on, for the pixels of `range`) that holds a value no sum can
/// have (not finite, a negative square), or whose addition would overflow a pixel's phase or camera-ray count
/// or make a sum infinite: a buggy or hostile peer must not wrap the counts (a panic in debug builds, silent
/// corruption in release) nor leave part of its delta merged.
fn check_piece(
    sums: &Accumulator,
    delta: &Shuffled,
    j0: usize,
    range: std::ops::Range<usize>,
) -> Result<(), DeltaError> {
    let channels = sums.aux.layout().channels();
    let aux = sums.aux.values();
    for k in 0..F64_PLANES {
        for (j, i) in (j0..).zip(range.clone()) {
            let v = delta.value(k, j);
            if !v.is_finite() || (SQUARE_PLANES.contains(&k) && v < 0.0) {
                return Err(DeltaError(format!("pixel {i} has an invalid sum ({v})")));
            }
        }
    }
    for k in 0..channels {
        for (j, i) in (j0..).zip(range.clone()) {
            let v = delta.aux(k, j);
            if !v.is_finite() {
                return Err(DeltaError(format!("pixel {i} has an invalid auxiliary sum ({v})")));
            }
        }
    }
    for (j, i) in (j0..).zip(range) {
        let p = &sums.pixels[i];
        if let Some(k) = (0..U32_PLANES).find(|&k| u32_plane(p, k).checked_add(delta.count(k, j)).is_none()) {
            return Err(DeltaError(format!(
                "pixel {i} would overflow its count {k} ({} + {})",
                u32_plane(p, k),
                delta.count(k, j)
            )));
        }
        if let Some(k) = (0..F64_PLANES).find(|&k| !(f64_plane(p, k) + delta.value(k, j)).is_finite()) {
            return Err(DeltaError(format!("pixel {i} would overflow its sum {k}")));
        }
        if let Some(k) = (0..channels).find(|&k| !(aux[i * channels + k] + delta.aux(k, j)).is_finite()) {
            return Err(DeltaError(format!("pixel {i} would overflow its auxiliary sum {k}")));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accumulation::AuxLayer;
    use crate::color::Rgb;

    fn ghost_layout() -> AuxLayout {
        AuxLayout::new(vec![AuxLayer { name: "ghost".into(), channels: 3 }])
    }

    /// Sums of `phases` phases per pixel; with a layout, every auxiliary channel gets a part of each phase.
    fn sums(n: usize, phases: u32, seed: f32, aux: &AuxLayout) -> Accumulator {
        let mut a = Accumulator::with_aux(n as u32, 1, aux.clone());
        for i in 0..n {
            for j in 0..phases {
                let v = Rgb::splat(seed + (i as f32 * 0.37 + j as f32 * 1.3).sin().abs());
                a.add_phase(i, &[v, v * 0.5, v * 0.25, Rgb::ZERO], 1, j as usize % REPLICATES);
                let part: Vec<f32> = (0..aux.channels()).map(|c| v.x * 0.1 * (c + 1) as f32).collect();
                a.aux.add_phase(i, &part);
            }
        }
        a
    }

    fn check_round_trip(aux: &AuxLayout) {
        let base = sums(100, 3, 0.1, aux);
        let mut current = base.clone();
        current.merge(&sums(100, 2, 0.7, aux));
        for compression in [Compression::Fast, Compression::Small] {
            let mut receiver = base.clone();
            let summary = apply_delta(&encode_delta(&current, &base, compression), &mut receiver).unwrap();
            assert_eq!(summary.pixel_phases, 200);
            for (r, c) in receiver.pixels.iter().zip(&current.pixels) {
                for k in 0..U32_PLANES {
                    assert_eq!(u32_plane(r, k), u32_plane(c, k));
                }
                for k in 0..F64_PLANES {
                    assert!((f64_plane(r, k) - f64_plane(c, k)).abs() <= 1e-12 * f64_plane(c, k).abs().max(1.0));
                }
            }
            assert_eq!(receiver.aux.values().len(), current.aux.values().len());
            for (r, c) in receiver.aux.values().iter().zip(current.aux.values()) {
                assert!((r - c).abs() <= 1e-12 * c.abs().max(1.0), "auxiliary sum {r} vs {c}");
            }
        }
    }

    #[test]
    fn deltas_add_up_to_the_sums_they_were_taken_from() {
        check_round_trip(&AuxLayout::default());
    }

    #[test]
    fn deltas_with_ghost_planes_add_up_to_the_sums_they_were_taken_from() {
        assert!(sums(10, 2, 0.5, &ghost_layout()).aux.values().iter().all(|&v| v > 0.0), "the test sums are empty");
        check_round_trip(&ghost_layout());
        check_round_trip(&AuxLayout::new(vec![
            AuxLayer { name: "ghost".into(), channels: 3 },
            AuxLayer { name: "band_550".into(), channels: 1 },
        ]));
    }

    #[test]
    fn a_whole_image_in_pieces_gives_back_the_sums_exactly_one_run_of_pixels_per_piece() {
        for layout in [AuxLayout::default(), ghost_layout()] {
            let current = sums(37, 3, 0.7, &layout);
            let mut back = Accumulator::with_aux(37, 1, layout.clone());
            let mut runs = Vec::new();
            encode_whole_in_pieces(&current, 10, Compression::Small, |piece| {
                runs.extend(apply_delta(piece, &mut back)?.pixels.runs().to_vec());
                Ok::<_, DeltaError>(())
            })
            .unwrap();
            assert_eq!(runs, [(0, 10), (10, 10), (20, 10), (30, 7)]);
            assert_eq!(back, current, "a delta from zero added to zero is the sums bit for bit");
        }
    }

    #[test]
    fn a_delta_of_other_auxiliary_layers_is_refused_and_changes_nothing() {
        let ghost = sums(10, 1, 0.2, &ghost_layout());
        let delta = encode_delta(&ghost, &Accumulator::with_aux(10, 1, ghost_layout()), Compression::Fast);
        let mut plain = Accumulator::new(10, 1);
        assert!(apply_delta(&delta, &mut plain).is_err(), "ghost planes into an image without them");
        let bands = AuxLayout::new(vec![
            AuxLayer { name: "band_450".into(), channels: 1 },
            AuxLayer { name: "band_550".into(), channels: 1 },
            AuxLayer { name: "band_650".into(), channels: 1 },
        ]);
        // As many channels as the ghost layer: only the names tell them apart.
        let mut other = Accumulator::with_aux(10, 1, bands);
        let e = apply_delta(&delta, &mut other).unwrap_err().to_string();
        assert!(e.contains("auxiliary layers"), "{e}");
        assert!(other.pixels.iter().all(|p| p.phases == 0) && other.aux.values().iter().all(|&v| v == 0.0));
        let plain_delta = encode_delta(&Accumulator::new(10, 1), &Accumulator::new(10, 1), Compression::Fast);
        let mut with_ghost = Accumulator::with_aux(10, 1, ghost_layout());
        assert!(apply_delta(&plain_delta, &mut with_ghost).is_err(), "a delta without the ghost planes");
    }

    #[test]
    fn changes_kept_before_an_update_encode_the_bytes_of_a_delta_from_a_copy_of_the_whole_image() {
        for layout in [AuxLayout::default(), ghost_layout()] {
            let base = sums(40, 2, 0.3, &layout);
            let (mut current, mut changes) = (base.clone(), Changes::default());
            let more = sums(40, 1, 0.9, &layout);
            // Changed in no order, as groups' masks name their pixels; a run of three among them.
            for i in [31usize, 4, 17, 5, 6, 39] {
                changes.keep(i, &current);
                current.pixels[i].merge(&more.pixels[i]);
                let channels = layout.channels();
                for k in 0..channels {
                    current.aux.values_mut()[i * channels + k] += more.aux.pixel(i)[k];
                }
            }
            assert_eq!(changes.phases_before().next(), Some((31, 2)));
            let changes = changes.into_sorted();
            let runs = changes.runs();
            assert_eq!(runs.runs(), &[(4, 3), (17, 1), (31, 1), (39, 1)]);
            for compression in [Compression::Fast, Compression::Small] {
                assert_eq!(
                    encode_changes(&current, &changes, compression),
                    encode_delta_of(&current, &base, &runs, compression)
                );
            }
            let mut receiver = base.clone();
            apply_delta(&encode_changes(&current, &changes, Compression::Fast), &mut receiver).unwrap();
            assert_eq!(
                receiver.pixels.iter().map(|p| p.phases).collect::<Vec<_>>(),
                current.pixels.iter().map(|p| p.phases).collect::<Vec<_>>()
            );
        }
        assert_eq!(Changes::default().into_sorted().runs(), PixelRuns::default());
    }

    #[test]
    fn a_frame_that_states_no_size_decodes_as_one_that_does() {
        let current = sums(30, 2, 0.4, &AuxLayout::default());
        let stated = encode_delta(&current, &Accumulator::new(30, 1), Compression::Fast);
        assert!(zstd::zstd_safe::get_frame_content_size(&stated).unwrap().is_some(), "bulk frames state their size");
        let raw = zstd::bulk::decompress(&stated, 1 << 20).unwrap();
        let mut compressor = zstd::bulk::Compressor::new(1).unwrap();
        compressor.include_contentsize(false).unwrap();
        let unstated = compressor.compress(&raw).unwrap();
        assert_eq!(zstd::zstd_safe::get_frame_content_size(&unstated).unwrap(), None);
        let (mut a, mut b) = (Accumulator::new(30, 1), Accumulator::new(30, 1));
        apply_delta(&stated, &mut a).unwrap();
        apply_delta(&unstated, &mut b).unwrap();
        assert_eq!((&a, &b), (&current, &current));
    }

    #[test]
    fn a_delta_for_another_image_size_or_with_garbage_is_refused_and_changes_nothing() {
        let none = AuxLayout::default();
        let current = sums(10, 1, 0.2, &none);
        let delta = encode_delta(&current, &Accumulator::new(10, 1), Compression::Small);
        let mut other = Accumulator::new(11, 1);
        assert!(apply_delta(&delta, &mut other).is_err());
        assert!(other.pixels.iter().all(|p| p.phases == 0));
        assert!(apply_delta(b"not zstd at all", &mut other).is_err());
        // A NaN inside a valid frame.
        let mut bad = current.clone();
        bad.pixels[3].sum[0][0] = f64::NAN;
        let mut target = Accumulator::new(10, 1);
        assert!(apply_delta(&encode_delta(&bad, &Accumulator::new(10, 1), Compression::Fast), &mut target).is_err());
        assert!(target.pixels.iter().all(|p| p.phases == 0));
        // A NaN in a ghost plane.
        let mut bad = sums(10, 1, 0.2, &ghost_layout());
        bad.aux.values_mut()[7] = f64::NAN;
        let zero = Accumulator::with_aux(10, 1, ghost_layout());
        let mut target = zero.clone();
        assert!(apply_delta(&encode_delta(&bad, &zero, Compression::Fast), &mut target).is_err());
        assert_eq!(target, zero);
    }

    #[test]
    fn a_delta_that_would_overflow_a_pixels_counts_is_refused_whole() {
        let none = AuxLayout::default();
        let mut target = sums(10, 2, 0.2, &none);
        target.pixels[7].phases = u32::MAX - 1;
        let before = target.clone();
        // Two more phases on every pixel: pixel 7 would wrap, the pixels before it would not.
        let delta = encode_delta(&sums(10, 2, 0.4, &none), &Accumulator::new(10, 1), Compression::Fast);
        let e = apply_delta(&delta, &mut target).unwrap_err().to_string();
        assert!(e.contains("pixel 7") && e.contains("overflow"), "{e}");
        assert_eq!(target, before, "nothing of a refused delta is merged");
        let mut target = sums(10, 2, 0.2, &none);
        target.pixels[2].camera_rays = u32::MAX;
        let before = target.clone();
        assert!(apply_delta(&delta, &mut target).is_err());
        assert_eq!(target, before);
        // A finite sum that a finite delta would push past f64::MAX.
        let mut huge = sums(10, 2, 0.4, &none);
        huge.pixels[4].sum[0][0] = 0.75 * f64::MAX;
        let delta = encode_delta(&huge, &Accumulator::new(10, 1), Compression::Fast);
        let mut target = sums(10, 2, 0.2, &none);
        target.pixels[4].sum[0][0] = 0.75 * f64::MAX;
        let before = target.clone();
        assert!(apply_delta(&delta, &mut target).unwrap_err().to_string().contains("pixel 4"));
        assert_eq!(target, before);
    }

    /// Sums of an image of 64 × 48 pixels where the 16-pixel tiles in `tiles` (row-major over 4 × 3) got two
    /// more phases than `base`, and the flags of their pixels.
    fn with_tiles_changed(base: &Accumulator, tiles: &[usize], aux: &AuxLayout) -> (Accumulator, Vec<bool>) {
        let mut current = base.clone();
        let more = sums(64 * 48, 2, 0.9, aux);
        let mut flags = vec![false; 64 * 48];
        for &t in tiles {
            for y in 0..16 {
                for x in 0..16 {
                    let i = (t / 4 * 16 + y) * 64 + t % 4 * 16 + x;
                    flags[i] = true;
                    current.pixels[i].merge(&more.pixels[i]);
                    let c = aux.channels();
                    for k in 0..c {
                        current.aux.values_mut()[i * c + k] += more.aux.values()[i * c + k];
                    }
                }
            }
        }
        (current, flags)
    }

    #[test]
    fn a_delta_of_the_changed_tiles_merges_to_the_sums_of_a_whole_image_delta() {
        for aux in [AuxLayout::default(), ghost_layout()] {
            let mut base = sums(64 * 48, 3, 0.1, &aux);
            (base.width, base.height) = (64, 48);
            let (current, flags) = with_tiles_changed(&base, &[0, 5, 6, 11], &aux);
            let runs = PixelRuns::from_flags(&flags);
            // Tiles 5 and 6 touch: their rows are one run each.
            assert_eq!((runs.pixel_count(), runs.runs().len()), (4 * 256, 16 * 3));
            let mut receiver = sums(64 * 48, 5, 0.3, &aux);
            (receiver.width, receiver.height) = (64, 48);
            let (mut whole, mut sparse) = (receiver.clone(), receiver.clone());
            let full = encode_delta(&current, &base, Compression::Fast);
            let part = encode_delta_of(&current, &base, &runs, Compression::Fast);
            let a = apply_delta(&full, &mut whole).unwrap();
            let b = apply_delta(&part, &mut sparse).unwrap();
            // Bit for bit: the whole image's delta adds exact zeros elsewhere.
            assert_eq!(sparse, whole);
            assert_eq!((a.pixel_phases, b.pixel_phases), (4 * 256 * 2, 4 * 256 * 2));
            assert_eq!(b.pixels, runs);
            assert_eq!(a.pixels, PixelRuns::all(64 * 48));
            assert!(b.raw_bytes * 2 < a.raw_bytes, "{} raw bytes against {}", b.raw_bytes, a.raw_bytes);
            // Nothing changed: a delta of no pixels changes nothing.
            let none = encode_delta_of(&current, &current, &PixelRuns::default(), Compression::Small);
            let before = sparse.clone();
            assert_eq!(apply_delta(&none, &mut sparse).unwrap().pixel_phases, 0);
            assert_eq!(sparse, before);
        }
    }

    #[test]
    fn a_sparse_delta_with_pixels_out_of_order_overlapping_or_outside_the_image_is_refused() {
        let none = AuxLayout::default();
        let base = Accumulator::new(64, 48);
        let (current, flags) = with_tiles_changed(&base, &[1, 2, 9], &none);
        let runs = PixelRuns::from_flags(&flags);
        let raw = zstd::bulk::decompress(
            &encode_delta_of(&current, &base, &runs, Compression::Fast),
            max_raw_bytes(64 * 48, &none) as usize,
        )
        .unwrap();
        let table = 8 + layout_bytes(&none).len() + 4;
        let run = |raw: &[u8], r: usize, field: usize| {
            let at = table + 8 * r + 4 * field;
            u32::from_le_bytes(raw[at..at + 4].try_into().unwrap())
        };
        let set = |raw: &mut Vec<u8>, r: usize, field: usize, v: u32| {
            let at = table + 8 * r + 4 * field;
            raw[at..at + 4].copy_from_slice(&v.to_le_bytes());
        };
        let mut edits: Vec<Vec<u8>> = Vec::new();
        let mut e = raw.clone();
        // The second run starts inside the first.
        let first_end = run(&raw, 0, 0) + run(&raw, 0, 1);
        set(&mut e, 1, 0, first_end - 1);
        edits.push(e);
        let mut e = raw.clone();
        // Runs swapped.
        let (r0, r1) = ((run(&raw, 0, 0), run(&raw, 0, 1)), (run(&raw, 1, 0), run(&raw, 1, 1)));
        set(&mut e, 0, 0, r1.0);
        set(&mut e, 0, 1, r1.1);
        set(&mut e, 1, 0, r0.0);
        set(&mut e, 1, 1, r0.1);
        edits.push(e);
        let mut e = raw.clone();
        // The last run past the image's end.
        let last = runs.runs().len() - 1;
        set(&mut e, last, 0, 64 * 48 - 8);
        edits.push(e);
        let mut e = raw.clone();
        // An empty run.
        set(&mut e, 2, 1, 0);
        edits.push(e);
        let mut e = raw.clone();
        // More runs than the table holds.
        e[table - 4..table].copy_from_slice(&u32::MAX.to_le_bytes());
        edits.push(e);
        let mut e = raw.clone();
        // One pixel more than the planes hold.
        set(&mut e, 0, 1, run(&raw, 0, 1) + 1);
        edits.push(e);
        for (k, e) in edits.iter().enumerate() {
            let mut target = Accumulator::new(64, 48);
            let r = apply_delta(&zstd::bulk::compress(e, 1).unwrap(), &mut target);
            assert!(r.is_err(), "edit {k} was merged");
            assert_eq!(target, Accumulator::new(64, 48), "edit {k} changed the sums");
        }
        let mut target = Accumulator::new(64, 48);
        apply_delta(&zstd::bulk::compress(&raw, 1).unwrap(), &mut target).unwrap();
        assert_eq!(target, current);
    }

    #[test]
    fn a_delta_without_new_phases_compresses_to_almost_nothing() {
        for aux in [AuxLayout::default(), ghost_layout()] {
            let s = sums(4096, 2, 0.3, &aux);
            for compression in [Compression::Fast, Compression::Small] {
                let len = encode_delta(&s, &s, compression).len();
                assert!(len < 4096, "{compression:?}: {len} bytes");
            }
        }
    }
}
