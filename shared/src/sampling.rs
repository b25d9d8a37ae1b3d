//! Random streams and the warps from uniform numbers to the directions and points the estimators need.

mod piecewise;
mod square_grid;

pub use piecewise::{DistributionError, Piecewise1d, Piecewise2d};
pub use square_grid::{GridShape, SquareGrid};

use glam::{Vec2, Vec3};
use rand_core::RngCore;
use rand_pcg::Pcg32;
use std::f32::consts::PI;

/// One deterministic random stream; every (job seed, pass, phase, item) gets its own, so that results do not
/// depend on how work is split between threads. A quasi-random stream draws its first numbers from one point
/// of an Owen-scrambled Sobol sequence (`with_sobol`) and the rest from its pseudo-random stream.
pub struct Sampler {
    rng: Pcg32,
    sobol: Option<SobolPoint>,
}

/// The numbers of a path drawn from its Sobol point: a camera path's pixel jitter, lens, first next-event
/// sample and first BSDF samples; a light path's light choice, position, direction and first bounces. Further
/// numbers come from the pseudo-random stream: their dimensions gain little from stratification.
pub const SOBOL_DIMENSIONS: u32 = 12;

/// Independent scramblings of a pixel's Sobol sequence. Phases of one sequence are not independent, so a
/// pixel's phases are dealt among the replicates and its standard error comes from the spread of the replicate
/// means (`crate::accumulation`), which are independent.
pub const REPLICATES: usize = 4;

/// sobol_burley's points per sequence: past them a stream takes a fresh scrambling.
const SOBOL_POINTS: u64 = 1 << 16;

/// Point `index` of the Sobol sequence scrambled by `seed`, how many of its coordinates were drawn, and the
/// current set of four, which sobol_burley computes together (SIMD) for a quarter of the cost of one by one.
#[derive(Clone, Copy, Debug)]
struct SobolPoint {
    index: u32,
    seed: u32,
    dimension: u32,
    set: [f32; 4],
}

/// Where phase `j` (1-based) of a pixel lies in its quasi-random sequences: its replicate and its index in
/// that replicate's sequence.
#[inline]
pub fn replicate_of(j: u64) -> (usize, u64) {
    let i = j.saturating_sub(1);
    ((i % REPLICATES as u64) as usize, i / REPLICATES as u64)
}

/// Which part of a phase a stream feeds, so that camera and light streams never overlap.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pass {
    Camera = 1,
    Light = 2,
    Path = 3,
    /// The wavelength of a phase of a spectral scene.
    Wavelength = 4,
    /// The ghost paths of a phase (`crate::pbpm::trace_ghost_paths`).
    Ghost = 5,
}

fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

impl Sampler {
    /// The stream of one item (a pixel's camera path, one light path) of one phase of one job.
    pub fn new(seed: u64, pass: Pass, phase: u64, item: u64) -> Self {
        let state = splitmix64(seed ^ splitmix64(phase.wrapping_mul(0x1000_0000_01B3) ^ pass as u64));
        let stream = splitmix64(item ^ (pass as u64) << 56);
        Sampler { rng: Pcg32::new(state, stream), sobol: None }
    }

    /// The same stream with its first `SOBOL_DIMENSIONS` numbers taken from point `index` of the
    /// Owen-scrambled Sobol sequence `sequence` (any 64-bit key; distinct keys give independent scramblings).
    pub fn with_sobol(self, sequence: u64, index: u64) -> Self {
        // Every 2^16 points the sequence continues with a fresh scrambling: still uniform, still unbiased.
        let seed = splitmix64(sequence ^ splitmix64(index / SOBOL_POINTS)) as u32;
        let point = SobolPoint { index: (index % SOBOL_POINTS) as u32, seed, dimension: 0, set: [0.0; 4] };
        Sampler { sobol: Some(point), ..self }
    }

    /// The camera stream of phase `j` (1-based) of `pixel`: pseudo-random as `new(seed, Pass::Camera, key,
    /// pixel)`, its first numbers from the pixel's Sobol sequence of replicate `replicate_of(j)`.
    pub fn camera(seed: u64, key: u64, pixel: u64, j: u64) -> Self {
        Self::pixel(seed, Pass::Camera, key, pixel, j)
    }

