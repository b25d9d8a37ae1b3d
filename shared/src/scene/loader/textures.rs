//! Texture values of the scene format: wherever a material parameter may vary over a surface, the scene gives a
//! constant (a colour `[r, g, b]` or a number) or a table, `{ bitmap = "file", ... }` or
//! `{ checkerboard = true, ... }` (scenes/README.md, "Textures"). Colour parameters read them with
//! [`Loader::texture`], numeric ones (a roughness, an opacity) with [`Loader::scalar_texture`].

use super::state::Loader;
use crate::color::Rgb;
use crate::scene::description::{bound_images, constant_max, Bound, TextureDesc};
use crate::scene::SceneError;
use crate::texture::{BitmapTexture, Checkerboard, Encoding, Filter, Texture, UvTransform, Wrap};
use std::ops::Range;
use toml::Value;

/// What a parameter holds: a colour, or a number (whose constants and factors are numbers too).
#[derive(Clone, Copy, PartialEq)]
enum Kind {
    Colour,
    Scalar,
}

impl Kind {
    /// How a constant of this kind is written, for errors.
    fn constant(self) -> &'static str {
        match self {
            Kind::Colour => "a colour [r, g, b] (or a number for a grey)",
            Kind::Scalar => "a number",
        }
    }
}

const BITMAP_KEYS: &[&str] = &["bitmap", "raw", "filter", "wrap", "to_uv", "factor"];
const CHECKERBOARD_KEYS: &[&str] = &["checkerboard", "color0", "color1", "to_uv"];

