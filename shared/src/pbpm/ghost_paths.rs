//! Ghost paths (docs/estimator.md, "The ghost layer"): light paths that look only for the ghost chains a sensor
//! camera's lens makes. Each is sent to reflect at one pair of the scene's dielectric surfaces, drawn from a
//! table the scene keeps (`crate::scene::ghost::GhostPairs`, filled by this file's pilot), as lens-design
//! software traces a lens's ghosts pair by pair: every chain of a pair then carries nearly the same weight,
//! where a path free to reflect anywhere carries weights that differ by the number of surfaces it crossed.

use super::forward_pass::{register_crossing, Crossing, ForwardStats, LightEvent, LightSettings};
use crate::bsdf::{Bsdf, BsdfSample, Reflection, Transport};
use crate::color::{luminance, Rgb};
use crate::geometry::{ray::offset_origin, Ray, SurfaceHit};
use crate::integrator::walk::{walk, Technique, Walk};
use crate::light::ghost_aim::{AimGrid, RINGS, SECTORS};
use crate::light::{disc_crossing, AimDensity, EmissionSample, UniformAim};
use crate::ray_map::{PathKind, PathLog, RecordedPath, Recorder, Unrecorded};
use crate::sampling::{Pass, Sampler};
use crate::scene::ghost::{ghost_paths, GhostPair, GhostPairs};
use crate::scene::Scene;
use crate::spectrum::{PathSpectrum, PhaseSpectrum};
use glam::Vec3;
use rayon::prelude::*;

/// The share of a ghost path's emission aimed at the lens's front element: ghosts reach the sensor through it.
pub const GHOST_AIMED_FRACTION: f32 = 0.9;

/// The probability, unless F is higher, with which a ghost path reflects at the surface its pair names next.
/// Below 1, so that a chain crossing that surface before it reflects there can still be sampled.
pub const PAIR_REFLECTION: f32 = 0.95;

/// The share of the pair table spread evenly over every pair: a pair the pilot saw bring nothing keeps a
/// probability, so the ghost layer stays unbiased whatever the pilot missed.
pub const EVEN_SHARE: f32 = 0.2;

/// Ghost paths the table's pilot traces in all, spread over the pairs, and the fewest it traces per pair: enough
/// that each pair's aim grid sees a few paths per cell.
const PILOT_PATHS: usize = 1 << 17;
const PILOT_PATHS_PER_PAIR: usize = 256;

/// How a ghost path of `pair` that has reflected `reflections` times chooses at a dielectric `object`.
///
/// Before its pair's last reflection it reflects only at the surface the pair names next (with probability
/// `PAIR_REFLECTION`) and refracts everywhere else, so each chain's first two reflections are sampled by exactly
/// one pair; after its second reflection it follows F, so longer chains belong to the pair of their first two
/// reflections. A one-reflection pair refracts everywhere after its reflection.
fn pair_choice(pair: &GhostPair, reflections: u32, object: u32) -> Reflection {
    let next = match reflections {
        0 => Some(pair.first),
        1 => match pair.second {
            Some(second) => Some(second),
            None => return Reflection::Never,
        },
        _ => return Reflection::Fresnel,
    };
    if next == Some(object) {
        Reflection::AtLeast(PAIR_REFLECTION)
    } else {
        Reflection::Never
    }
}

/// The ghost pairs of `scene` (`GhostPairs`), from its pilot, run on the first call for the scene and kept
/// with it; None when the scene traces no ghost paths or has no dielectric surface.
///
/// The pilot is decided by the scene alone (the same in every process). It traces ghost paths of each pair
/// aimed evenly and gives each cell of the pair's grid a weight proportional to the root of the mean square of
/// what a path through it registers, the density that minimises the sum of the pixels' variances; the pair
/// gets a share proportional to the root of the mean square one path registers with that density.
/// `EVEN_SHARE` of the table is spread over all pairs.
///
/// The pilot runs in parallel: call this before a stage's parallel work (as `RenderSettings::phase` does),
/// not first from inside it, where a thread waiting for the table could be the one computing it.
pub fn ghost_pairs(scene: &Scene) -> Option<&GhostPairs> {
    scene.ghost_pairs.get_or_init(|| if ghost_paths(scene) > 0 { pilot_table(scene) } else { None }).as_ref()
}

