//! Deltas of the sums: per-pixel sums added between two moments, exact (f64), laid out plane by plane with the
//! bytes of each plane shuffled by significance so that zstd finds the repetition in exponents and counts.
//! The auxiliary layers' channels follow as further planes; the header names them, so that sums of another
//! layout are refused rather than misread. Workers send them in snapshots; checkpoints store the sums as a delta
//! from zero.

use super::{Accumulator, AuxLayout, PixelSums};
use crate::sampling::REPLICATES;

/// The first bytes of every uncompressed delta (its format version).
pub const MAGIC: &[u8; 4] = b"PFD3";
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

/// Appends `values` with byte i of every value stored together (a byte shuffle).
fn push_shuffled<const N: usize>(out: &mut Vec<u8>, values: &[[u8; N]]) {
    let start = out.len();
    out.resize(start + N * values.len(), 0);
    let planes = &mut out[start..];
    let n = values.len();
    for (i, v) in values.iter().enumerate() {
        for (byte, &x) in v.iter().enumerate() {
            planes[byte * n + i] = x;
        }
    }
}

/// The values of one shuffled plane.
fn unshuffle<const N: usize>(plane: &[u8], n: usize) -> Vec<[u8; N]> {
    let mut out = vec![[0u8; N]; n];
    for byte in 0..N {
        for (v, &x) in out.iter_mut().zip(&plane[byte * n..(byte + 1) * n]) {
            v[byte] = x;
        }
    }
    out
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

/// The delta `current − base`, compressed. Pixels with no new phase cost almost nothing after compression.
pub fn encode_delta(current: &Accumulator, base: &Accumulator, compression: Compression) -> Vec<u8> {
    assert_eq!(current.pixels.len(), base.pixels.len(), "a delta needs two sums of the same image");
    assert_eq!(current.aux.layout(), base.aux.layout(), "a delta needs two sums of the same layers");
    let layout = layout_bytes(current.aux.layout());
    let aux_channels = current.aux.layout().channels();
    let n = current.pixels.len();
    let mut raw = Vec::with_capacity(8 + layout.len() + (BYTES_PER_PIXEL + 8 * aux_channels) * n);
    raw.extend_from_slice(MAGIC);
    raw.extend_from_slice(&(n as u32).to_le_bytes());
    raw.extend_from_slice(&layout);
    let pairs = current.pixels.iter().zip(&base.pixels);
    for k in 0..U32_PLANES {
        let counts: Vec<[u8; 4]> =
            pairs.clone().map(|(c, b)| (u32_plane(c, k) - u32_plane(b, k)).to_le_bytes()).collect();
        push_shuffled(&mut raw, &counts);
    }
    let mut plane: Vec<[u8; 8]> = Vec::with_capacity(n);
    for k in 0..F64_PLANES {
        plane.clear();
        plane.extend(pairs.clone().map(|(c, b)| (f64_plane(c, k) - f64_plane(b, k)).to_le_bytes()));
        push_shuffled(&mut raw, &plane);
    }
    let (c, b) = (current.aux.values(), base.aux.values());
    for k in 0..aux_channels {
        plane.clear();
        plane.extend((0..n).map(|i| (c[i * aux_channels + k] - b[i * aux_channels + k]).to_le_bytes()));
        push_shuffled(&mut raw, &plane);
    }
    zstd::bulk::compress(&raw, compression.level()).expect("zstd compression of an in-memory buffer cannot fail")
}

/// The most bytes a compressed delta of `pixels` pixels with the auxiliary layers `layout` can take
/// (zstd's bound for incompressible input).
pub fn max_delta_bytes(pixels: u64, layout: &AuxLayout) -> u64 {
    let raw = 8 + layout_bytes(layout).len() as u64 + (BYTES_PER_PIXEL as u64 + 8 * layout.channels() as u64) * pixels;
    // zstd's documented bound: the input, plus 1/256 of it, plus a small constant for its frame.
    raw + raw / 256 + (128 << 10)
}

/// What a delta added.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DeltaSummary {
    /// Pixel-phases added (Σ over pixels of new phases).
    pub pixel_phases: u64,
    /// Bytes of the delta before compression.
    pub raw_bytes: usize,
}

/// Why a delta was refused: it does not fit the sums it was applied to, or holds a value no sum can have.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct DeltaError(String);