impl Loader<'_> {
    /// A colour parameter at `field`: a constant colour, a number (a grey), or a texture table; no value may be
    /// negative, and none may exceed `max` anywhere when it is given (a reflectance's 1). `span` is where the
    /// errors point (the value's table: the format keeps no span inside a material).
    pub(super) fn texture(
        &mut self,
        value: &Value,
        span: &Range<usize>,
        field: &str,
        max: Option<f32>,
    ) -> Result<TextureDesc, SceneError> {
        let mut t = self.texture_of(value, span, field, Kind::Colour)?;
        self.check_max(&mut t, span, field, max)?;
        Ok(t)
    }

    /// A numeric parameter at `field` (a roughness, an opacity): a number or a texture table, read where a number
    /// is wanted by [`Texture::eval_scalar`] (a colour bitmap by its luminance); bounded as [`Loader::texture`].
    pub(super) fn scalar_texture(
        &mut self,
        value: &Value,
        span: &Range<usize>,
        field: &str,
        max: Option<f32>,
    ) -> Result<TextureDesc, SceneError> {
        let mut t = self.texture_of(value, span, field, Kind::Scalar)?;
        self.check_max(&mut t, span, field, max)?;
        Ok(t)
    }

    /// Refuses a texture whose constants exceed `max` somewhere, and bounds its images by `max` (checked where
    /// the build step decodes them).
    pub(super) fn check_max(
        &self,
        t: &mut TextureDesc,
        span: &Range<usize>,
        field: &str,
        max: Option<f32>,
    ) -> Result<(), SceneError> {
        let Some(max) = max else { return Ok(()) };
        bound_images(t, &Bound { max, source: self.source(Some(span.clone()), field) });
        let top = constant_max(t);
        if top > max {
            let what = match t {
                Texture::Constant(_) => format!("must be at most {max}"),
                _ => format!("reaches {top} somewhere (texels times factor), and must stay at most {max}"),
            };
            let why = if max == 1.0 { " (a surface cannot reflect more than it receives)" } else { "" };
            return Err(self.error(Some(span.clone()), field, format!("{what}{why}")));
        }
        Ok(())
    }

    fn texture_of(
        &mut self,
        value: &Value,
        span: &Range<usize>,
        field: &str,
        kind: Kind,
    ) -> Result<TextureDesc, SceneError> {
        match value {
            Value::Table(table) => {
                if table.contains_key("bitmap") {
                    self.bitmap_texture(table, span, field, kind)
                } else if table.contains_key("checkerboard") {
                    self.checkerboard_texture(table, span, field, kind)
                } else {
                    Err(self.error(
                        Some(span.clone()),
                        field,
                        format!(
                            "a texture table names its kind: {{ bitmap = \"file\", ... }} or {{ checkerboard = true, \
                             ... }} (keys given: {})",
                            keys(table)
                        ),
                    ))
                }
            }
            other => Ok(Texture::Constant(self.constant(other, span, field, kind)?)),
        }
    }

    /// A constant of `kind`, not negative.
    fn constant(&self, value: &Value, span: &Range<usize>, field: &str, kind: Kind) -> Result<Rgb, SceneError> {
        let wrong = || {
            self.error(
                Some(span.clone()),
                field,
                format!("must be {} or a texture table, got {}", kind.constant(), shown(value)),
            )
        };
        let c = match (value, kind) {
            (Value::Array(a), Kind::Colour) if a.len() == 3 => {
                let mut c = [0.0f32; 3];
                for (x, v) in c.iter_mut().zip(a) {
                    *x = number(v).ok_or_else(wrong)?;
                }
                self.colour(c, span, field, None)?
            }
            _ => {
                let v = number(value).ok_or_else(wrong)?;
                self.colour([v; 3], span, field, None)?
            }
        };
        Ok(c)
    }

    fn bitmap_texture(
        &mut self,
        table: &toml::Table,
        span: &Range<usize>,
        field: &str,
        kind: Kind,
    ) -> Result<TextureDesc, SceneError> {
        self.known_keys(table, BITMAP_KEYS, span, field, "a bitmap texture")?;
        let sub = |k: &str| format!("{field}.{k}");
        let Some(Value::String(file)) = table.get("bitmap") else {
            return Err(self.error(Some(span.clone()), sub("bitmap"), "must be the image file's path, a string"));
        };
        let raw = match table.get("raw") {
            None => false,
            Some(Value::Boolean(b)) => *b,
            Some(v) => {
                return Err(self.error(
                    Some(span.clone()),
                    sub("raw"),
                    format!("must be true or false, got {}", shown(v)),
                ))
            }
        };
        let encoding = if raw { Encoding::Linear } else { Encoding::Srgb };
        let filter = match self.word(table, "filter", span, field, &["bilinear", "nearest"])? {
            Some("nearest") => Filter::Nearest,
            _ => Filter::Bilinear,
        };
        let wrap = match self.word(table, "wrap", span, field, &["repeat", "mirror", "clamp"])? {
            Some("mirror") => Wrap::Mirror,
            Some("clamp") => Wrap::Clamp,
            _ => Wrap::Repeat,
        };
        let to_uv = self.to_uv(table, span, field)?;
        let factor = match table.get("factor") {
            None => Rgb::ONE,
            Some(v) => self.constant(v, span, &sub("factor"), kind)?,
        };
        let image = self.image(file, Some(span.clone()), &sub("bitmap"), encoding)?;
        Ok(Texture::Bitmap(BitmapTexture { image, factor, filter, wrap, to_uv }))
    }

    fn checkerboard_texture(
        &mut self,
        table: &toml::Table,
        span: &Range<usize>,
        field: &str,
        kind: Kind,
    ) -> Result<TextureDesc, SceneError> {
        self.known_keys(table, CHECKERBOARD_KEYS, span, field, "a checkerboard texture")?;
        let sub = |k: &str| format!("{field}.{k}");
        if table.get("checkerboard") != Some(&Value::Boolean(true)) {
            return Err(self.error(Some(span.clone()), sub("checkerboard"), "must be true in a checkerboard texture"));
        }
        let defaults = Checkerboard::default();
        let color0 = match table.get("color0") {
            Some(v) => self.texture_of(v, span, &sub("color0"), kind)?,
            None => defaults.color0,
        };
        let color1 = match table.get("color1") {
            Some(v) => self.texture_of(v, span, &sub("color1"), kind)?,
            None => defaults.color1,
        };
        let to_uv = self.to_uv(table, span, field)?;
        Ok(Texture::Checkerboard(Box::new(Checkerboard { color0, color1, to_uv })))
    }

    /// Refuses a key of `table` that is not one of `known`.
    fn known_keys(
        &self,
        table: &toml::Table,
        known: &[&str],
        span: &Range<usize>,
        field: &str,
        what: &str,
    ) -> Result<(), SceneError> {
        match table.keys().find(|k| !known.contains(&k.as_str())) {
            Some(k) => Err(self.error(
                Some(span.clone()),
                format!("{field}.{k}"),
                format!("unknown key in {what} (it takes {})", known.join(", ")),
            )),
            None => Ok(()),
        }
    }

    /// An optional string key that must be one of `words`.
    fn word<'t>(
        &self,
        table: &'t toml::Table,
        key: &str,
        span: &Range<usize>,
        field: &str,
        words: &[&str],
    ) -> Result<Option<&'t str>, SceneError> {
        match table.get(key) {
            None => Ok(None),
            Some(Value::String(s)) if words.contains(&s.as_str()) => Ok(Some(s.as_str())),
            Some(v) => Err(self.error(
                Some(span.clone()),
                format!("{field}.{key}"),
                format!("must be one of \"{}\", got {}", words.join("\", \""), shown(v)),
            )),
        }
    }

    /// The optional `to_uv`: two rows [a, b, c], [d, e, f] (u' = a u + b v + c, v' = d u + e v + f, in
    /// photonfarm's coordinates), or three with the last [0, 0, 1].
    fn to_uv(&self, table: &toml::Table, span: &Range<usize>, field: &str) -> Result<UvTransform, SceneError> {
        let Some(value) = table.get("to_uv") else { return Ok(UvTransform::IDENTITY) };
        let wrong = |why: &str| {
            self.error(
                Some(span.clone()),
                format!("{field}.to_uv"),
                format!(
                    "must be [[a, b, c], [d, e, f]] (optionally a third row [0, 0, 1]) with finite numbers: {why}, got {}",
                    shown(value)
                ),
            )
        };
        let Value::Array(rows) = value else { return Err(wrong("not an array of rows")) };
        let mut m = [[0.0f32; 3]; 3];
        if !(rows.len() == 2 || rows.len() == 3) {
            return Err(wrong("it needs two or three rows"));
        }
        for (row, value) in m.iter_mut().zip(rows) {
            let Value::Array(entries) = value else { return Err(wrong("a row is not an array")) };
            if entries.len() != 3 {
                return Err(wrong("every row has three numbers"));
            }
            for (x, v) in row.iter_mut().zip(entries) {
                *x = number(v).filter(|x| x.is_finite()).ok_or_else(|| wrong("an entry is not a finite number"))?;
            }
        }
        if rows.len() == 3 && m[2] != [0.0, 0.0, 1.0] {
            return Err(wrong("the third row of an affine map is [0, 0, 1]"));
        }
        UvTransform::from_rows([m[0], m[1]]).ok_or_else(|| wrong("an entry is not a finite number"))
    }
}