/// The table of `scene` from a fresh pilot; None when the scene has no dielectric surface.
fn pilot_table(scene: &Scene) -> Option<GhostPairs> {
    let pairs = GhostPair::all_of(scene);
    if pairs.is_empty() {
        return None;
    }
    let pilots = pilot(scene, &pairs);
    let weights: Vec<f64> = pilots.iter().map(PairPilot::root_mean_square).collect();
    let aims = pilots.iter().map(PairPilot::aim).collect();
    let total: f64 = weights.iter().sum();
    let n = pairs.len() as f64;
    let probabilities: Vec<f32> = weights
        .iter()
        .map(|w| if total > 0.0 { (1.0 - EVEN_SHARE as f64) * w / total + EVEN_SHARE as f64 / n } else { 1.0 / n })
        .map(|p| p as f32)
        .collect();
    GhostPairs::new(pairs, aims, &probabilities)
}

/// Cells of a pair's grid over the front element.
const AIM_CELLS: usize = RINGS * SECTORS;

/// What one pair's pilot paths registered: the sum of the squares of their luminance and the paths per cell of
/// the front element they aimed at, and the sum for the paths that left by the cosine and missed it.
struct PairPilot {
    paths: usize,
    squares: [f64; AIM_CELLS],
    through: [u32; AIM_CELLS],
    elsewhere: f64,
}

impl PairPilot {
    /// The cells' weights: the root of the mean square a path through each registered.
    fn roots(&self) -> [f64; AIM_CELLS] {
        std::array::from_fn(
            |c| if self.through[c] > 0 { (self.squares[c] / self.through[c] as f64).sqrt() } else { 0.0 },
        )
    }

    /// Where the pair's paths aim: the cells in proportion to their roots (`AimGrid::from_weights`).
    fn aim(&self) -> AimGrid {
        AimGrid::from_weights(&self.roots())
    }

    /// The root of the mean square one path of the pair registers when it aims by its grid, as the pilot
    /// estimates it: the mean of the cells' roots (each cell is the same share of the disc), and the paths
    /// that missed the disc as they were.
    fn root_mean_square(&self) -> f64 {
        self.roots().iter().sum::<f64>() / AIM_CELLS as f64 + (self.elsewhere / self.paths as f64).sqrt()
    }
}

/// Each pair's pilot: pseudo-random ghost paths of fixed seeds in RGB, aimed evenly at the front element.
fn pilot(scene: &Scene, pairs: &[GhostPair]) -> Vec<PairPilot> {
    let per_pair = (PILOT_PATHS / pairs.len()).max(PILOT_PATHS_PER_PAIR);
    let settings = LightSettings { max_depth: scene.render.max_depth, sensor: true, vertices: false, ghost_paths: 1 };
    let front = scene.lights.aim();
    pairs
        .par_iter()
        .enumerate()
        .map(|(p, &pair)| {
            let mut stats = ForwardStats::default();
            let mut pilot =
                PairPilot { paths: per_pair, squares: [0.0; AIM_CELLS], through: [0; AIM_CELLS], elsewhere: 0.0 };
            for i in 0..per_pair {
                let mut sampler = Sampler::new(0, Pass::Ghost, u64::MAX - p as u64, i as u64);
                let Some(e) = emit(scene, &UniformAim, &mut sampler) else { continue };
                let mut registered = 0.0f64;
                let mut visit = |e: &LightEvent| {
                    if let LightEvent::Sensor(hit) = e {
                        registered += luminance(hit.value) as f64;
                    }
                };
                let start = GhostStart { emission: e, index: 0, pair, weight: 1.0 };
                let spectrum = &PhaseSpectrum::RGB;
                let log = &mut Unrecorded;
                ghost_path::<false, _>(scene, settings, spectrum, start, &mut sampler, &mut stats, &mut visit, log);
                let square = registered * registered;
                match front.and_then(|d| disc_crossing(&d, e.origin, e.direction)) {
                    Some((point, _)) => {
                        let c = AimGrid::cell_of(point);
                        pilot.squares[c] += square;
                        pilot.through[c] += 1;
                    }
                    None => pilot.elsewhere += square,
                }
            }
            pilot
        })
        .collect()
}

