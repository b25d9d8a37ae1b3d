//! Emitters outside shapes: `point` and `spot`. Environment, sun, directional and constant emitters are refused
//! by name until photonfarm renders them.

use super::params::Params;
use super::{rgb, Importer};
use crate::light::Light;
use crate::scene::mitsuba::{MitsubaError, Plugin, SpectrumUse};
use glam::DVec3;

impl Importer<'_> {
    /// A top-level emitter as a light.
    pub(super) fn emitter(&mut self, plugin: &Plugin) -> Result<Light, MitsubaError> {
        let p = Params::new(plugin);
        let to_world = p.transform("to_world")?;
        let intensity = rgb(p.colour("intensity", SpectrumUse::Emission)?.unwrap_or([1.0; 3]));
        if !intensity.is_finite() || intensity.min_element() < 0.0 {
            return Err(p.error(format!("the intensity must be finite and not negative, got {intensity:?}")));
        }
        let light = match plugin.kind.as_str() {
            "point" => {
                let position = match p.point("position")? {
                    Some(_) if to_world != glam::DMat4::IDENTITY => {
                        return Err(p.error("give position or to_world, not both"))
                    }
                    Some(at) => at,
                    None => to_world.transform_point3(DVec3::ZERO),
                };
                Light::Point { position: position.as_vec3(), intensity }
            }
            "spot" => {
                let cutoff = p.float_or("cutoff_angle", 20.0)?;
                let beam = p.float_or("beam_width", 0.75 * cutoff)?;
                if !(cutoff > 0.0 && cutoff <= 90.0 && beam >= 0.0 && beam <= cutoff) {
                    return Err(p.error(format!(
                        "cutoff_angle must be in (0, 90] and beam_width in [0, cutoff_angle], got {cutoff} and {beam}"
                    )));
                }
                if p.child("texture").is_some() {
                    return Err(p.error("a spot light's texture is not supported"));
                }
                let direction = to_world.transform_vector3(DVec3::Z);
                let direction = direction.try_normalize().ok_or_else(|| p.error("to_world collapses the direction"))?;
                // Both are full intensity within beam_width and dark beyond cutoff_angle; between them Mitsuba's
                // falloff is linear in the angle, photonfarm's a smoothstep in its cosine.
                self.notes.push(format!(
                    "{} at {}: the falloff between beam_width and cutoff_angle follows photonfarm's curve",
                    plugin.element(),
                    plugin.position
                ));
                Light::Spot {
                    position: to_world.transform_point3(DVec3::ZERO).as_vec3(),
                    direction: direction.as_vec3(),
                    intensity,
                    cos_total: cutoff.to_radians().cos() as f32,
                    cos_falloff_start: beam.to_radians().cos() as f32,
                }
            }
            "envmap" | "constant" | "directional" | "sunsky" | "sky" | "sun" | "projector" | "directionalarea" => {
                return Err(p.error(format!(
                    "the emitter `{}` is not supported yet (photonfarm renders area emitters on meshes, point and spot)",
                    plugin.kind
                )))
            }
            "area" => return Err(p.error("an area emitter belongs inside a shape")),
            other => return Err(p.error(format!("the emitter `{other}` is not supported"))),
        };
        p.finish()?;
        Ok(light)
    }
}