/// A TOML number (integer or float) as f32.
fn number(v: &Value) -> Option<f32> {
    match v {
        Value::Float(x) => Some(*x as f32),
        Value::Integer(i) => Some(*i as f32),
        _ => None,
    }
}

/// A value as the scene writes it, for errors.
fn shown(v: &Value) -> String {
    match v {
        Value::Table(t) => format!("a table with keys {}", keys(t)),
        other => other.to_string(),
    }
}

fn keys(t: &toml::Table) -> String {
    let k: Vec<&str> = t.keys().map(String::as_str).collect();
    if k.is_empty() {
        "none".into()
    } else {
        k.join(", ")
    }
}

#[cfg(test)]
mod tests {
    use super::super::state::MeshSource;
    use super::*;
    use std::collections::BTreeMap;
    use std::path::Path;

    /// A 2 × 1 8-bit grey PNG: 51 and 255.
    fn png() -> Vec<u8> {
        let mut out = Vec::new();
        let mut e = png::Encoder::new(&mut out, 2, 1);
        e.set_color(png::ColorType::Grayscale);
        e.set_depth(png::BitDepth::Eight);
        e.write_header().unwrap().write_image_data(&[51, 255]).unwrap();
        out
    }

    fn files() -> BTreeMap<String, Vec<u8>> {
        BTreeMap::from([("grey.png".to_string(), png())])
    }

