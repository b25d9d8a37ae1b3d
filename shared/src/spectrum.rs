//! Spectral rendering for scenes with dispersion: the CIE 1931 observer, wavelength sampling, the way an RGB
//! quantity is read at one wavelength, refractive indices that vary with wavelength (Cauchy, from an Abbe
//! number), and the colour state of a path, which stays RGB until the path meets a dispersive surface.
//!
//! Colour convention: the equal-energy spectrum is white, i.e. a constant spectrum of value 1 has linear RGB
//! (1, 1, 1), so that white and grey surfaces and lights look the same in RGB and in spectral rendering.

use crate::color::Rgb;
use crate::sampling::Sampler;
use glam::{Mat3, Vec3};
use std::sync::OnceLock;

/// Whether this build renders spectrally (the `spectral` feature). Without it every path stays RGB and the
/// branches below fold away at compile time.
pub const ENABLED: bool = cfg!(feature = "spectral");

/// Shortest wavelength rendered (nm).
pub const LAMBDA_MIN: f32 = 380.0;
/// Longest wavelength rendered (nm).
pub const LAMBDA_MAX: f32 = 780.0;

/// The Fraunhofer lines that define a glass's Abbe number V_d = (n_d − 1) / (n_F − n_C), in µm.
const LAMBDA_D: f32 = 0.587_56;
const LAMBDA_F: f32 = 0.486_13;
const LAMBDA_C: f32 = 0.656_27;

/// A piecewise Gaussian with different widths left and right of its peak (Wyman, Sloan, Shirley 2013).
fn lobe(lambda: f32, mu: f32, sigma_left: f32, sigma_right: f32) -> f32 {
    let t = (lambda - mu) / if lambda < mu { sigma_left } else { sigma_right };
    (-0.5 * t * t).exp()
}

/// CIE 1931 2° colour-matching functions x̄, ȳ, z̄ at `lambda` nm, by the multi-lobe fit of Wyman, Sloan and
/// Shirley, "Simple Analytic Approximations to the CIE XYZ Color Matching Functions", JCGT 2(2), 2013.
pub fn cie_xyz(lambda: f32) -> Vec3 {
    let x = 1.056 * lobe(lambda, 599.8, 37.9, 31.0) + 0.362 * lobe(lambda, 442.0, 16.0, 26.7)
        - 0.065 * lobe(lambda, 501.1, 20.4, 26.2);
    let y = 0.821 * lobe(lambda, 568.8, 46.9, 40.5) + 0.286 * lobe(lambda, 530.9, 16.3, 31.1);
    let z = 1.217 * lobe(lambda, 437.0, 11.8, 36.0) + 0.681 * lobe(lambda, 459.0, 26.0, 13.8);
    Vec3::new(x, y, z)
}

/// CIE XYZ to linear Rec.709 (sRGB primaries, D65), IEC 61966-2-1.
fn xyz_to_linear_rgb() -> Mat3 {
    Mat3::from_cols(
        Vec3::new(3.2406, -0.9689, 0.0557),
        Vec3::new(-1.5372, 1.8758, -0.2040),
        Vec3::new(-0.4986, 0.0415, 1.0570),
    )
}

/// Three wavelength bands that an RGB reflectance or emission is spread over when read spectrally: blue,
/// green, red. The edges keep the basis matrix close to diagonal (see `Tables`).
const BAND_EDGES: [f32; 2] = [490.0, 585.0];

fn band_of(lambda: f32) -> usize {
    if lambda < BAND_EDGES[0] {
        0
    } else if lambda < BAND_EDGES[1] {
        1
    } else {
        2
    }
}

/// Integrals computed once: the white normalisation of the RGB matching functions and the inverse of the
/// band basis.
struct Tables {
    /// Per-channel scale that maps the equal-energy spectrum to RGB (1, 1, 1).
    white_scale: Vec3,
    /// Row `b` gives the height of band `b`'s box for an RGB triple: heights = rows · rgb.
    uplift_rows: [Vec3; 3],
}

/// Midpoint-rule step (nm) for the integrals over the visible range.
const STEP: f32 = 0.5;

