//! The checks every BSDF family gets, on a family in its local frame (`Model::scatter`): a chi-square test that
//! sampled directions follow `pdf`, agreement of each sample with `eval`, `pdf` and `pdf_stored`, and the
//! albedo by quadrature and by the mean sampled weight, per lobe class (`integrate` computes both integrals).

use glam::{Vec2, Vec3};
use photonfarm::bsdf::{LobeFlags, Scatter, Transport};
use std::f64::consts::PI;

/// A small deterministic stream of uniform numbers (splitmix64), so that the checks are reproducible.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0xD1B5_4A32_D192_ED03)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1) with 24 bits, as the renderer's samplers give.
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 * (1.0 / 16_777_216.0)
    }

    pub fn next_2d(&mut self) -> Vec2 {
        Vec2::new(self.next_f32(), self.next_f32())
    }

    /// A uniform direction on the sphere.
    pub fn direction(&mut self) -> Vec3 {
        let z = 2.0 * self.next_f32() - 1.0;
        let phi = 2.0 * std::f32::consts::PI * self.next_f32();
        let r = (1.0 - z * z).max(0.0).sqrt();
        Vec3::new(r * phi.cos(), r * phi.sin(), z)
    }
}

/// A unit direction with polar angle cos θ = `z` toward azimuth φ.
pub fn direction(z: f64, phi: f64) -> Vec3 {
    let r = (1.0 - z * z).max(0.0).sqrt();
    Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32)
}

/// The unit direction along (x, y, z).
pub fn wo(x: f32, y: f32, z: f32) -> Vec3 {
    Vec3::new(x, y, z).normalize()
}