    /// Reads `value` (TOML for one value) as a colour or a scalar texture with at most `max`.
    fn read(value: &str, scalar: bool, max: Option<f32>) -> Result<Texture, String> {
        let files = files();
        let mut loader = Loader::new("", Path::new("t.toml"), MeshSource::Memory(&files));
        let v: Value = toml::from_str::<toml::Table>(&format!("x = {value}")).unwrap().remove("x").unwrap();
        let field = "materials.m.albedo";
        let r = if scalar {
            loader.scalar_texture(&v, &(0..0), field, max)
        } else {
            loader.texture(&v, &(0..0), field, max)
        };
        let t = r.map_err(|e| e.to_string())?;
        crate::scene::build::decode_texture(&t, &files).map_err(|e| e.to_string())
    }

    fn bitmap(t: Texture) -> BitmapTexture {
        match t {
            Texture::Bitmap(b) => b,
            other => panic!("not a bitmap: {other:?}"),
        }
    }

    #[test]
    fn constants_are_colours_or_greys_and_never_negative() {
        assert_eq!(read("[0.1, 0.2, 0.3]", false, None).unwrap(), Texture::Constant(Rgb::new(0.1, 0.2, 0.3)));
        assert_eq!(read("0.5", false, None).unwrap(), Texture::grey(0.5));
        assert_eq!(read("1", true, None).unwrap(), Texture::grey(1.0));
        let e = read("[0.1, -0.2, 0.3]", false, None).unwrap_err();
        assert!(e.contains("materials.m.albedo") && e.contains("negative"), "{e}");
        let e = read("\"red\"", false, None).unwrap_err();
        assert!(e.contains("a colour [r, g, b]") && e.contains("\"red\""), "{e}");
        // A scalar parameter takes a number, not a colour.
        let e = read("[0.1, 0.2, 0.3]", true, None).unwrap_err();
        assert!(e.contains("must be a number or a texture table"), "{e}");
        let e = read("[0.1, 0.2]", false, None).unwrap_err();
        assert!(e.contains("[0.1, 0.2]"), "{e}");
    }

    #[test]
    fn a_bitmap_table_reads_every_key_with_mitsubas_defaults() {
        let b = bitmap(read("{ bitmap = \"grey.png\" }", false, None).unwrap());
        assert_eq!(
            (b.factor, b.filter, b.wrap, b.to_uv),
            (Rgb::ONE, Filter::Bilinear, Wrap::Repeat, UvTransform::IDENTITY)
        );
        // sRGB by default: 51 reads srgb(0.2); raw reads 0.2.
        assert!((b.image.texel(0, 0).x - crate::texture::srgb_to_linear(0.2)).abs() < 1e-6);
        let b = bitmap(
            read(
                "{ bitmap = \"grey.png\", raw = true, filter = \"nearest\", wrap = \"mirror\", factor = [0.5, 1, 0.25], \
                 to_uv = [[2, 0, 0.5], [0, 3, 0], [0, 0, 1]] }",
                false,
                Some(1.0),
            )
            .unwrap(),
        );
        assert!((b.image.texel(0, 0).x - 0.2).abs() < 1e-6);
        assert_eq!((b.filter, b.wrap, b.factor), (Filter::Nearest, Wrap::Mirror, Rgb::new(0.5, 1.0, 0.25)));
        assert_eq!(b.to_uv, UvTransform::from_rows([[2.0, 0.0, 0.5], [0.0, 3.0, 0.0]]).unwrap());
        let b = bitmap(read("{ bitmap = \"grey.png\", wrap = \"clamp\", factor = 0.5 }", true, None).unwrap());
        assert_eq!((b.wrap, b.factor), (Wrap::Clamp, Rgb::splat(0.5)));
    }