fn tables() -> &'static Tables {
    static TABLES: OnceLock<Tables> = OnceLock::new();
    TABLES.get_or_init(|| {
        let m = xyz_to_linear_rgb();
        let steps = ((LAMBDA_MAX - LAMBDA_MIN) / STEP) as usize;
        let mut white = Vec3::ZERO;
        // Column b: RGB (before white scaling) of band b's unit box.
        let mut band_rgb = [Vec3::ZERO; 3];
        for i in 0..steps {
            let lambda = LAMBDA_MIN + (i as f32 + 0.5) * STEP;
            let rgb = m * cie_xyz(lambda) * STEP;
            white += rgb;
            band_rgb[band_of(lambda)] += rgb;
        }
        let white_scale = Vec3::ONE / white;
        // basis[b] = RGB of band b's box: the matrix B with rgb = B · heights. Its columns sum to (1, 1, 1), so
        // B⁻¹ maps grey g to heights (g, g, g): a grey stays a flat spectrum.
        let basis = Mat3::from_cols(band_rgb[0] * white_scale, band_rgb[1] * white_scale, band_rgb[2] * white_scale);
        let inverse = basis.inverse();
        let rows = [inverse.row(0), inverse.row(1), inverse.row(2)];
        Tables { white_scale, uplift_rows: rows }
    })
}

/// Normalised RGB matching functions at `lambda`: ∫ rgb̄(λ) dλ over the visible range is (1, 1, 1).
pub fn rgb_matching(lambda: f32) -> Rgb {
    xyz_to_linear_rgb() * cie_xyz(lambda) * tables().white_scale
}

/// The sampling density's shape, sech²(a(λ − 538 nm)): close to the sum of the matching functions, so that
/// every wavelength's contribution has similar luminance (Radziszewski, Boryczko, Alda 2009).
const SECH_A: f32 = 0.0072;
const SECH_CENTRE: f32 = 538.0;

fn tanh_range() -> (f32, f32) {
    ((SECH_A * (LAMBDA_MIN - SECH_CENTRE)).tanh(), (SECH_A * (LAMBDA_MAX - SECH_CENTRE)).tanh())
}

/// Density over [LAMBDA_MIN, LAMBDA_MAX] (per nm) with which `Wavelength::sample` draws `lambda`.
pub fn wavelength_pdf(lambda: f32) -> f32 {
    if !(LAMBDA_MIN..=LAMBDA_MAX).contains(&lambda) {
        return 0.0;
    }
    let (t0, t1) = tanh_range();
    let c = (SECH_A * (lambda - SECH_CENTRE)).cosh();
    SECH_A / ((t1 - t0) * c * c)
}

/// One sampled wavelength and what turns a spectral value at it into an image contribution.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Wavelength {
    /// Wavelength in nm.
    pub nm: f32,
    /// Density it was drawn with (per nm).
    pub pdf: f32,
    /// rgb̄(λ) / pdf: a spectral radiance value at λ times this is an unbiased estimate of its RGB.
    to_rgb: Rgb,
    /// Row of the band basis's inverse for λ's band.
    uplift: Rgb,
}

impl Wavelength {
    /// Draws a wavelength from the sech² density with one uniform number.
    pub fn sample(u: f32) -> Self {
        let (t0, t1) = tanh_range();
        let t = t0 + u.clamp(0.0, 1.0) * (t1 - t0);
        let nm = (SECH_CENTRE + t.atanh() / SECH_A).clamp(LAMBDA_MIN, LAMBDA_MAX);
        Self::with_pdf(nm, wavelength_pdf(nm))
    }

    /// A wavelength taken with a given density (a test or a stratified sweep may fix it).
    pub fn with_pdf(nm: f32, pdf: f32) -> Self {
        let tables = tables();
        Wavelength { nm, pdf, to_rgb: rgb_matching(nm) / pdf, uplift: tables.uplift_rows[band_of(nm)] }
    }

    /// The spectral value at this wavelength of an RGB reflectance, emission or throughput: the height of its
    /// band in the three-band spectrum whose RGB is the triple (clamped at zero for colours outside the
    /// bands' gamut). Grey g reads g at every wavelength.
    #[inline]
    pub fn value_of(&self, c: Rgb) -> f32 {
        self.uplift.dot(c).max(0.0)
    }

    /// The image contribution (linear RGB) of spectral value `s` at this wavelength.
    #[inline]
    pub fn to_rgb(&self, s: f32) -> Rgb {
        self.to_rgb * s
    }
}