/// ln Γ(x) for x > 0 (Lanczos, g = 7, n = 9: 15 digits).
pub fn ln_gamma(x: f64) -> f64 {
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        return (PI / (PI * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = C[0];
    let t = x + 7.5;
    for (i, c) in C.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// The regularised upper incomplete gamma function Q(a, x) = Γ(a, x) / Γ(a): by its series below a + 1 and by
/// its continued fraction (modified Lentz) above, as in Numerical Recipes §6.2.
pub fn gamma_q(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    let ln_front = a * x.ln() - x - ln_gamma(a);
    if x < a + 1.0 {
        let (mut sum, mut term, mut n) = (1.0 / a, 1.0 / a, a);
        for _ in 0..10_000 {
            n += 1.0;
            term *= x / n;
            sum += term;
            if term.abs() < sum.abs() * 1e-15 {
                break;
            }
        }
        1.0 - sum * ln_front.exp()
    } else {
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..10_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let delta = d * c;
            h *= delta;
            if (delta - 1.0).abs() < 1e-15 {
                break;
            }
        }
        ln_front.exp() * h
    }
}

/// Bins of the sphere for the chi-square test: uniform in cos θ (equal solid angle) and in φ.
const COS_BINS: usize = 16;
const PHI_BINS: usize = 32;

/// The samples of one family for one `wo`, and what the checks found.
pub struct Sampled {
    /// Counts per (cos θ, φ) bin of the non-delta samples.
    pub histogram: Vec<u64>,
    /// Samples that were deltas or absorbed.
    pub outside: u64,
    pub n: u64,
    /// Sum and sum of squares of every sample's weight (luminance-free: channel 0), of the non-delta ones, and
    /// of those through stored lobes (zero for the others).
    pub all: (f64, f64),
    pub non_delta: (f64, f64),
    pub stored: (f64, f64),
    /// The worst relative disagreement of a sample with eval/pdf (see `sample_and_check`).
    pub worst: f64,
    pub worst_what: String,
}

fn bin_of(d: Vec3) -> usize {
    let c = (((d.z as f64 + 1.0) * 0.5 * COS_BINS as f64) as usize).min(COS_BINS - 1);
    let phi = (d.y as f64).atan2(d.x as f64).rem_euclid(2.0 * PI);
    let p = ((phi / (2.0 * PI) * PHI_BINS as f64) as usize).min(PHI_BINS - 1);
    c * PHI_BINS + p
}

/// Relative difference, with `floor` as the smallest magnitude that counts.
fn rel(a: f64, b: f64, floor: f64) -> f64 {
    (a - b).abs() / a.abs().max(b.abs()).max(floor)
}

/// Draws `n` samples for `wo` and checks every non-delta one against the family's own `eval`, `pdf` and
/// `pdf_stored`: the sample's pdf is `pdf` at its direction, `direct` · pdf = f · |cos|, and `weight` ·
/// pdf_class = f_class · |cos| for the class it took.
pub fn sample_and_check(s: &dyn Scatter, wo: Vec3, mode: Transport, n: u64, seed: u64) -> Sampled {
    let mut rng = Rng::new(seed);
    let mut out = Sampled {
        histogram: vec![0; COS_BINS * PHI_BINS],
        outside: 0,
        n,
        all: (0.0, 0.0),
        non_delta: (0.0, 0.0),
        stored: (0.0, 0.0),
        worst: 0.0,
        worst_what: String::new(),
    };
    let add = |acc: &mut (f64, f64), v: f64| {
        acc.0 += v;
        acc.1 += v * v;
    };
    for i in 0..n {
        let Some(smp) = s.sample(wo, rng.next_2d(), mode) else {
            out.outside += 1;
            continue;
        };
        let w = smp.weight.x as f64;
        assert!(smp.weight.is_finite() && smp.weight.min_element() >= 0.0, "weight {}", smp.weight);
        add(&mut out.all, w);
        if smp.is_delta() {
            out.outside += 1;
            continue;
        }
        assert!((smp.wi.length() - 1.0).abs() < 1e-3, "wi {} not unit", smp.wi);
        out.histogram[bin_of(smp.wi)] += 1;
        add(&mut out.non_delta, w);
        if smp.stored {
            add(&mut out.stored, w);
        }
        if i < 4000 {
            let wi = smp.wi;
            let cos = wi.z.abs() as f64;
            let pdf = s.pdf(wo, wi) as f64;
            let pdf_stored = s.pdf_stored(wo, wi) as f64;
            let pdf_class = if smp.stored { pdf_stored } else { pdf - pdf_stored };
            let f = s.eval(wo, wi, mode, false).x as f64;
            let f_stored = s.eval(wo, wi, mode, true).x as f64;
            let f_class = if smp.stored { f_stored } else { f - f_stored };
            let floor = 1e-3 * (1.0 + smp.pdf as f64);
            for (what, d) in [
                ("pdf() at the sample vs its pdf", rel(pdf, smp.pdf as f64, floor)),
                ("direct · pdf vs f · cos", rel(smp.direct.x as f64 * pdf, f * cos, 1e-4)),
                ("weight · pdf_class vs f_class · cos", rel(w * pdf_class, f_class * cos, 1e-4)),
            ] {
                if d > out.worst {
                    out.worst = d;
                    out.worst_what = format!("{what} at wi {wi}: pdf {pdf} (sample {}), f {f}, weight {w}", smp.pdf);
                }
            }
        }
    }
    out
}

/// The integrals over each bin of the sphere that the checks compare with the samples.
pub struct Integrals {
    /// ∫ pdf over each bin (the probability of a sample landing there).
    pub pdf: Vec<f64>,
    /// ∫ f(wo, wi) |cos θ_i| dω_i over the sphere: every non-delta lobe, and the stored ones alone.
    pub albedo: f64,
    pub albedo_stored: f64,
}

/// Integrates the pdf and f |cos| (all non-delta lobes and the stored ones) over every bin by adaptive
/// Simpson's rule: a cell is split in four where Simpson on its 4 × 4 grid and on the grid's every other node
/// disagree (a sharp lobe varies within it), down to 1/256 of a bin. Bin edges fall on the horizon, where
/// reflection gives way to transmission.
pub fn integrate(s: &dyn Scatter, wo: Vec3, mode: Transport, n: u64) -> Integrals {
    let flags = s.flags();
    let split = flags.contains(LobeFlags::STORED) && flags.contains(LobeFlags::PASS);
    let (dc, dp) = (2.0 / COS_BINS as f64, 2.0 * PI / PHI_BINS as f64);
    let n = n as f64;
    let integrand = |z: f64, phi: f64| -> [f64; 3] {
        let wi = direction(z, phi);
        let f = s.eval(wo, wi, mode, false).x as f64;
        let f_stored = if split { s.eval(wo, wi, mode, true).x as f64 } else { f };
        [s.pdf(wo, wi) as f64, f * z.abs(), f_stored * z.abs()]
    };
    let mut out = Integrals { pdf: vec![0.0; COS_BINS * PHI_BINS], albedo: 0.0, albedo_stored: 0.0 };
    for (c, p) in (0..COS_BINS).flat_map(|c| (0..PHI_BINS).map(move |p| (c, p))) {
        let v = adaptive(&integrand, -1.0 + dc * c as f64, dp * p as f64, dc, dp, n, 4);
        out.pdf[c * PHI_BINS + p] = v[0];
        out.albedo += v[1];
        out.albedo_stored += v[2];
    }
    if !flags.contains(LobeFlags::STORED) {
        out.albedo_stored = 0.0;
    }
    out
}

/// Simpson's rule for the integrand over the cell [z, z + dz] × [φ, φ + dφ], split in four (up to `depth`
/// times) where the 4 × 4 and 2 × 2 rules differ by more than a small share of the expected count's noise
/// (the pdf, for `n` samples) or of the albedo.
fn adaptive(
    integrand: &dyn Fn(f64, f64) -> [f64; 3],
    z: f64,
    phi: f64,
    dz: f64,
    dphi: f64,
    n: f64,
    depth: u32,
) -> [f64; 3] {
    const K: usize = 4;
    let weight = |i: usize, k: usize| -> f64 {
        if i == 0 || i == k {
            1.0
        } else if i % 2 == 1 {
            4.0
        } else {
            2.0
        }
    };
    let (mut fine, mut coarse) = ([0.0; 3], [0.0; 3]);
    for a in 0..=K {
        for b in 0..=K {
            let v = integrand(z + dz * a as f64 / K as f64, phi + dphi * b as f64 / K as f64);
            let w = weight(a, K) * weight(b, K);
            let w2 = if a % 2 == 0 && b % 2 == 0 { weight(a / 2, K / 2) * weight(b / 2, K / 2) } else { 0.0 };
            for i in 0..3 {
                fine[i] += w * v[i];
                coarse[i] += w2 * v[i];
            }
        }
    }
    let area = dz * dphi;
    let fine = fine.map(|x| x * area / (9.0 * (K * K) as f64));
    let coarse = coarse.map(|x| x * area / (9.0 * (K * K / 4) as f64));
    let pdf_off = (fine[0] - coarse[0]).abs() * n > 0.05 * (fine[0] * n).max(1.0).sqrt();
    let f_off = (fine[1] - coarse[1]).abs().max((fine[2] - coarse[2]).abs()) > 1e-3 * area / (4.0 * PI);
    if depth == 0 || !(pdf_off || f_off) {
        return fine;
    }
    let (hz, hp) = (dz / 2.0, dphi / 2.0);
    let mut sum = [0.0; 3];
    for (oz, op) in [(0.0, 0.0), (hz, 0.0), (0.0, hp), (hz, hp)] {
        let v = adaptive(integrand, z + oz, phi + op, hz, hp, n / 4.0, depth - 1);
        for i in 0..3 {
            sum[i] += v[i];
        }
    }
    sum
}

/// The chi-square test of the sampled directions against the pdf's integral over each bin (bins whose expected
/// count is below 5 pooled, the deltas and absorbed samples one more cell); returns the p-value and a
/// description.
pub fn chi_square(integrals: &Integrals, sampled: &Sampled) -> (f64, String) {
    let n = sampled.n as f64;
    let expected: Vec<f64> = integrals.pdf.iter().map(|p| p * n).collect();
    let total: f64 = expected.iter().sum();
    let mut cells: Vec<(f64, f64)> = expected.iter().zip(&sampled.histogram).map(|(&e, &o)| (e, o as f64)).collect();
    cells.push(((n - total).max(0.0), sampled.outside as f64));
    cells.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (mut pooled_e, mut pooled_o, mut chi2, mut dof) = (0.0, 0.0, 0.0, 0usize);
    for (e, o) in cells {
        if e < 5.0 || pooled_e > 0.0 && pooled_e < 5.0 {
            pooled_e += e;
            pooled_o += o;
            continue;
        }
        chi2 += (o - e) * (o - e) / e;
        dof += 1;
    }
    if pooled_e > 0.0 {
        chi2 += (pooled_o - pooled_e).powi(2) / pooled_e.max(1e-9);
        dof += 1;
    }
    let dof = dof.saturating_sub(1).max(1);
    let p = gamma_q(dof as f64 / 2.0, chi2 / 2.0);
    (p, format!("χ² = {chi2:.1} over {dof} degrees of freedom, ∫ pdf = {:.5}, p = {p:.3e}", total / n))
}

/// The mean and its standard error of a sum and sum of squares over `n` samples.
pub fn mean_sem(acc: (f64, f64), n: u64) -> (f64, f64) {
    let n = n as f64;
    let mean = acc.0 / n;
    let var = (acc.1 / n - mean * mean).max(0.0);
    (mean, (var / n).sqrt())
}
