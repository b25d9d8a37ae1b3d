//! What a scene declares about ghosts (`crate::ghost`): whether its lens can make them and whether light paths
//! bring them, its `[render]` settings for ghost paths, the lens's front element light paths aim at, which
//! lights' images through the lens the light paths bring, and the table of surface pairs ghost paths reflect
//! at. The table's probabilities and aims come from a pilot the estimator runs (`crate::pbpm::ghost_pairs`);
//! the scene only keeps it, so that it is computed once per scene.

use crate::camera::{Camera, Lens, RearElement};
use crate::geometry::LensSurface;
use crate::light::ghost_aim::AimGrid;
use crate::light::{Light, AIMED_FRACTION};
use crate::sampling::Discrete;
use crate::scene::Scene;

/// True when the scene can make ghosts and so gets a ghost layer: its camera is a sensor behind a lens built in
/// the scene (`type = "sensor"`) and at least one object is a dielectric. A pinhole or thin-lens camera has no
/// lens to reflect in, and a lens of mirrors and coatings alone has no dielectric surface.
pub fn scene_can_make_ghosts(scene: &Scene) -> bool {
    matches!(scene.camera.lens, Lens::Sensor { .. })
        && scene.objects.iter().any(|o| scene.materials[o.material as usize].is_dielectric())
}

/// True when light paths register the ghost chains on the scene's sensor and camera paths leave those chains to
/// them: the scene can make ghosts and does not ask camera paths to find them alone (`[render]
/// ghost_light_paths = false`).
pub fn sensor_ghosts(scene: &Scene) -> bool {
    scene.render.ghost_light_paths && scene_can_make_ghosts(scene)
}

/// Ghost paths per light path unless the scene sets `[render] ghost_paths`. One: a ghost path crosses the whole
/// lens and costs more rays than the rest of its light path's work, so a second one takes more phases from the
/// camera paths than it gives the ghost layer (docs/measurements.md, "Ghost pairs").
pub const GHOST_PATHS_PER_LIGHT_PATH: u32 = 1;

/// The radius in pixels, at the first phase, of the disc a ghost chain's registration is spread over on the
/// sensor unless the scene sets `[render] ghost_radius` (`crate::pbpm::sensor_kernel`). Of 4, 8 and 16, 8 gave
/// the lens's ghost layer the lowest true error at 30 s (docs/measurements.md, "Ghost chains on a disc of
/// pixels").
pub const GHOST_RADIUS: f32 = 8.0;

/// The largest `ghost_radius` a scene may ask for: a disc of a few thousand pixels per registration.
pub const MAX_GHOST_RADIUS: f32 = 32.0;

/// The most ghost paths per light path a scene may ask for.
pub const MAX_GHOST_PATHS: u32 = 64;

/// Ghost paths traced per light path in a phase of `scene` (`crate::pbpm::trace_ghost_paths`): the scene's
/// setting where light paths bring the ghost chains, 0 elsewhere.
pub fn ghost_paths(scene: &Scene) -> u32 {
    if sensor_ghosts(scene) {
        scene.render.ghost_paths
    } else {
        0
    }
}

/// The disc light paths aim at so that ghost chains start often: the clear aperture of the lens surface
/// farthest in front of a sensor camera (the front element), in the plane of its rim. None for other cameras.
pub fn front_element(camera: &Camera, lens_surfaces: impl IntoIterator<Item = LensSurface>) -> Option<RearElement> {
    let Lens::Sensor { .. } = camera.lens else { return None };
    let forward = camera.forward();
    lens_surfaces
        .into_iter()
        .map(|s| RearElement { center: s.vertex + s.axis * s.rim_sag(), axis: s.axis, radius: s.aperture_radius })
        .filter(|d| (d.center - camera.position).dot(forward) > 0.0)
        .max_by(|a, b| {
            let depth = |d: &RearElement| (d.center - camera.position).dot(forward);
            depth(a).total_cmp(&depth(b))
        })
}

/// Aimed light paths per phase that each pixel of a light's image through the lens must be able to expect (with
/// as many light paths per phase as the picture has pixels, before the lens's losses) for light paths to bring
/// that image.
pub const LENS_IMAGE_PATHS_PER_PIXEL: f32 = 16.0;