/// A refractive index that may vary with wavelength: Cauchy's two-term law n(λ) = A + B/λ², written with the
/// index at the d line, n(λ) = n_d + B (1/λ² − 1/λ_d²).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RefractiveIndex {
    /// Index at the helium d line, 587.56 nm.
    pub d: f32,
    /// Cauchy's B in µm² (zero: no dispersion).
    pub b: f32,
}

impl RefractiveIndex {
    /// A wavelength-independent index.
    pub const fn constant(n: f32) -> Self {
        RefractiveIndex { d: n, b: 0.0 }
    }

    /// The Cauchy index with n_d and Abbe number V_d: B = (n_d − 1) / (V_d (1/λ_F² − 1/λ_C²)).
    pub fn from_abbe(n_d: f32, abbe: f32) -> Self {
        let b = (n_d - 1.0) / (abbe * (1.0 / (LAMBDA_F * LAMBDA_F) - 1.0 / (LAMBDA_C * LAMBDA_C)));
        RefractiveIndex { d: n_d, b }
    }

    /// True when the index varies with wavelength.
    pub fn is_dispersive(&self) -> bool {
        self.b != 0.0
    }

    /// The index at `nm` nanometres.
    pub fn at(&self, nm: f32) -> f32 {
        let um = nm * 1e-3;
        self.d + self.b * (1.0 / (um * um) - 1.0 / (LAMBDA_D * LAMBDA_D))
    }
}

/// Wavelengths drawn per phase. Camera paths (by pixel) and light paths (by index) are dealt into this many
/// classes, each with its own wavelength, so that one phase does not colour a whole region alike.
pub const PHASE_WAVELENGTHS: usize = 4;

/// The wavelengths of one phase of a spectral scene, one per class.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PhaseSpectrum {
    /// The wavelength each class adopts when its paths meet dispersion; None in an RGB scene.
    pub wavelengths: Option<[Wavelength; PHASE_WAVELENGTHS]>,
    /// Every path is spectral from its first vertex (spectral output asked for), not only after dispersion.
    pub from_start: bool,
}

impl PhaseSpectrum {
    /// An RGB phase: no path ever becomes spectral.
    pub const RGB: PhaseSpectrum = PhaseSpectrum { wavelengths: None, from_start: false };

    /// Draws the phase's wavelengths, stratified: a random rotation deals the density's strata to the classes,
    /// so each class's wavelength follows the whole density (phases stay independent, as δ assumes) while the
    /// phase as a whole covers the spectrum evenly.
    pub fn sample(sampler: &mut Sampler, from_start: bool) -> Self {
        let k = PHASE_WAVELENGTHS;
        let rotation = ((sampler.next_f32() * k as f32) as usize).min(k - 1);
        let wavelengths = std::array::from_fn(|class| {
            let stratum = (class + rotation) % k;
            Wavelength::sample((stratum as f32 + sampler.next_f32()) / k as f32)
        });
        PhaseSpectrum { wavelengths: Some(wavelengths), from_start }
    }

    /// The class of a camera path (by pixel) or light path (by index).
    #[inline]
    pub fn class_of(item: u64) -> u8 {
        (item % PHASE_WAVELENGTHS as u64) as u8
    }

    /// The wavelength of a class, in a spectral scene.
    #[inline]
    pub fn wavelength(&self, class: u8) -> Option<Wavelength> {
        self.wavelengths.map(|w| w[class as usize % PHASE_WAVELENGTHS])
    }
}

/// What a path's colour state needs to know of a surface it scatters from: whether the surface's behaviour
/// depends on wavelength, and how it looks at one wavelength. Materials implement it; this module needs nothing
/// else of them.
pub trait Dispersive: Sized {
    /// True when the behaviour depends on wavelength: a path that meets it becomes spectral.
    fn is_dispersive(&self) -> bool;

    /// The surface as a path at one wavelength sees it.
    fn at_wavelength(&self, w: &Wavelength) -> Self;
}

/// The colour state of one path: RGB, or spectral at its class's wavelength once the path met a dispersive
/// surface (its throughput then holds the spectral value in all three channels). `S` is false in the
/// integrators' instantiation for RGB phases, where every method below folds to the RGB case at compile time.
#[derive(Clone, Copy, Debug)]
pub struct PathSpectrum<const S: bool> {
    wavelength: Option<Wavelength>,
    class: u8,
    spectral: bool,
}