    /// The path tracer's stream of phase `j` of `pixel`, quasi-random as the camera stream.
    pub fn path(seed: u64, pixel: u64, j: u64) -> Self {
        Self::pixel(seed, Pass::Path, j, pixel, j)
    }

    fn pixel(seed: u64, pass: Pass, key: u64, pixel: u64, j: u64) -> Self {
        let (replicate, index) = replicate_of(j);
        // The replicate goes into the hash: XORed onto the seed, seeds 0–3 would share their four scramblings.
        let sequence = splitmix64(seed ^ splitmix64(pixel ^ (pass as u64) << 56 ^ (replicate as u64) << 48));
        Self::new(seed, pass, key, pixel).with_sobol(sequence, index)
    }

    /// The stream of light path `index` of the phase with random key `key`: the phase's light paths are the
    /// points of one Sobol sequence, scrambled anew in every phase so that phases stay independent.
    pub fn light(seed: u64, key: u64, index: u64) -> Self {
        let sequence = splitmix64(seed ^ splitmix64(key.wrapping_mul(0x1000_0000_01B3) ^ Pass::Light as u64));
        Self::new(seed, Pass::Light, key, index).with_sobol(sequence, index)
    }

    /// The stream of ghost path `index` of the phase with random key `key`, quasi-random over the phase as the
    /// light paths are, in a sequence of its own.
    pub fn ghost(seed: u64, key: u64, index: u64) -> Self {
        let sequence = splitmix64(seed ^ splitmix64(key.wrapping_mul(0x1000_0000_01B3) ^ Pass::Ghost as u64));
        Self::new(seed, Pass::Ghost, key, index).with_sobol(sequence, index)
    }

    /// Uniform in [0, 1).
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        if let Some(p) = &mut self.sobol {
            if p.dimension < SOBOL_DIMENSIONS {
                if p.dimension % 4 == 0 {
                    p.set = sobol_burley::sample_4d(p.index, p.dimension / 4, p.seed);
                }
                let u = p.set[(p.dimension % 4) as usize];
                p.dimension += 1;
                return u;
            }
        }
        (self.rng.next_u32() >> 8) as f32 * (1.0 / 16_777_216.0)
    }

    /// Two uniform numbers in [0, 1).
    #[inline]
    pub fn next_2d(&mut self) -> Vec2 {
        Vec2::new(self.next_f32(), self.next_f32())
    }

    /// Puts `items` in a random order drawn from this stream (Fisher–Yates).
    pub fn shuffle<T>(&mut self, items: &mut [T]) {
        for i in (1..items.len()).rev() {
            let j = ((self.next_f32() * (i + 1) as f32) as usize).min(i);
            items.swap(i, j);
        }
    }
}

/// An orthonormal frame around a unit normal (Duff et al. 2017), for sampling in local coordinates.
#[derive(Clone, Copy, Debug)]
pub struct Frame {
    pub s: Vec3,
    pub t: Vec3,
    pub n: Vec3,
}

impl Frame {
    /// Builds a frame whose third axis is `n`.
    #[inline]
    pub fn from_normal(n: Vec3) -> Self {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        let s = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
        let t = Vec3::new(b, sign + n.y * n.y * a, -n.y);
        Frame { s, t, n }
    }

    /// Builds a frame whose third axis is `n` and whose first is `tangent` made perpendicular to it, as Mitsuba
    /// orients shading frames by ∂p/∂u; the frame of `from_normal` where the tangent is parallel to `n` (within
    /// a millionth of a radian) or not finite.
    pub fn from_normal_tangent(n: Vec3, tangent: Vec3) -> Self {
        let s = tangent - n * n.dot(tangent);
        let (len2, scale2) = (s.length_squared(), tangent.length_squared());
        if !(len2 > 1e-12 * scale2 && len2.is_finite() && len2 > 0.0) {
            return Frame::from_normal(n);
        }
        let s = s / len2.sqrt();
        Frame { s, t: n.cross(s), n }
    }