/// Adds a delta to `sums` after checking all of it: the image size, the auxiliary layers, finite numbers,
/// non-negative squares. A refused delta leaves `sums` unchanged.
pub fn apply_delta(bytes: &[u8], sums: &mut Accumulator) -> Result<DeltaSummary, DeltaError> {
    let n = sums.pixels.len();
    let layout = layout_bytes(sums.aux.layout());
    let aux_channels = sums.aux.layout().channels();
    let expected = 8 + layout.len() + (BYTES_PER_PIXEL + 8 * aux_channels) * n;
    let raw = zstd::bulk::decompress(bytes, expected).map_err(|e| DeltaError(format!("cannot decompress: {e}")))?;
    if raw.len() != expected || &raw[..4] != MAGIC || raw[4..8] != (n as u32).to_le_bytes() {
        return Err(DeltaError(format!(
            "expected a delta of {n} pixels with the auxiliary layers {} ({expected} bytes), got {} bytes",
            layout_names(sums.aux.layout()),
            raw.len()
        )));
    }
    if raw[8..8 + layout.len()] != layout[..] {
        return Err(DeltaError(format!(
            "the delta's auxiliary layers are not the image's {}",
            layout_names(sums.aux.layout())
        )));
    }
    let body = &raw[8 + layout.len()..];
    let (counts, rest) = body.split_at(4 * n * U32_PLANES);
    let (planes, aux_planes) = rest.split_at(8 * n * F64_PLANES);
    let values: Vec<Vec<f64>> = (0..F64_PLANES)
        .map(|k| unshuffle::<8>(&planes[8 * n * k..8 * n * (k + 1)], n).into_iter().map(f64::from_le_bytes).collect())
        .collect();
    for (k, plane) in values.iter().enumerate() {
        if let Some((i, v)) =
            plane.iter().enumerate().find(|(_, v)| !v.is_finite() || (SQUARE_PLANES.contains(&k) && **v < 0.0))
        {
            return Err(DeltaError(format!("pixel {i} has an invalid sum ({v})")));
        }
    }
    let aux_values: Vec<Vec<f64>> = (0..aux_channels)
        .map(|k| {
            unshuffle::<8>(&aux_planes[8 * n * k..8 * n * (k + 1)], n).into_iter().map(f64::from_le_bytes).collect()
        })
        .collect();
    for plane in &aux_values {
        if let Some((i, v)) = plane.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(DeltaError(format!("pixel {i} has an invalid auxiliary sum ({v})")));
        }
    }
    let counts: Vec<Vec<u32>> = (0..U32_PLANES)
        .map(|k| unshuffle::<4>(&counts[4 * n * k..4 * n * (k + 1)], n).into_iter().map(u32::from_le_bytes).collect())
        .collect();
    check_sums_stay_valid(sums, &counts, &values, &aux_values)?;
    let aux = sums.aux.values_mut();
    for (k, plane) in aux_values.iter().enumerate() {
        for (i, v) in plane.iter().enumerate() {
            aux[i * aux_channels + k] += v;
        }
    }
    let mut pixel_phases = 0u64;
    for (i, p) in sums.pixels.iter_mut().enumerate() {
        pixel_phases += counts[0][i] as u64;
        // `check_sums_stay_valid` found no overflow; wrapping adds keep a release build from checking again.
        for (k, plane) in counts.iter().enumerate() {
            let c = u32_plane_mut(p, k);
            *c = c.wrapping_add(plane[i]);
        }
        for (k, plane) in values.iter().enumerate() {
            *f64_plane_mut(p, k) += plane[i];
        }
    }
    Ok(DeltaSummary { pixel_phases, raw_bytes: expected })
}

/// Refuses a delta whose addition would overflow a pixel's phase or camera-ray count or make a sum infinite: a
/// buggy or hostile peer must not wrap the counts (a panic in debug builds, silent corruption in release) nor
/// leave part of its delta merged.
fn check_sums_stay_valid(
    sums: &Accumulator,
    counts: &[Vec<u32>],
    values: &[Vec<f64>],
    aux_values: &[Vec<f64>],
) -> Result<(), DeltaError> {
    for (i, p) in sums.pixels.iter().enumerate() {
        if let Some(k) = (0..U32_PLANES).find(|&k| u32_plane(p, k).checked_add(counts[k][i]).is_none()) {
            return Err(DeltaError(format!(
                "pixel {i} would overflow its count {k} ({} + {})",
                u32_plane(p, k),
                counts[k][i]
            )));
        }
        if let Some((k, _)) = values.iter().enumerate().find(|(k, plane)| !(f64_plane(p, *k) + plane[i]).is_finite()) {
            return Err(DeltaError(format!("pixel {i} would overflow its sum {k}")));
        }
    }
    let channels = aux_values.len();
    let aux = sums.aux.values();
    for (k, plane) in aux_values.iter().enumerate() {
        if let Some((i, _)) = plane.iter().enumerate().find(|(i, v)| !(aux[i * channels + k] + **v).is_finite()) {
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
