//! The `[[lights]]` entries: point and spot lights.

use super::state::Loader;
use crate::light::Light;
use crate::scene::file::LightSection;
use crate::scene::SceneError;
use toml::Spanned;

impl Loader<'_> {
    /// Every entry of `[[lights]]`, in order.
    pub(super) fn lights(&self, entries: &[Spanned<LightSection>]) -> Result<Vec<Light>, SceneError> {
        entries.iter().enumerate().map(|(i, l)| self.light(l, i)).collect()
    }

    /// Entry `i`.
    fn light(&self, l: &Spanned<LightSection>, i: usize) -> Result<Light, SceneError> {
        let s = l.span();
        let f = |x: &str| format!("lights[{i}].{x}");
        Ok(match l.get_ref() {
            LightSection::Point { position, intensity } => Light::Point {
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
                Light::Spot {
                    position: self.vec3(*position, &s, &f("position"))?,
                    direction: dir.normalize(),
                    intensity: self.colour(*intensity, &s, &f("intensity"), None)?,
                    cos_total: cone.to_radians().cos(),
                    cos_falloff_start: start.to_radians().cos(),
                }
            }
        })
    }
}