    #[test]
    fn a_checkerboard_table_takes_mitsubas_defaults_and_textured_colours() {
        let Texture::Checkerboard(c) = read("{ checkerboard = true }", false, None).unwrap() else { panic!() };
        assert_eq!(*c, Checkerboard::default());
        let t = read(
            "{ checkerboard = true, color0 = [1, 0, 0], color1 = { bitmap = \"grey.png\" }, to_uv = [[4, 0, 0], [0, 4, 0]] }",
            false,
            None,
        )
        .unwrap();
        let Texture::Checkerboard(c) = t else { panic!() };
        assert_eq!(c.color0, Texture::Constant(Rgb::X));
        assert!(matches!(c.color1, Texture::Bitmap(_)));
        assert_eq!(c.to_uv, UvTransform::scale(4.0, 4.0));
        let e = read("{ checkerboard = false }", false, None).unwrap_err();
        assert!(e.contains("materials.m.albedo.checkerboard") && e.contains("must be true"), "{e}");
        let e = read("{ checkerboard = true, color0 = [1, 0, 0] }", true, None).unwrap_err();
        assert!(e.contains("materials.m.albedo.color0") && e.contains("a number"), "{e}");
    }

    #[test]
    fn mistakes_in_a_texture_table_name_the_key_and_what_it_takes() {
        for (value, needles) in [
            ("{ file = \"grey.png\" }", &["materials.m.albedo", "bitmap = \"file\"", "keys given: file"][..]),
            ("{ bitmap = \"grey.png\", warp = \"clamp\" }", &["materials.m.albedo.warp", "unknown key", "wrap"]),
            (
                "{ bitmap = \"grey.png\", wrap = \"tile\" }",
                &["albedo.wrap", "\"repeat\", \"mirror\", \"clamp\"", "tile"],
            ),
            ("{ bitmap = \"grey.png\", filter = 1 }", &["albedo.filter", "\"bilinear\", \"nearest\""]),
            ("{ bitmap = \"grey.png\", raw = \"yes\" }", &["albedo.raw", "true or false"]),
            ("{ bitmap = 3 }", &["albedo.bitmap", "path"]),
            ("{ bitmap = \"grey.png\", to_uv = [[1, 0], [0, 1]] }", &["albedo.to_uv", "three numbers"]),
            ("{ bitmap = \"grey.png\", to_uv = [[1, 0, 0]] }", &["albedo.to_uv", "two or three rows"]),
            ("{ bitmap = \"grey.png\", to_uv = [[1, 0, 0], [0, 1, 0], [1, 0, 1]] }", &["albedo.to_uv", "[0, 0, 1]"]),
            ("{ bitmap = \"grey.png\", to_uv = [[1, 0, \"a\"], [0, 1, 0]] }", &["albedo.to_uv", "finite"]),
            ("{ bitmap = \"grey.png\", factor = [1, -1, 0] }", &["albedo.factor", "negative"]),
            ("{ bitmap = \"missing.png\" }", &["albedo.bitmap", "missing.png"]),
            ("{ checkerboard = true, to_uv = 2 }", &["albedo.to_uv", "not an array"]),
            ("{ checkerboard = true, bitmap = \"grey.png\" }", &["albedo.checkerboard", "unknown key", "raw"]),
        ] {
            let e = read(value, false, None).unwrap_err();
            for n in needles {
                assert!(e.contains(n), "{value}: {e:?} does not mention {n:?}");
            }
        }
    }

    #[test]
    fn a_bound_applies_to_every_value_the_texture_reaches() {
        assert!(read("{ bitmap = \"grey.png\", factor = 1 }", false, Some(1.0)).is_ok());
        let e = read("{ bitmap = \"grey.png\", factor = [1, 1.5, 1] }", false, Some(1.0)).unwrap_err();
        assert!(e.contains("reaches 1.5") && e.contains("cannot reflect more"), "{e}");
        let e = read("{ checkerboard = true, color1 = 2 }", true, Some(1.0)).unwrap_err();
        assert!(e.contains("reaches 2"), "{e}");
        let e = read("[1, 1, 1.2]", false, Some(1.0)).unwrap_err();
        assert!(e.contains("must be at most 1"), "{e}");
        assert!(read("[1, 1, 1.2]", false, None).is_ok());
    }
}