    /// Local to world coordinates.
    #[inline]
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.s * v.x + self.t * v.y + self.n * v.z
    }

    /// World to local coordinates.
    #[inline]
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.s), v.dot(self.t), v.dot(self.n))
    }
}

/// Cosine-weighted direction in the local hemisphere around +z; pdf = cos θ / π.
pub fn cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = concentric_disk(u);
    let z = (1.0 - d.x * d.x - d.y * d.y).max(0.0).sqrt();
    Vec3::new(d.x, d.y, z)
}

/// Uniform point on the unit disk with low distortion (Shirley–Chiu).
pub fn concentric_disk(u: Vec2) -> Vec2 {
    let o = 2.0 * u - Vec2::ONE;
    if o.x == 0.0 && o.y == 0.0 {
        return Vec2::ZERO;
    }
    let (r, theta) = if o.x.abs() > o.y.abs() {
        (o.x, (PI / 4.0) * (o.y / o.x))
    } else {
        (o.y, PI / 2.0 - (PI / 4.0) * (o.x / o.y))
    };
    r * Vec2::new(theta.cos(), theta.sin())
}

/// Uniform direction on the unit sphere; pdf = 1 / 4π.
pub fn uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Uniform direction in the cone of half-angle acos(cos_max) around +z; pdf = 1 / (2π (1 − cos_max)).
pub fn uniform_cone(u: Vec2, cos_max: f32) -> Vec3 {
    let z = 1.0 - u.x * (1.0 - cos_max);
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Uniform barycentric coordinates (b1, b2) on a triangle: p = (1 − b1 − b2) v0 + b1 v1 + b2 v2.
pub fn uniform_triangle(u: Vec2) -> Vec2 {
    let su = u.x.sqrt();
    Vec2::new(1.0 - su, u.y * su)
}

/// Power heuristic with β = 2 (Veach 1995), the MIS weight of paper eq. 3/5.
#[inline]
pub fn power_heuristic(pdf_a: f32, pdf_b: f32) -> f32 {
    let a = pdf_a * pdf_a;
    let b = pdf_b * pdf_b;
    if a + b == 0.0 {
        0.0
    } else {
        a / (a + b)
    }
}

/// A discrete distribution sampled by inverting its cumulative sum; used to choose lights by power.
#[derive(Clone, Debug)]
pub struct Discrete {
    cdf: Vec<f32>,
    pmf: Vec<f32>,
}

impl Discrete {
    /// Builds the distribution from non-negative weights; returns None when they sum to zero.
    pub fn new(weights: &[f32]) -> Option<Self> {
        let total: f64 = weights.iter().map(|&w| w.max(0.0) as f64).sum();
        if total <= 0.0 || !total.is_finite() {
            return None;
        }
        let mut acc = 0.0f64;
        let mut cdf = Vec::with_capacity(weights.len());
        let mut pmf = Vec::with_capacity(weights.len());
        for &w in weights {
            let w = w.max(0.0) as f64;
            acc += w;
            cdf.push((acc / total) as f32);
            pmf.push((w / total) as f32);
        }
        if let Some(last) = cdf.last_mut() {
            *last = 1.0;
        }
        Some(Discrete { cdf, pmf })
    }

    /// Index with probability proportional to its weight, and that probability.
    pub fn sample(&self, u: f32) -> (usize, f32) {
        let i = self.cdf.partition_point(|&c| c <= u).min(self.cdf.len() - 1);
        // Zero-weight entries share their cdf value with the next one and are never chosen.
        (i, self.pmf[i])
    }

    /// `sample`, and `u` rescaled to [0, 1) within the chosen entry's share, so that it can draw once more.
    pub fn sample_remapped(&self, u: f32) -> (usize, f32, f32) {
        let (i, p) = self.sample(u);
        let below = if i == 0 { 0.0 } else { self.cdf[i - 1] };
        (i, p, ((u - below) / p).clamp(0.0, 1.0 - f32::EPSILON / 2.0))
    }

    /// Probability of choosing `i`.
    pub fn pmf(&self, i: usize) -> f32 {
        self.pmf[i]
    }

    /// Number of entries.
    pub fn len(&self) -> usize {
        self.pmf.len()
    }

    /// True when there are no entries (never, for a constructed distribution).
    pub fn is_empty(&self) -> bool {
        self.pmf.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_of_different_items_differ_and_repeat() {
        let mut a = Sampler::new(7, Pass::Camera, 3, 10);
        let mut b = Sampler::new(7, Pass::Camera, 3, 10);
        let mut c = Sampler::new(7, Pass::Camera, 3, 11);
        let va: Vec<f32> = (0..8).map(|_| a.next_f32()).collect();
        let vb: Vec<f32> = (0..8).map(|_| b.next_f32()).collect();
        let vc: Vec<f32> = (0..8).map(|_| c.next_f32()).collect();
        assert_eq!(va, vb);
        assert_ne!(va, vc);
        assert!(va.iter().all(|&x| (0.0..1.0).contains(&x)));
    }

    #[test]
    fn frame_is_orthonormal_for_any_normal() {
        for n in [Vec3::Z, -Vec3::Z, Vec3::X, Vec3::new(0.3, -0.5, 0.8).normalize()] {
            let f = Frame::from_normal(n);
            assert!(f.s.dot(f.t).abs() < 1e-5 && f.s.dot(n).abs() < 1e-5 && f.t.dot(n).abs() < 1e-5);
            assert!((f.s.length() - 1.0).abs() < 1e-5 && (f.t.length() - 1.0).abs() < 1e-5);
        }
    }

    #[test]
    fn a_tangent_frame_takes_the_tangent_perpendicular_to_the_normal_and_is_right_handed() {
        let n = Vec3::new(0.0, 0.196_116, 0.980_581).normalize();
        // Mitsuba 3.9.1 gives this frame for ∂p/∂u = (1, 1, 0) at that shading normal: s = (0.714006,
        // 0.686544, −0.137309), t = (−0.70014, 0.70014, −0.140028).
        let f = Frame::from_normal_tangent(n, Vec3::new(1.0, 1.0, 0.0));
        assert!((f.s - Vec3::new(0.714_006, 0.686_544, -0.137_309)).length() < 1e-5, "{}", f.s);
        assert!((f.t - Vec3::new(-0.700_14, 0.700_14, -0.140_028)).length() < 1e-5, "{}", f.t);
        assert!((f.s.cross(f.t) - n).length() < 1e-5);
        // Turned to the other side the tangent stays, and the frame stays right-handed.
        let b = Frame::from_normal_tangent(-n, Vec3::new(1.0, 1.0, 0.0));
        assert!((b.s - f.s).length() < 1e-6 && (b.s.cross(b.t) + n).length() < 1e-5);
        // A tangent along the normal, a zero one or a NaN one leaves the frame of the normal alone.
        for bad in [n * 3.0, Vec3::ZERO, Vec3::NAN] {
            let g = Frame::from_normal_tangent(n, bad);
            assert_eq!((g.s, g.t), (Frame::from_normal(n).s, Frame::from_normal(n).t));
        }
    }

    #[test]
    fn discrete_distribution_never_picks_zero_weights() {
        let d = Discrete::new(&[0.0, 1.0, 0.0, 3.0]).unwrap();
        for i in 0..1000 {
            let (k, p) = d.sample(i as f32 / 1000.0);
            assert!(k == 1 || k == 3);
            assert!(p > 0.0);
        }
        assert!((d.pmf(3) - 0.75).abs() < 1e-6);
        assert!(Discrete::new(&[0.0, 0.0]).is_none());
    }

    #[test]
    fn a_remapped_draw_is_uniform_within_the_chosen_share() {
        let d = Discrete::new(&[1.0, 0.0, 3.0]).unwrap();
        assert_eq!(d.sample_remapped(0.125), (0, 0.25, 0.5));
        let (i, p, u) = d.sample_remapped(0.625);
        assert_eq!((i, p), (2, 0.75));
        assert!((u - 0.5).abs() < 1e-6, "{u}");
        assert!(d.sample_remapped(0.999_999_9).2 < 1.0);
    }
}