/// A ghost path's start: a light chosen by power, a point on it, and `GHOST_AIMED_FRACTION` of an area light's
/// paths aimed at the front element at points drawn from `density`.
#[inline]
fn emit(scene: &Scene, density: &impl AimDensity, sampler: &mut Sampler) -> Option<EmissionSample> {
    let u_select = sampler.next_f32();
    let (u_pos, u_dir) = (sampler.next_2d(), sampler.next_2d());
    scene.lights.sample_emission_aimed(&scene.geometry, u_select, u_pos, u_dir, GHOST_AIMED_FRACTION, density)
}

/// Traces the `settings.ghost_paths` ghost paths of light path `index` of the phase with random key `key`,
/// handing each ghost chain that reaches the sensor to `visit` worth 1 / `ghost_paths` of itself, so that the
/// ghost layer is normalised by the phase's light paths as every gather is.
///
/// A ghost path draws its pair of reflecting surfaces from the scene's table and counts 1 / (the pair's
/// probability); its light leaves toward the front element with probability `GHOST_AIMED_FRACTION`; it takes
/// its pair's reflections (`pair_choice`, each choice weighted so that the chain keeps its value) and
/// registers where it crosses the sensor once it has them; it ends at its first diffuse vertex. It has no
/// roulette: all-specular chains are short and `max_depth` bounds them.
///
/// With `record` (a ray map's recorder and the phase's number), each ghost path is recorded as a light path
/// numbered as the light path it belongs to, its weight being what it registered.
#[allow(clippy::too_many_arguments)]
pub fn trace_ghost_paths(
    scene: &Scene,
    settings: LightSettings,
    spectrum: &PhaseSpectrum,
    index: u64,
    seed: u64,
    key: u64,
    stats: &mut ForwardStats,
    visit: &mut impl FnMut(&LightEvent),
    record: Option<(&Recorder, u64)>,
) {
    let k = settings.ghost_paths as u64;
    if k == 0 {
        return;
    }
    let Some(pairs) = ghost_pairs(scene) else { return };
    let mut log = record.map(|(_, phase)| RecordedPath::new(PathKind::Light, phase as u32, index as u32, 0));
    for j in 0..k {
        let ghost = index * k + j;
        let mut sampler = Sampler::ghost(seed, key, ghost);
        let (pair, p, aim) = pairs.sample(sampler.next_f32());
        let weight = 1.0 / (p * k as f32);
        let Some(emission) = emit(scene, aim, &mut sampler) else { continue };
        let start = GhostStart { emission, index: ghost, pair, weight };
        let spectral = spectrum.wavelengths.is_some();
        match (&mut log, spectral) {
            (Some(log), true) => {
                ghost_path::<true, _>(scene, settings, spectrum, start, &mut sampler, stats, visit, log)
            }
            (Some(log), false) => {
                ghost_path::<false, _>(scene, settings, spectrum, start, &mut sampler, stats, visit, log)
            }
            (None, true) => {
                ghost_path::<true, _>(scene, settings, spectrum, start, &mut sampler, stats, visit, &mut Unrecorded)
            }
            (None, false) => {
                ghost_path::<false, _>(scene, settings, spectrum, start, &mut sampler, stats, visit, &mut Unrecorded)
            }
        }
        if let (Some((recorder, _)), Some(log)) = (record, &log) {
            recorder.record(log);
        }
    }
}

/// What a ghost path starts from: its emission, its number among the phase's ghost paths (its wavelength class),
/// its pair, and the factor its emitted flux is multiplied by.
#[derive(Clone, Copy, Debug)]
struct GhostStart {
    emission: EmissionSample,
    index: u64,
    pair: GhostPair,
    weight: f32,
}

