//! Texture-valued parameters: a constant (`rgb`, `spectrum`, `float`) or a `bitmap` or `checkerboard` child,
//! mapped to photonfarm's textures, whose v runs the other way (`UvTransform::from_mitsuba`).

use super::params::{constant_colour, Params};
use super::{rgb, Importer};
use crate::scene::description::{bound_images, constant_max, Bound, TextureDesc};
use crate::scene::mitsuba::{Category, Child, MitsubaError, SpectrumUse};
use crate::texture::{BitmapTexture, Checkerboard, Encoding, Filter, Texture, UvTransform, Wrap};
use glam::DMat4;

impl Importer<'_> {
    /// The parameter `name` of `p` as a texture (a constant or a texture child), None when absent; `max` bounds
    /// every value (a reflectance's 1).
    pub(super) fn texture_param(
        &mut self,
        p: &Params,
        name: &str,
        usage: SpectrumUse,
        max: Option<f32>,
    ) -> Result<Option<TextureDesc>, MitsubaError> {
        if let Some(param) = p.get(name) {
            let c = constant_colour(&param.value, usage).ok_or_else(|| {
                p.error_at(param, format!("must be a colour or a texture, not a <{}>", param.value.tag()))
            })?;
            let t = Texture::Constant(rgb(c));
            self.check_range(&t, max).map_err(|m| p.error_at(param, m))?;
            return Ok(Some(t));
        }
        let Some(child) = p.child(name) else { return Ok(None) };
        let mut t = self.texture(child, usage)?;
        self.check_range(&t, max).map_err(|m| MitsubaError::at(&child.position, child.plugin.element(), m))?;
        // The images' values are checked where the build step decodes them, at the child.
        if let Some(max) = max {
            bound_images(&mut t, &Bound { max, source: super::source(&child.position, child.plugin.element()) });
        }
        Ok(Some(t))
    }

    /// `texture_param` with a grey `default`.
    pub(super) fn texture_or(
        &mut self,
        p: &Params,
        name: &str,
        default: f32,
        max: Option<f32>,
    ) -> Result<TextureDesc, MitsubaError> {
        Ok(self.texture_param(p, name, SpectrumUse::Reflectance, max)?.unwrap_or(Texture::grey(default)))
    }

    /// Refuses negative values and constants above `max`.
    fn check_range(&self, t: &TextureDesc, max: Option<f32>) -> Result<(), String> {
        if let Texture::Constant(c) = t {
            if !c.is_finite() || c.min_element() < 0.0 {
                return Err(format!("must be finite and not negative, got {c:?}"));
            }
        }
        if let Some(max) = max {
            let top = constant_max(t);
            if top > max {
                return Err(format!("reaches {top}, above {max} (a surface cannot reflect more than it receives)"));
            }
        }
        Ok(())
    }

    /// A texture plugin.
    fn texture(&mut self, child: &Child, usage: SpectrumUse) -> Result<TextureDesc, MitsubaError> {
        let plugin = &child.plugin;
        let p = Params::new(plugin);
        if plugin.category != Category::Texture {
            return Err(p.error(format!("{} is not a texture", plugin.element())));
        }
        let t = match plugin.kind.as_str() {
            "bitmap" => {
                let file = p.string("filename")?.ok_or_else(|| p.error("a bitmap needs a filename"))?;
                let encoding = if p.boolean("raw", false)? { Encoding::Linear } else { Encoding::Srgb };
                let filter = match p.string("filter_type")?.unwrap_or("bilinear") {
                    "bilinear" => Filter::Bilinear,
                    "nearest" => Filter::Nearest,
                    other => return Err(p.error(format!("filter_type \"{other}\" is not bilinear or nearest"))),
                };
                let wrap = match p.string("wrap_mode")?.unwrap_or("repeat") {
                    "repeat" => Wrap::Repeat,
                    "mirror" => Wrap::Mirror,
                    "clamp" => Wrap::Clamp,
                    other => return Err(p.error(format!("wrap_mode \"{other}\" is not repeat, mirror or clamp"))),
                };
                let to_uv = self.uv_transform(&p)?;
                let image = self.bitmap(file, encoding, &plugin.position, &plugin.element())?;
                let mut texture = BitmapTexture::new(image);
                texture.filter = filter;
                texture.wrap = wrap;
                texture.to_uv = to_uv;
                Texture::Bitmap(texture)
            }
            "checkerboard" => {
                let defaults = Checkerboard::default();
                let color0 = self.texture_param(&p, "color0", usage, None)?.unwrap_or(defaults.color0);
                let color1 = self.texture_param(&p, "color1", usage, None)?.unwrap_or(defaults.color1);
                let to_uv = self.uv_transform(&p)?;
                Texture::Checkerboard(Box::new(Checkerboard { color0, color1, to_uv }))
            }
            other => {
                return Err(p.error(format!("the texture `{other}` is not supported (bitmap and checkerboard are)")))
            }
        };
        p.finish()?;
        Ok(t)
    }

    /// A texture's `to_uv`: Mitsuba applies the upper-left 3×3 block of the 4×4 transform to (u, v, 1).
    fn uv_transform(&mut self, p: &Params) -> Result<UvTransform, MitsubaError> {
        let m: DMat4 = p.transform("to_uv")?;
        if m == DMat4::IDENTITY {
            return Ok(UvTransform::IDENTITY);
        }
        let r = |i: usize| [m.col(0)[i] as f32, m.col(1)[i] as f32, m.col(2)[i] as f32];
        if m.col(3)[0] != 0.0 || m.col(3)[1] != 0.0 {
            self.notes.push(format!(
                "{} at {}: to_uv's translation along x or y (the 4×4 matrix's last column) is dropped, as Mitsuba's \
                 texture transform keeps the upper-left 3×3 block",
                p.plugin.element(),
                p.plugin.position
            ));
        }
        UvTransform::from_mitsuba([r(0), r(1)]).ok_or_else(|| p.error("to_uv has a value that is not finite"))
    }
}