/// Which lights' images through the lens light paths bring to the sensor, parallel to `scene.lights.all()`.
///
/// A camera path finds a small bright light through the lens only when its sample of the aperture happens to
/// hit the light, once per pixel and phase and at one wavelength; the light's own paths aimed at the front
/// element land on its image many times per phase. The light side therefore takes an area light's image when
/// the light faces the front element and its share of the aimed paths, spread over the pixels of its image
/// (its solid angle from the front element over a pixel's), gives each of them at least
/// `LENS_IMAGE_PATHS_PER_PIXEL`; large or dim lights stay with the camera paths, which see their images
/// without noise. Point and spot lights have no image a camera path could hit and stay out of both.
pub fn lens_images_by_light_paths(scene: &Scene, front: &RearElement) -> Vec<bool> {
    let lights = &scene.lights;
    let pixels = scene.camera.pixel_count() as f32;
    let pixel_solid_angle = scene.camera.pixel_angle().powi(2);
    lights
        .all()
        .iter()
        .enumerate()
        .map(|(l, light)| {
            let Light::Area { triangle, area, normal, .. } = *light else { return false };
            let v = scene.geometry.triangle(triangle).v;
            let to_front = front.center - (v[0] + v[1] + v[2]) / 3.0;
            let d2 = to_front.length_squared();
            let cos = normal.dot(to_front) / d2.sqrt();
            if !(cos > 0.0 && d2 > 0.0) {
                return false;
            }
            let image_pixels = area * cos / d2 / pixel_solid_angle;
            let aimed_paths = pixels * lights.selection_pmf(l) * AIMED_FRACTION;
            aimed_paths >= LENS_IMAGE_PATHS_PER_PIXEL * image_pixels
        })
        .collect()
}

/// The dielectric surfaces (scene objects) a ghost path reflects at: `first`, then `second`. A pair without a
/// second surface stands for the chains that reflect once.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GhostPair {
    pub first: u32,
    pub second: Option<u32>,
}

impl GhostPair {
    /// Every pair of `scene` in the table's order: each dielectric surface alone, then followed by each
    /// dielectric surface, surface by surface.
    pub fn all_of(scene: &Scene) -> Vec<GhostPair> {
        let dielectric = |o: &u32| scene.materials[scene.objects[*o as usize].material as usize].is_dielectric();
        let surfaces: Vec<u32> = (0..scene.objects.len() as u32).filter(dielectric).collect();
        surfaces
            .iter()
            .flat_map(|&first| {
                std::iter::once(GhostPair { first, second: None })
                    .chain(surfaces.iter().map(move |&s| GhostPair { first, second: Some(s) }))
            })
            .collect()
    }

    /// The reflections at dielectrics a chain of this pair has.
    pub fn reflections(&self) -> u32 {
        if self.second.is_some() {
            2
        } else {
            1
        }
    }
}

/// The table ghost paths draw their pair from: every ordered pair of the scene's dielectric surfaces, and every
/// surface alone (`GhostPair::all_of`), with probabilities and, per pair, where on the front element to aim.
/// With every pair's probability and every cell's density above zero the estimate is unbiased whatever they
/// are; the pilot that fills the table (`crate::pbpm::ghost_pairs`) only puts them where ghosts are.
#[derive(Clone, Debug)]
pub struct GhostPairs {
    pairs: Vec<GhostPair>,
    aims: Vec<AimGrid>,
    choice: Discrete,
}

impl GhostPairs {
    /// The table of `pairs` drawn with `probabilities` and aimed by `aims`, both parallel to `pairs`; None
    /// when no pair has a positive probability.
    pub fn new(pairs: Vec<GhostPair>, aims: Vec<AimGrid>, probabilities: &[f32]) -> Option<GhostPairs> {
        assert!(pairs.len() == aims.len() && pairs.len() == probabilities.len(), "one aim and probability per pair");
        let choice = Discrete::new(probabilities)?;
        Some(GhostPairs { pairs, aims, choice })
    }

    /// The pair for the random number `u`, its probability, and where its paths aim.
    #[inline]
    pub fn sample(&self, u: f32) -> (GhostPair, f32, &AimGrid) {
        let (i, p) = self.choice.sample(u);
        (self.pairs[i], p, &self.aims[i])
    }

    /// Every pair with its probability, in the table's order.
    pub fn iter(&self) -> impl Iterator<Item = (GhostPair, f32)> + '_ {
        self.pairs.iter().enumerate().map(|(i, &pair)| (pair, self.choice.pmf(i)))
    }

    /// Where the paths of the table's `i`-th pair aim.
    pub fn aim(&self, i: usize) -> &AimGrid {
        &self.aims[i]
    }
}
