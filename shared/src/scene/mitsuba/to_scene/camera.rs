//! The sensor: `perspective` and `thinlens` with Mitsuba's field of view (`fov` along `fov_axis`, or a 35 mm
//! `focal_length`), `to_world` and the `hdrfilm`'s size; the sampler and a reconstruction filter other than
//! `box` are ignored with a note (photonfarm's pixel is the box-filtered radiance and it renders until its own
//! stop).

use super::params::Params;
use super::Importer;
use crate::scene::description::{CameraDesc, LensDesc};
use crate::scene::mitsuba::{Category, MitsubaError, SourcePos};
use glam::{DMat4, DVec3, Vec3};

/// Mitsuba's film size when the scene gives none.
const DEFAULT_FILM: (i64, i64) = (768, 576);

impl Importer<'_> {
    /// The first sensor (the one Mitsuba renders by default) as photonfarm's camera.
    pub(super) fn camera(&mut self) -> Result<CameraDesc, MitsubaError> {
        let doc = self.doc;
        let Some(sensor) = doc.sensors.first() else {
            return Err(MitsubaError::in_file(
                SourcePos::file_start(&doc.path),
                "the scene has no <sensor>: add <sensor type=\"perspective\">",
            ));
        };
        if doc.sensors.len() > 1 {
            self.notes.push(format!("{} sensors: the first one is rendered, as Mitsuba does", doc.sensors.len()));
        }
        let p = Params::new(sensor);
        let thin = match sensor.kind.as_str() {
            "perspective" => false,
            "thinlens" => true,
            other => {
                return Err(p.error(format!("the sensor `{other}` is not supported (perspective and thinlens are)")))
            }
        };
        let (width, height) = self.film(&p)?;
        self.sampler(&p)?;
        let aspect = width as f64 / height as f64;
        let fov_x = fov_x(&p, aspect)?;
        let tan_y = (0.5 * fov_x.to_radians()).tan() / aspect;
        let fov_y = 2.0 * tan_y.atan().to_degrees();
        for name in ["principal_point_offset_x", "principal_point_offset_y"] {
            if p.float(name)?.is_some_and(|x| x != 0.0) {
                return Err(p.error(format!("{name} other than 0 is not supported (photonfarm's image is centred)")));
            }
        }
        // Clipping planes only hide what lies nearer or farther: noted, since photonfarm has none.
        for name in ["near_clip", "far_clip"] {
            if p.float(name)?.is_some() {
                self.notes.push(format!("{} {name} is not applied", sensor.element()));
            }
        }
        let to_world = p.transform("to_world")?;
        let (position, look_at, up) = camera_frame(&to_world).map_err(|m| p.error(m))?;
        let lens = if thin {
            let radius = p.float("aperture_radius")?.ok_or_else(|| p.error("a thinlens needs aperture_radius"))?;
            let focus = p.float("focus_distance")?.ok_or_else(|| p.error("a thinlens needs focus_distance"))?;
            if !(radius > 0.0 && focus > 0.0) {
                return Err(p.error("aperture_radius and focus_distance must be positive"));
            }
            LensDesc::Thin { fov_y_deg: fov_y as f32, radius: radius as f32, focus_distance: focus as f32 }
        } else {
            // A pinhole focuses everywhere: Blender's exporter writes focus_distance anyway.
            p.ignore(&["focus_distance"]);
            LensDesc::Pinhole { fov_y_deg: fov_y as f32 }
        };
        p.finish()?;
        Ok(CameraDesc { position, look_at, up, width, height, lens })
    }

    /// The film's size in pixels.
    fn film(&mut self, sensor: &Params) -> Result<(u32, u32), MitsubaError> {
        let films = sensor.children_of(Category::Film);
        let Some(film) = films.first() else {
            self.notes.push(format!("no film: Mitsuba's default {}×{}", DEFAULT_FILM.0, DEFAULT_FILM.1));
            return Ok((DEFAULT_FILM.0 as u32, DEFAULT_FILM.1 as u32));
        };
        let f = Params::new(&film.plugin);
        if film.plugin.kind != "hdrfilm" {
            return Err(f.error(format!("the film `{}` is not supported (hdrfilm is)", film.plugin.kind)));
        }
        let width = f.integer("width")?.unwrap_or(DEFAULT_FILM.0);
        let height = f.integer("height")?.unwrap_or(DEFAULT_FILM.1);
        if !(1..=16384).contains(&width) || !(1..=16384).contains(&height) {
            return Err(f.error(format!("the film must be 1..=16384 pixels each way, got {width}×{height}")));
        }
        let crop = [
            f.integer("crop_offset_x")?.is_some_and(|x| x != 0),
            f.integer("crop_offset_y")?.is_some_and(|x| x != 0),
            f.integer("crop_width")?.is_some_and(|x| x != width),
            f.integer("crop_height")?.is_some_and(|x| x != height),
        ];
        if crop.iter().any(|&c| c) {
            return Err(f.error("a crop window is not supported: render the whole film"));
        }
        // How Mitsuba writes its output file; photonfarm writes its own outputs.
        f.ignore(&["pixel_format", "component_format", "file_format", "sample_border", "banner"]);
        for rfilter in f.children_of(Category::ReconstructionFilter) {
            if rfilter.plugin.kind != "box" {
                self.notes.push(format!(
                    "{} at {} is rendered with a box filter (photonfarm's pixel is the box-filtered radiance)",
                    rfilter.plugin.element(),
                    rfilter.plugin.position
                ));
            }
        }
        f.finish()?;
        Ok((width as u32, height as u32))
    }

    /// The sampler, which photonfarm replaces by its own: noted.
    fn sampler(&mut self, sensor: &Params) -> Result<(), MitsubaError> {
        for sampler in sensor.children_of(Category::Sampler) {
            let count = match sampler.plugin.param("sample_count").map(|p| &p.value) {
                Some(crate::scene::mitsuba::Value::Integer(n)) => format!(" with sample_count {n}"),
                _ => String::new(),
            };
            self.notes.push(format!(
                "{}{count} is ignored: photonfarm samples until its own stop (--time, --phases)",
                sampler.plugin.element()
            ));
        }
        Ok(())
    }
}

