//! The `[[lights]]` entries: point and spot lights, environments (a map or a constant radiance) and the sun.

use super::state::Loader;
use crate::light::directional::Sun;
use crate::light::environment::ConstantEnvironment;
use crate::light::infinite::InfiniteLightError;
use crate::scene::description::{LightDesc, LightKind};
use crate::scene::file::LightSection;
use crate::scene::SceneError;
use crate::texture::Encoding;
use glam::Mat3;
use std::ops::Range;
use toml::Spanned;

impl Loader<'_> {
    /// Every entry of `[[lights]]`, in order.
    pub(super) fn lights(&mut self, entries: &[Spanned<LightSection>]) -> Result<Vec<LightDesc>, SceneError> {
        entries.iter().enumerate().map(|(i, l)| self.light(l, i)).collect()
    }

    /// Entry `i`.
    fn light(&mut self, l: &Spanned<LightSection>, i: usize) -> Result<LightDesc, SceneError> {
        let s = l.span();
        let f = |x: &str| format!("lights[{i}].{x}");
        let mut field = f("type");
        let kind = match l.get_ref() {
            LightSection::Point { position, intensity } => LightKind::Point {
                position: self.vec3(*position, &s, &f("position"))?,
                intensity: self.colour(*intensity, &s, &f("intensity"), None)?,
            },
            LightSection::Spot { position, direction, intensity, cone_angle_deg, falloff_start_deg } => {
                let dir = self.vec3(*direction, &s, &f("direction"))?;
                if dir.length_squared() == 0.0 {
                    return Err(self.error(Some(s), f("direction"), "must not be the zero vector"));
                }
                let cone = self.scalar(
                    *cone_angle_deg,
                    &s,
                    &f("cone_angle_deg"),
                    |v| v > 0.0 && v <= 90.0,
                    "in (0, 90] degrees",
                )?;
                let start = self.scalar(
                    falloff_start_deg.unwrap_or(cone),
                    &s,
                    &f("falloff_start_deg"),
                    |v| (0.0..=cone).contains(&v),
                    "between 0 and cone_angle_deg",
                )?;
                LightKind::Spot {
                    position: self.vec3(*position, &s, &f("position"))?,
                    direction: dir.normalize(),
                    intensity: self.colour(*intensity, &s, &f("intensity"), None)?,
                    cos_total: cone.to_radians().cos(),
                    cos_falloff_start: start.to_radians().cos(),
                }
            }
            LightSection::Environment { filename, radiance, scale, to_world } => {
                let scale = self.scalar(scale.unwrap_or(1.0), &s, &f("scale"), |v| v > 0.0, "a positive number")?;
                let rotation = self.rotation(*to_world, &s, &f("to_world"))?;
                match (filename, radiance) {
                    (Some(name), None) => {
                        field = f("filename");
                        // 8-bit images hold sRGB values, as textures and Mitsuba's maps do; HDR formats are linear whatever
                        // the encoding says.
                        let image = self.image(name, Some(s.clone()), &field, Encoding::Srgb)?;
                        LightKind::Map { image, scale, rotation, mirrored: false }
                    }
                    (None, Some(radiance)) => {
                        if to_world.is_some() {
                            return Err(self.error(
                                Some(s),
                                f("to_world"),
                                "a constant environment is the same from every direction: it takes no rotation",
                            ));
                        }
                        field = f("radiance");
                        let c = self.colour(*radiance, &s, &field, None)? * scale;
                        ConstantEnvironment::new(c).map_err(|e| self.light_error(&s, &field, e))?;
                        LightKind::Constant { radiance: c }
                    }
                    (Some(_), Some(_)) => {
                        return Err(self.error(
                            Some(s),
                            f("radiance"),
                            "give either `filename` (a map) or `radiance` (a constant), not both",
                        ))
                    }
                    (None, None) => {
                        return Err(self.error(
                            Some(s),
                            f("filename"),
                            "an environment needs `filename` (an OpenEXR, HDR or PFM map) or a constant `radiance`",
                        ))
                    }
                }
            }
            LightSection::Sun { direction, irradiance, angular_radius_deg } => {
                let dir = self.vec3(*direction, &s, &f("direction"))?;
                if dir.length_squared() == 0.0 {
                    return Err(self.error(Some(s), f("direction"), "must not be the zero vector"));
                }
                let irradiance = self.colour(*irradiance, &s, &f("irradiance"), None)?;
                let radius = self.scalar(
                    angular_radius_deg.unwrap_or(0.0),
                    &s,
                    &f("angular_radius_deg"),
                    |v| (0.0..90.0).contains(&v),
                    "in [0, 90) degrees",
                )?;
                // `direction` is where the light travels; the sun lies the other way.
                field = f("irradiance");
                Sun::new(-dir, irradiance, radius.to_radians()).map_err(|e| self.light_error(&s, &field, e))?;
                LightKind::Sun { toward: -dir, irradiance, angular_radius: radius.to_radians() }
            }
        };
        Ok(LightDesc { kind, source: self.source(Some(s), field) })
    }

    /// A `to_world` rotation given as three rows (the identity when absent); refused unless orthonormal with
    /// determinant 1.
    fn rotation(&self, rows: Option<[[f32; 3]; 3]>, span: &Range<usize>, field: &str) -> Result<Mat3, SceneError> {
        let Some(rows) = rows else { return Ok(Mat3::IDENTITY) };
        if !rows.iter().flatten().all(|x| x.is_finite()) {
            return Err(self.error(
                Some(span.clone()),
                field,
                format!("every entry must be a finite number, {rows:?}"),
            ));
        }
        let m = Mat3::from_cols_array_2d(&rows).transpose();
        crate::light::infinite::check_rotation(m).map_err(|e| self.light_error(span, field, e))?;
        Ok(m)
    }

    /// An infinite light's parameter error at `field`.
    fn light_error(&self, span: &Range<usize>, field: &str, e: InfiniteLightError) -> SceneError {
        self.error(Some(span.clone()), field, e.to_string())
    }
}