impl<const S: bool> PathSpectrum<S> {
    /// The state of a path of `class` starting with throughput `beta`, converted if the path is spectral from
    /// the start.
    pub fn start(phase: &PhaseSpectrum, class: u8, beta: &mut Rgb) -> Self {
        let wavelength = if S && ENABLED { phase.wavelength(class) } else { None };
        let mut path = PathSpectrum { wavelength, class, spectral: false };
        if phase.from_start {
            if let Some(w) = path.wavelength {
                path.spectral = true;
                *beta = Rgb::splat(w.value_of(*beta));
            }
        }
        path
    }

    /// True once the path carries one wavelength.
    #[inline]
    pub fn is_spectral(&self) -> bool {
        S && ENABLED && self.spectral
    }

    /// The wavelength the path is carried at, once it is spectral.
    #[inline]
    pub fn wavelength_nm(&self) -> Option<f32> {
        self.wavelength.filter(|_| self.is_spectral()).map(|w| w.nm)
    }

    /// What a stored vertex records of the path's colour: 0 for RGB, 1 + class once spectral (see `join`).
    #[inline]
    pub fn tag(&self) -> u8 {
        if self.is_spectral() {
            self.class + 1
        } else {
            0
        }
    }

    /// The material a path scatters from: at a dispersive surface an RGB path turns spectral (its throughput
    /// `beta` read at the wavelength); a spectral path sees every material at its wavelength.
    #[inline]
    pub fn material<M: Dispersive>(&mut self, m: M, beta: &mut Rgb) -> M {
        if !(S && ENABLED) {
            return m;
        }
        let Some(w) = self.wavelength else { return m };
        if !self.spectral {
            if !m.is_dispersive() {
                return m;
            }
            self.spectral = true;
            *beta = Rgb::splat(w.value_of(*beta));
        }
        m.at_wavelength(&w)
    }

    /// An RGB radiometric quantity met along the path (emitted radiance, incident light) in the path's terms.
    #[inline]
    pub fn quantity(&self, c: Rgb) -> Rgb {
        match (self.is_spectral(), self.wavelength) {
            (true, Some(w)) => Rgb::splat(w.value_of(c)),
            _ => c,
        }
    }

    /// A contribution in the path's terms as linear RGB for the image.
    #[inline]
    pub fn to_image(&self, c: Rgb) -> Rgb {
        match (self.is_spectral(), self.wavelength) {
            (true, Some(w)) => w.to_rgb(c.x),
            _ => c,
        }
    }
}

/// Most wavelength bands `--spectral-output` may ask for: 1 nm each.
pub const MAX_BANDS: u32 = 400;

/// The name of band `b` of `bands` (its EXR layer), e.g. "band_380-390nm".
pub fn band_name(b: u32, bands: u32) -> String {
    let width = (LAMBDA_MAX - LAMBDA_MIN) / bands as f32;
    let (lo, hi) = (LAMBDA_MIN + b as f32 * width, LAMBDA_MIN + (b + 1) as f32 * width);
    format!("band_{}-{}nm", lo.round() as u32, hi.round() as u32)
}

/// A pixel's spectral-output values for one phase, when its whole phase value `total` was carried at one
/// wavelength `w` (every path spectral from the start): its spectral value at λ is total · v / (v · v) with
/// v = rgb̄(λ)/p(λ), and the band holding λ gets that value over p(λ) Δλ — over phases an unbiased estimate of
/// the spectrum averaged over the band (a flat spectrum of value 1 reads 1 in every band). Other bands get 0.
pub fn band_values(total: Rgb, w: &Wavelength, out: &mut [f32]) {
    out.fill(0.0);
    let bands = out.len();
    let v = w.to_rgb;
    let vv = v.dot(v);
    let usable = vv > 0.0 && w.pdf > 0.0;
    if bands == 0 || !usable {
        return;
    }
    let width = (LAMBDA_MAX - LAMBDA_MIN) / bands as f32;
    let b = (((w.nm - LAMBDA_MIN) / width) as usize).min(bands - 1);
    out[b] = total.dot(v) / vv / (w.pdf * width);
}

