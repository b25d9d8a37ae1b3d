//! Ghosts: light that reached a sensor after reflections inside the camera's lens. A camera path is a *ghost path* from
//! the moment it takes a reflection at a dielectric surface (Fresnel or total internal reflection) before its first
//! diffuse vertex; all light it contributes from then on (emitters seen through the lens, next-event estimates, and the
//! light later gathered into its backward photons) is ghost light. The ghost layer shows that part of the total; the
//! light stays in its usual layer as well.

use crate::camera::{Camera, Lens, RearElement};
use crate::geometry::{LensSurface, SurfaceHit};
use crate::light::{Light, AIMED_FRACTION};
use crate::scene::Scene;

/// The auxiliary layer (and EXR layer) holding ghost light.
pub const GHOST_LAYER: &str = "ghost";

/// True when the scene can make ghosts and so gets a ghost layer: its camera is a sensor behind a lens built in
/// the scene (`type = "sensor"`) and at least one object is a dielectric. A pinhole or thin-lens camera has no
/// lens to reflect in, and a lens of mirrors and coatings alone has no dielectric surface.
pub fn scene_can_make_ghosts(scene: &Scene) -> bool {
    matches!(scene.camera.lens, crate::camera::Lens::Sensor { .. })
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

/// True when a camera path that reached the emitter at `hit` through specular vertices only, in `segments`
/// segments, leaves that light to the light paths of a scene where they register on the sensor: a ghost, or
/// the lens image (two segments or more) of a light whose image light paths bring.
#[inline]
pub fn light_side_owns(scene: &Scene, hit: &SurfaceHit, ghost: bool, segments: u32) -> bool {
    ghost || (segments >= 2 && scene.lights.lens_image_by_light_paths_at(hit))
}
