//! Snapshot deltas: per-pixel sums added since the previous snapshot, exact (f64), laid out plane by plane with
//! the bytes of each plane shuffled by significance so that zstd finds the repetition in exponents and counts.

use super::ProtocolError;
use crate::accumulation::PixelSums;

const MAGIC: &[u8; 4] = b"PFD1";
/// f64 planes: 12 layer sums (4 layers × RGB), then 5 squared-luminance sums.
const F64_PLANES: usize = 17;
/// Bytes per pixel before compression: two u32 counts and the f64 planes.
const BYTES_PER_PIXEL: usize = 8 + 8 * F64_PLANES;

fn f64_plane(p: &PixelSums, k: usize) -> f64 {
    if k < 12 {
        p.sum[k / 3][k % 3]
    } else {
        p.sum_sq[k - 12]
    }
}

fn f64_plane_mut(p: &mut PixelSums, k: usize) -> &mut f64 {
    if k < 12 {
        &mut p.sum[k / 3][k % 3]
    } else {
        &mut p.sum_sq[k - 12]
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
pub fn encode_delta(current: &[PixelSums], base: &[PixelSums], compression: Compression) -> Vec<u8> {
    assert_eq!(current.len(), base.len(), "a delta needs two sums of the same image");
    let n = current.len();
    let mut raw = Vec::with_capacity(8 + BYTES_PER_PIXEL * n);
    raw.extend_from_slice(MAGIC);
    raw.extend_from_slice(&(n as u32).to_le_bytes());
    let pairs = current.iter().zip(base);
    let counts: Vec<[u8; 4]> = pairs.clone().map(|(c, b)| (c.phases - b.phases).to_le_bytes()).collect();
    push_shuffled(&mut raw, &counts);
    let counts: Vec<[u8; 4]> = pairs.clone().map(|(c, b)| (c.camera_rays - b.camera_rays).to_le_bytes()).collect();
    push_shuffled(&mut raw, &counts);
    let mut plane: Vec<[u8; 8]> = Vec::with_capacity(n);
    for k in 0..F64_PLANES {
        plane.clear();
        plane.extend(pairs.clone().map(|(c, b)| (f64_plane(c, k) - f64_plane(b, k)).to_le_bytes()));
        push_shuffled(&mut raw, &plane);
    }
    zstd::bulk::compress(&raw, compression.level()).expect("zstd compression of an in-memory buffer cannot fail")
}

/// What a delta added.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DeltaSummary {
    /// Pixel-phases added (Σ over pixels of new phases).
    pub pixel_phases: u64,
    /// Bytes of the delta before compression.
    pub raw_bytes: usize,
}

/// Adds a delta to `sums` after checking all of it: the image size, finite numbers, non-negative squares.
/// A refused delta leaves `sums` unchanged.
pub fn apply_delta(bytes: &[u8], sums: &mut [PixelSums]) -> Result<DeltaSummary, ProtocolError> {
    let n = sums.len();
    let expected = 8 + BYTES_PER_PIXEL * n;
    let raw = zstd::bulk::decompress(bytes, expected)
        .map_err(|e| ProtocolError::Snapshot(format!("cannot decompress: {e}")))?;
    if raw.len() != expected || &raw[..4] != MAGIC || raw[4..8] != (n as u32).to_le_bytes() {
        return Err(ProtocolError::Snapshot(format!(
            "expected a delta of {n} pixels ({expected} bytes), got {} bytes",
            raw.len()
        )));
    }
    let body = &raw[8..];
    let (phases, rest) = body.split_at(4 * n);
    let (rays, planes) = rest.split_at(4 * n);
    let values: Vec<Vec<f64>> = (0..F64_PLANES)
        .map(|k| unshuffle::<8>(&planes[8 * n * k..8 * n * (k + 1)], n).into_iter().map(f64::from_le_bytes).collect())
        .collect();
    for (k, plane) in values.iter().enumerate() {
        if let Some((i, v)) = plane.iter().enumerate().find(|(_, v)| !v.is_finite() || (k >= 12 && **v < 0.0)) {
            return Err(ProtocolError::Snapshot(format!("pixel {i} has an invalid sum ({v})")));
        }
    }
    let (phases, rays) = (unshuffle::<4>(phases, n), unshuffle::<4>(rays, n));
    let mut pixel_phases = 0u64;
    for (i, p) in sums.iter_mut().enumerate() {
        let dp = u32::from_le_bytes(phases[i]);
        p.phases += dp;
        p.camera_rays += u32::from_le_bytes(rays[i]);
        pixel_phases += dp as u64;
        for (k, plane) in values.iter().enumerate() {
            *f64_plane_mut(p, k) += plane[i];
        }
    }
    Ok(DeltaSummary { pixel_phases, raw_bytes: expected })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::color::Rgb;

    fn sums(n: usize, phases: u32, seed: f32) -> Vec<PixelSums> {
        (0..n)
            .map(|i| {
                let mut p = PixelSums::default();
                for j in 0..phases {
                    let v = Rgb::splat(seed + (i as f32 * 0.37 + j as f32 * 1.3).sin().abs());
                    p.add_phase(&[v, v * 0.5, v * 0.25, Rgb::ZERO], 1);
                }
                p
            })
            .collect()
    }

    #[test]
    fn deltas_add_up_to_the_sums_they_were_taken_from() {
        let base = sums(100, 3, 0.1);
        let mut current = base.clone();
        for (c, extra) in current.iter_mut().zip(sums(100, 2, 0.7)) {
            c.merge(&extra);
        }
        for compression in [Compression::Fast, Compression::Small] {
            let mut receiver = base.clone();
            let summary = apply_delta(&encode_delta(&current, &base, compression), &mut receiver).unwrap();
            assert_eq!(summary.pixel_phases, 200);
            for (r, c) in receiver.iter().zip(&current) {
                assert_eq!((r.phases, r.camera_rays), (c.phases, c.camera_rays));
                for k in 0..F64_PLANES {
                    assert!((f64_plane(r, k) - f64_plane(c, k)).abs() <= 1e-12 * f64_plane(c, k).abs().max(1.0));
                }
            }
        }
    }

    #[test]
    fn a_delta_for_another_image_size_or_with_garbage_is_refused_and_changes_nothing() {
        let current = sums(10, 1, 0.2);
        let delta = encode_delta(&current, &vec![PixelSums::default(); 10], Compression::Small);
        let mut other = vec![PixelSums::default(); 11];
        assert!(apply_delta(&delta, &mut other).is_err());
        assert!(other.iter().all(|p| p.phases == 0));
        assert!(apply_delta(b"not zstd at all", &mut other).is_err());
        // A NaN inside a valid frame.
        let mut bad = current.clone();
        bad[3].sum[0][0] = f64::NAN;
        let mut target = vec![PixelSums::default(); 10];
        assert!(
            apply_delta(&encode_delta(&bad, &vec![PixelSums::default(); 10], Compression::Fast), &mut target).is_err()
        );
        assert!(target.iter().all(|p| p.phases == 0));
    }

    #[test]
    fn a_delta_without_new_phases_compresses_to_almost_nothing() {
        let s = sums(4096, 2, 0.3);
        for compression in [Compression::Fast, Compression::Small] {
            let len = encode_delta(&s, &s, compression).len();
            assert!(len < 4096, "{compression:?}: {len} bytes");
        }
    }
}
