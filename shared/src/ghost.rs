//! Ghosts: light that reached a sensor after reflections inside the camera's lens. A camera path is a *ghost path* from
//! the moment it takes a reflection at a dielectric surface (Fresnel or total internal reflection) before its first
//! diffuse vertex; all light it contributes from then on (emitters seen through the lens, next-event estimates, and the
//! light later gathered into its backward photons) is ghost light. The ghost layer shows that part of the total; the
//! light stays in its usual layer as well. What the scene declares about ghosts (its lens, its settings, the pairs
//! of surfaces ghost paths reflect at) is in `crate::scene::ghost`.

use crate::geometry::SurfaceHit;
use crate::scene::Scene;

/// The auxiliary layer (and EXR layer) holding ghost light.
pub const GHOST_LAYER: &str = "ghost";

/// True when a camera path that reached the emitter at `hit` through specular vertices only, in `segments`
/// segments, leaves that light to the light paths of a scene where they register on the sensor: a ghost, or
/// the lens image (two segments or more) of a light whose image light paths bring.
#[inline]
pub fn light_side_owns(scene: &Scene, hit: &SurfaceHit, ghost: bool, segments: u32) -> bool {
    ghost || (segments >= 2 && scene.lights.lens_image_by_light_paths_at(hit))
}