/// The horizontal field of view in degrees, from `fov` and `fov_axis` or from `focal_length`, as Mitsuba's
/// `parse_fov` computes it for a film of `aspect` = width / height.
fn fov_x(p: &Params, aspect: f64) -> Result<f64, MitsubaError> {
    let fov = p.float("fov")?;
    let focal = p.get("focal_length");
    let fov = match (fov, focal) {
        (Some(_), Some(param)) => return Err(p.error_at(param, "give fov or focal_length, not both")),
        (Some(fov), None) => fov,
        (None, focal) => {
            let text = match focal {
                Some(param) => match &param.value {
                    crate::scene::mitsuba::Value::String(s) => s.clone(),
                    crate::scene::mitsuba::Value::Float(x) => format!("{x}"),
                    _ => return Err(p.error_at(param, "must be a <string> such as \"50mm\"")),
                },
                None => "50mm".to_string(),
            };
            let mm: f64 = text
                .trim()
                .trim_end_matches("mm")
                .parse()
                .map_err(|_| p.error(format!("focal_length \"{text}\" is not a length such as \"50mm\"")))?;
            if mm <= 0.0 {
                return Err(p.error(format!("focal_length must be positive, got {text}")));
            }
            // A 35 mm film is 36 mm wide.
            2.0 * (36.0 / (2.0 * mm)).atan().to_degrees()
        }
    };
    if !(fov > 0.0 && fov < 180.0) {
        return Err(p.error(format!("fov must be between 0 and 180 degrees, got {fov}")));
    }
    let axis = p.string("fov_axis")?.unwrap_or("x");
    let tan = (0.5 * fov.to_radians()).tan();
    let from_y = |tan: f64| 2.0 * (tan * aspect).atan().to_degrees();
    Ok(match axis {
        "x" => fov,
        "y" => from_y(tan),
        "diagonal" => {
            let width = 2.0 * tan / (1.0 + 1.0 / (aspect * aspect)).sqrt();
            2.0 * (0.5 * width).atan().to_degrees()
        }
        "smaller" if aspect > 1.0 => from_y(tan),
        "smaller" => fov,
        "larger" if aspect > 1.0 => fov,
        "larger" => from_y(tan),
        other => return Err(p.error(format!("fov_axis \"{other}\" is not one of x, y, diagonal, smaller, larger"))),
    })
}

/// The camera's position, a point it looks at and its up, from Mitsuba's camera-to-world matrix (+z forward,
/// +y up, +x to the image's left); refused when it mirrors or shears the image.
fn camera_frame(m: &DMat4) -> Result<(Vec3, Vec3, Vec3), String> {
    let position = m.transform_point3(DVec3::ZERO);
    let left = m.transform_vector3(DVec3::X);
    let up = m.transform_vector3(DVec3::Y);
    let forward = m.transform_vector3(DVec3::Z);
    let lengths = [left.length(), up.length(), forward.length()];
    if lengths.iter().any(|&l| l.is_nan() || l <= 1e-12) {
        return Err("the sensor's to_world collapses a direction".into());
    }
    let (l, u, f) = (left / lengths[0], up / lengths[1], forward / lengths[2]);
    let skew = l.dot(u).abs().max(l.dot(f).abs()).max(u.dot(f).abs());
    if skew > 1e-4 || (lengths[0] - lengths[1]).abs() > 1e-4 * lengths[0] {
        return Err("the sensor's to_world shears or stretches the image, which photonfarm's camera cannot".into());
    }
    if l.dot(u.cross(f)) < 0.0 {
        return Err("the sensor's to_world mirrors the image (a negative determinant), which photonfarm's camera \
                    cannot"
            .into());
    }
    let v = |d: DVec3| d.as_vec3();
    Ok((v(position), v(position + f), v(u)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_look_at_frame_gives_back_its_position_and_direction() {
        // Mitsuba's lookat from (1, 2, 3) towards the origin: columns left, up, forward, origin.
        let origin = DVec3::new(1.0, 2.0, 3.0);
        let dir = (-origin).normalize();
        let left = DVec3::Y.cross(dir).normalize();
        let m = DMat4::from_cols(left.extend(0.0), dir.cross(left).extend(0.0), dir.extend(0.0), origin.extend(1.0));
        let (p, at, up) = camera_frame(&m).unwrap();
        assert!((p - Vec3::new(1.0, 2.0, 3.0)).length() < 1e-5);
        assert!(((at - p).normalize() - (-p).normalize()).length() < 1e-5);
        assert!(up.dot(Vec3::Y) > 0.8 && up.dot(at - p).abs() < 1e-5, "{up}");
        let mirrored = m * DMat4::from_scale(DVec3::new(-1.0, 1.0, 1.0));
        assert!(camera_frame(&mirrored).unwrap_err().contains("mirrors"));
    }
}
