//! Checks of single values of a scene file: finite vectors, numbers within a rule, colours.

use super::state::Loader;
use crate::color::Rgb;
use crate::scene::SceneError;
use glam::Vec3;

impl Loader<'_> {
    /// A vector whose components are all finite.
    pub(super) fn vec3(&self, v: [f32; 3], span: &std::ops::Range<usize>, field: &str) -> Result<Vec3, SceneError> {
        if v.iter().all(|x| x.is_finite()) {
            Ok(Vec3::from(v))
        } else {
            Err(self.error(Some(span.clone()), field, format!("every component must be a finite number, got {v:?}")))
        }
    }

    /// A finite number that satisfies `ok`; `rule` says what `ok` asks for, in the error.
    pub(super) fn scalar(
        &self,
        x: f32,
        span: &std::ops::Range<usize>,
        field: &str,
        ok: impl Fn(f32) -> bool,
        rule: &str,
    ) -> Result<f32, SceneError> {
        if x.is_finite() && ok(x) {
            Ok(x)
        } else {
            Err(self.error(Some(span.clone()), field, format!("must be {rule}, got {x}")))
        }
    }

    /// A colour: finite, not negative, and at most `max` in every channel when given (reflectances).
    pub(super) fn colour(
        &self,
        v: [f32; 3],
        span: &std::ops::Range<usize>,
        field: &str,
        max: Option<f32>,
    ) -> Result<Rgb, SceneError> {
        let c = self.vec3(v, span, field)?;
        if c.min_element() < 0.0 {
            return Err(self.error(Some(span.clone()), field, format!("must not be negative, got {v:?}")));
        }
        if let Some(m) = max {
            if c.max_element() > m {
                return Err(self.error(
                    Some(span.clone()),
                    field,
                    format!("must be at most {m} (a surface cannot reflect more than it receives), got {v:?}"),
                ));
            }
        }
        Ok(c)
    }
}