/// One ghost path from `start`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn ghost_path<const S: bool, L: PathLog>(
    scene: &Scene,
    settings: LightSettings,
    spectrum: &PhaseSpectrum,
    start: GhostStart,
    sampler: &mut Sampler,
    stats: &mut ForwardStats,
    visit: &mut impl FnMut(&LightEvent),
    log: &mut L,
) {
    let GhostStart { emission: e, index, pair, weight } = start;
    let origin = if e.normal == Vec3::ZERO { e.origin } else { offset_origin(e.origin, e.normal, e.direction) };
    let mut beta = e.beta * weight;
    let path = PathSpectrum::<S>::start(spectrum, PhaseSpectrum::class_of(index), &mut beta);
    let mut w = Walk::new(scene, Ray::new(origin, e.direction), beta, path);
    let mut ghost = GhostPath { settings, spectrum, visit, pair, reflections: 0, sensor: None, registered: Rgb::ZERO };
    log.set_source(crate::ray_map::emitter_of(scene, e.light));
    log.begin(e.origin, e.normal);
    walk(&mut w, &mut ghost, sampler, log);
    stats.rays += w.rays;
    log.finish(ghost.registered, w.spectrum.wavelength_nm());
}

/// A ghost path's state as a technique of the walk: it takes its pair's reflections, registers where it crosses
/// the sensor once it has them, and ends at its first diffuse vertex. It has no roulette: all-specular chains
/// are short and `max_depth` bounds them.
struct GhostPath<'a, V> {
    settings: LightSettings,
    spectrum: &'a PhaseSpectrum,
    visit: &'a mut V,
    pair: GhostPair,
    /// Reflections at dielectrics so far.
    reflections: u32,
    /// Whether the segment being traced registers where it crosses the sensor.
    sensor: Option<bool>,
    /// What the path registered, for its recording.
    registered: Rgb,
}

impl<const S: bool, V: FnMut(&LightEvent)> Technique<S> for GhostPath<'_, V> {
    const MODE: Transport = Transport::Importance;

    #[inline(always)]
    fn before_segment(&mut self, w: &Walk<S>) {
        let registers = self.reflections >= self.pair.reflections();
        self.sensor = (registers && w.segments < self.settings.max_depth).then_some(true);
    }

    #[inline(always)]
    fn on_segment<L: PathLog>(&mut self, w: &Walk<S>, hit: Option<&SurfaceHit>, log: &mut L) {
        if let Some(ghost) = self.sensor {
            let t_max = hit.map_or(f32::INFINITY, |h| h.t);
            let crossing = Crossing { ray: &w.ray, t_max, beta: w.beta, tag: w.spectrum.tag(), ghost };
            self.registered += register_crossing(w.scene, self.spectrum, crossing, self.visit, log);
        }
    }

    #[inline(always)]
    fn at_vertex<L: PathLog>(
        &mut self,
        w: &mut Walk<S>,
        _: &SurfaceHit,
        bsdf: &Bsdf,
        _: Vec3,
        _: &mut Sampler,
        _: &mut L,
    ) -> bool {
        bsdf.flags().is_specular() && w.segments < self.settings.max_depth
    }

    #[inline(always)]
    fn choice(&self, hit: &SurfaceHit) -> Reflection {
        pair_choice(&self.pair, self.reflections, hit.object)
    }

    #[inline(always)]
    fn after_sample(&mut self, w: &mut Walk<S>, _: &SurfaceHit, bsdf: &Bsdf, s: &BsdfSample, _: Rgb) -> bool {
        if bsdf.is_dielectric_reflection(s) {
            self.reflections += 1;
        }
        s.is_delta() && w.beta != Rgb::ZERO
    }

    #[inline(always)]
    fn roulette_unit(&self, _: &Walk<S>) -> Option<f32> {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pair_reflects_only_at_the_surface_it_names_next_and_follows_fresnel_after_two_reflections() {
        let pair = GhostPair { first: 3, second: Some(5) };
        assert_eq!(pair_choice(&pair, 0, 3), Reflection::AtLeast(PAIR_REFLECTION));
        assert_eq!(pair_choice(&pair, 0, 5), Reflection::Never, "the second surface is crossed on the way in");
        assert_eq!(pair_choice(&pair, 1, 5), Reflection::AtLeast(PAIR_REFLECTION));
        assert_eq!(pair_choice(&pair, 1, 3), Reflection::Never);
        assert_eq!(pair_choice(&pair, 2, 3), Reflection::Fresnel);
        let single = GhostPair { first: 3, second: None };
        assert_eq!(pair_choice(&single, 1, 3), Reflection::Never, "a one-reflection pair reflects once");
        assert_eq!((pair.reflections(), single.reflections()), (2, 1));
    }
}
