//! Emitters outside shapes: `point`, `spot`, and the lights at infinity `envmap`, `constant` and `directional`.
//! Mitsuba's sky models (`sunsky`, …) and the emitters photonfarm has no counterpart for are refused by name.

use super::params::Params;
use super::{rgb, source, Importer};
use crate::color::Rgb;
use crate::light::directional::Sun;
use crate::light::environment::ConstantEnvironment;
use crate::scene::description::{LightDesc, LightKind};
use crate::scene::mitsuba::{MitsubaError, Plugin, SpectrumUse};
use crate::texture::Encoding;
use glam::{DMat3, DMat4, DVec3, Mat3};

impl Importer<'_> {
    /// A top-level emitter as a light.
    pub(super) fn emitter(&mut self, plugin: &Plugin) -> Result<LightDesc, MitsubaError> {
        let p = Params::new(plugin);
        let to_world = p.transform("to_world")?;
        let light = match plugin.kind.as_str() {
            "envmap" => self.envmap(&p, to_world)?,
            "constant" => {
                // Mitsuba reads a constant's to_world and has no use for it: the light is the same every way.
                let radiance = emission(&p, "radiance")?;
                ConstantEnvironment::new(radiance).map_err(|e| p.error(e.to_string()))?;
                LightKind::Constant { radiance }
            }
            "directional" => {
                let irradiance = emission(&p, "irradiance")?;
                let travel = match p.point("direction")? {
                    Some(_) if to_world != DMat4::IDENTITY => {
                        return Err(p.error("give direction or to_world, not both (Mitsuba refuses both too)"))
                    }
                    Some(d) => d.try_normalize().ok_or_else(|| p.error("the direction must not be zero"))?,
                    None => {
                        // Mitsuba sends the light along to_world's +z as it is, without normalising it: only a
                        // unit vector gives the irradiance asked for.
                        let d = to_world.transform_vector3(DVec3::Z);
                        if (d.length() - 1.0).abs() > 1e-6 {
                            return Err(p.error(format!(
                                "to_world scales the light's direction (+z becomes {d}), which changes Mitsuba's \
                                 irradiance: give a rotation"
                            )));
                        }
                        d
                    }
                };
                // photonfarm's sun is named by the way toward it, against the light's travel.
                Sun::new(-travel.as_vec3(), irradiance, 0.0).map_err(|e| p.error(e.to_string()))?;
                LightKind::Sun { toward: -travel.as_vec3(), irradiance, angular_radius: 0.0 }
            }
            "point" => {
                let intensity = intensity(&p)?;
                let position = match p.point("position")? {
                    Some(_) if to_world != glam::DMat4::IDENTITY => {
                        return Err(p.error("give position or to_world, not both"))
                    }
                    Some(at) => at,
                    None => to_world.transform_point3(DVec3::ZERO),
                };
                LightKind::Point { position: position.as_vec3(), intensity }
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
                let intensity = intensity(&p)?;
                let direction = to_world.transform_vector3(DVec3::Z);
                let direction = direction.try_normalize().ok_or_else(|| p.error("to_world collapses the direction"))?;
                // Both are full intensity within beam_width and dark beyond cutoff_angle; between them Mitsuba's
                // falloff is linear in the angle, photonfarm's a smoothstep in its cosine.
                self.notes.push(format!(
                    "{} at {}: the falloff between beam_width and cutoff_angle follows photonfarm's curve",
                    plugin.element(),
                    plugin.position
                ));
                LightKind::Spot {
                    position: to_world.transform_point3(DVec3::ZERO).as_vec3(),
                    direction: direction.as_vec3(),
                    intensity,
                    cos_total: cutoff.to_radians().cos() as f32,
                    cos_falloff_start: beam.to_radians().cos() as f32,
                }
            }
            "sunsky" | "sky" | "sun" | "projector" | "directionalarea" => {
                return Err(p.error(format!(
                    "the emitter `{}` has no counterpart in photonfarm (which renders area, point, spot, envmap, \
                     constant and directional emitters)",
                    plugin.kind
                )))
            }
            "area" => return Err(p.error("an area emitter belongs inside a shape")),
            other => return Err(p.error(format!("the emitter `{other}` is not supported"))),
        };
        p.finish()?;
        Ok(LightDesc { kind: light, source: source(&plugin.position, plugin.element()) })
    }

    /// An `envmap`: its image (PNG and JPEG decoded from sRGB, OpenEXR, Radiance HDR and PFM linear, as Mitsuba
    /// reads them) in Mitsuba's latitude-longitude orientation, which is photonfarm's (`light::environment`).
    fn envmap(&mut self, p: &Params, to_world: DMat4) -> Result<LightKind, MitsubaError> {
        let name = p.string("filename")?.ok_or_else(|| p.error("an envmap needs a filename"))?;
        let scale = p.float_or("scale", 1.0)?;
        if !(scale.is_finite() && scale > 0.0) {
            return Err(p.error(format!("the scale must be positive, got {scale}")));
        }
        // It changes how directions are sampled, not the image.
        p.boolean("mis_compensation", false)?;
        // Mitsuba turns directions by the inverse of to_world's linear part (a translation does nothing) and reads
        // the map without normalising them, so only a rotation, or a rotation and a mirror, leaves the map whole.
        let linear = DMat3::from_mat4(to_world);
        let orthonormal =
            (linear.transpose() * linear - DMat3::IDENTITY).to_cols_array().iter().all(|x| x.abs() < 1e-4);
        if !orthonormal {
            return Err(p.error(
                "the envmap's to_world must be a rotation (and translation): Mitsuba does not \
                 renormalise the directions a scale or shear gives it",
            ));
        }
        let mirrored = linear.determinant() < 0.0;
        // The map's size (at least 2 × 3 texels, as Mitsuba needs) is checked where the build step decodes it.
        let image = self.bitmap(name, Encoding::Srgb, &p.plugin.position, &p.plugin.element())?;
        let rotation = if mirrored {
            // A mirror M = R · diag(−1, 1, 1) turns u into 1 − u: the build step reads the map with the rotation R
            // and its columns in reverse order.
            linear * DMat3::from_diagonal(DVec3::new(-1.0, 1.0, 1.0))
        } else {
            linear
        };
        Ok(LightKind::Map { image, scale: scale as f32, rotation: mat3(rotation), mirrored })
    }
}

/// A point or spot light's `intensity` (default 1).
fn intensity(p: &Params) -> Result<Rgb, MitsubaError> {
    let intensity = rgb(p.colour("intensity", SpectrumUse::Emission)?.unwrap_or([1.0; 3]));
    if !intensity.is_finite() || intensity.min_element() < 0.0 {
        return Err(p.error(format!("the intensity must be finite and not negative, got {intensity:?}")));
    }
    Ok(intensity)
}

/// An infinite light's constant `name` (radiance or irradiance; Mitsuba's default 1); a texture is refused.
fn emission(p: &Params, name: &str) -> Result<Rgb, MitsubaError> {
    if p.child(name).is_some() {
        return Err(p.error(format!("a textured {name} is not supported: give a colour or a spectrum")));
    }
    Ok(rgb(p.colour(name, SpectrumUse::Emission)?.unwrap_or([1.0; 3])))
}

/// A rotation in photonfarm's single precision.
fn mat3(m: DMat3) -> Mat3 {
    m.as_mat3()
}