/// Joins a camera-path weight and a light-path flux into an image contribution (paper eq. 4's τ · ΔΦ). Each
/// side is RGB (tag 0) or spectral at its class's wavelength (tag 1 + class). An RGB side is read at the
/// other's wavelength. Two spectral sides join only within one class: a camera path meets 1/K of the light
/// paths at its wavelength, so the join counts K times, which keeps the estimate unbiased.
#[inline]
pub fn join(weight: Rgb, weight_tag: u8, flux: Rgb, flux_tag: u8, phase: &PhaseSpectrum) -> Rgb {
    if !ENABLED {
        return weight * flux;
    }
    let at = |tag: u8| phase.wavelength(tag - 1);
    match (weight_tag, flux_tag) {
        (0, 0) => weight * flux,
        (c, 0) => match at(c) {
            Some(w) => w.to_rgb(weight.x * w.value_of(flux)),
            None => weight * flux,
        },
        (0, c) => match at(c) {
            Some(w) => w.to_rgb(w.value_of(weight) * flux.x),
            None => weight * flux,
        },
        (a, b) if a == b => match at(a) {
            Some(w) => w.to_rgb(weight.x * flux.x * PHASE_WAVELENGTHS as f32),
            None => weight * flux,
        },
        _ => Rgb::ZERO,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn integrate(f: impl Fn(f32) -> Vec3) -> Vec3 {
        let n = ((LAMBDA_MAX - LAMBDA_MIN) / STEP) as usize;
        (0..n).map(|i| f(LAMBDA_MIN + (i as f32 + 0.5) * STEP) * STEP).sum()
    }

    #[test]
    fn colour_matching_fit_has_the_cie_peak_and_areas() {
        assert!((cie_xyz(555.0).y - 1.0).abs() < 0.01, "ȳ(555 nm) = {}", cie_xyz(555.0).y);
        let area = integrate(cie_xyz);
        // CIE 1931: ∫x̄ ≈ ∫ȳ ≈ ∫z̄ ≈ 106.86 nm (equal-energy white at x = y = 1/3).
        for a in area.to_array() {
            assert!((a - 106.86).abs() < 0.02 * 106.86, "areas {area}");
        }
    }

    #[test]
    fn equal_energy_spectrum_is_rgb_white() {
        let white = integrate(rgb_matching);
        assert!((white - Vec3::ONE).abs().max_element() < 1e-3, "{white}");
    }

    #[test]
    fn sampled_wavelengths_estimate_the_white_spectrum_without_bias() {
        // E[rgb̄(λ)/p(λ)] over the sampling density must be (1, 1, 1): stratified u makes this a quadrature.
        let n = 20_000;
        let mut sum = Rgb::ZERO;
        for i in 0..n {
            let w = Wavelength::sample((i as f32 + 0.5) / n as f32);
            assert!((LAMBDA_MIN..=LAMBDA_MAX).contains(&w.nm) && w.pdf > 0.0);
            sum += w.to_rgb(1.0);
        }
        let mean = sum / n as f32;
        assert!((mean - Vec3::ONE).abs().max_element() < 2e-3, "{mean}");
        // The density integrates to one.
        let total: f32 = integrate(|l| Vec3::splat(wavelength_pdf(l))).x;
        assert!((total - 1.0).abs() < 1e-3, "{total}");
    }

    #[test]
    fn grey_reads_the_same_at_every_wavelength_and_colours_round_trip() {
        for nm in [400.0, 480.0, 500.0, 560.0, 600.0, 700.0] {
            let w = Wavelength::with_pdf(nm, 1.0);
            assert!((w.value_of(Rgb::splat(0.37)) - 0.37).abs() < 1e-5, "{nm}");
        }
        // A colour inside the bands' gamut comes back as itself: Σ over wavelengths of value · rgb̄ / p.
        for c in [Rgb::new(0.6, 0.4, 0.3), Rgb::new(0.3, 0.5, 0.4), Rgb::new(0.25, 0.3, 0.6)] {
            let n = 20_000;
            let mut sum = Rgb::ZERO;
            for i in 0..n {
                let w = Wavelength::sample((i as f32 + 0.5) / n as f32);
                sum += w.to_rgb(w.value_of(c));
            }
            let back = sum / n as f32;
            assert!((back - c).abs().max_element() < 5e-3, "{c} came back as {back}");
        }
    }

    #[test]
    fn abbe_number_gives_the_glass_its_f_and_c_line_indices() {
        // Schott N-BK7: n_d 1.5168, V_d 64.17; catalogue n_F 1.52238, n_C 1.51432.
        let bk7 = RefractiveIndex::from_abbe(1.5168, 64.17);
        let (nf, nc) = (bk7.at(486.13), bk7.at(656.27));
        assert!((bk7.at(587.56) - 1.5168).abs() < 1e-6);
        assert!(((bk7.d - 1.0) / (nf - nc) - 64.17).abs() < 0.01);
        assert!((nf - 1.52238).abs() < 3e-4 && (nc - 1.51432).abs() < 3e-4, "n_F {nf}, n_C {nc}");
        assert!(!RefractiveIndex::constant(1.5).is_dispersive() && bk7.is_dispersive());
    }

    #[test]
    #[cfg(feature = "spectral")]
    fn rgb_joins_stay_rgb_and_spectral_joins_go_through_the_class_wavelength() {
        let mut sampler = Sampler::new(1, crate::sampling::Pass::Wavelength, 1, 0);
        let phase = PhaseSpectrum::sample(&mut sampler, false);
        let (a, b) = (Rgb::new(0.5, 0.25, 0.125), Rgb::new(2.0, 4.0, 8.0));
        assert_eq!(join(a, 0, b, 0, &phase), a * b);
        assert_eq!(join(a, 0, b, 0, &PhaseSpectrum::RGB), a * b);
        let w = phase.wavelength(2).unwrap();
        let s = join(Rgb::splat(0.5), 3, b, 0, &phase);
        assert!((s - w.to_rgb(0.5 * w.value_of(b))).abs().max_element() < 1e-6);
        // Two spectral sides: only within a class, counted K times.
        assert_eq!(join(Rgb::splat(0.5), 3, Rgb::splat(2.0), 2, &phase), Rgb::ZERO);
        let s = join(Rgb::splat(0.5), 3, Rgb::splat(2.0), 3, &phase);
        assert!((s - w.to_rgb(PHASE_WAVELENGTHS as f32)).abs().max_element() < 1e-5);
    }

    #[test]
    fn spectral_output_bands_read_a_flat_spectrum_as_one_in_every_band() {
        // A path that carried the flat spectrum 1 at λ: its image value is to_rgb(1). Averaged over the
        // sampling density, every band must read 1.
        let bands = 8;
        let n = 40_000;
        let mut sum = vec![0.0f64; bands];
        let mut out = vec![0.0f32; bands];
        for i in 0..n {
            let w = Wavelength::sample((i as f32 + 0.5) / n as f32);
            band_values(w.to_rgb(1.0), &w, &mut out);
            for (s, v) in sum.iter_mut().zip(&out) {
                *s += *v as f64;
            }
        }
        for (b, s) in sum.iter().enumerate() {
            assert!((s / n as f64 - 1.0).abs() < 2e-3, "band {} reads {}", band_name(b as u32, 8), s / n as f64);
        }
        assert_eq!(band_name(0, 8), "band_380-430nm");
        assert_eq!(band_name(7, 8), "band_730-780nm");
    }

    #[test]
    fn a_phase_covers_every_stratum_and_each_class_follows_the_whole_density() {
        let k = PHASE_WAVELENGTHS;
        let mut counts = vec![vec![0u32; k]; k];
        let (t0, t1) = tanh_range();
        let stratum = |nm: f32| {
            let u = ((SECH_A * (nm - SECH_CENTRE)).tanh() - t0) / (t1 - t0);
            ((u * k as f32) as usize).min(k - 1)
        };
        let phases = 4000;
        for i in 0..phases {
            let mut sampler = Sampler::new(3, crate::sampling::Pass::Wavelength, i, 0);
            let phase = PhaseSpectrum::sample(&mut sampler, false);
            let mut seen: Vec<usize> = (0..k).map(|c| stratum(phase.wavelength(c as u8).unwrap().nm)).collect();
            for (c, &s) in seen.iter().enumerate() {
                counts[c][s] += 1;
            }
            seen.sort();
            assert_eq!(seen, (0..k).collect::<Vec<_>>(), "phase {i} misses a stratum");
        }
        // Each class lands in each stratum a quarter of the time (binomial, 5 σ).
        let expected = phases as f64 / k as f64;
        let sigma = (expected * (1.0 - 1.0 / k as f64)).sqrt();
        for row in &counts {
            for &n in row {
                assert!((n as f64 - expected).abs() < 5.0 * sigma, "{counts:?}");
            }
        }
    }
}
