//! The `[camera]` table: a pinhole, thin-lens or sensor camera.

use super::state::Loader;
use crate::scene::description::{CameraDesc, LensDesc};
use crate::scene::file::CameraSection;
use crate::scene::SceneError;
use toml::Spanned;

impl Loader<'_> {
    /// The camera; a sensor camera's rear element, a lens surface of the scene, is found by the build step.
    pub(super) fn camera(&self, c: &Spanned<CameraSection>) -> Result<CameraDesc, SceneError> {
        let cam = c.get_ref();
        let position = self.vec3(*cam.position.get_ref(), &cam.position.span(), "camera.position")?;
        let look_at = self.vec3(*cam.look_at.get_ref(), &cam.look_at.span(), "camera.look_at")?;
        let up = self.vec3(*cam.up.get_ref(), &cam.up.span(), "camera.up")?;
        let forward = look_at - position;
        if forward.length_squared() == 0.0 {
            return Err(self.error(Some(cam.look_at.span()), "camera.look_at", "must differ from camera.position"));
        }
        if forward.normalize().cross(up).length_squared() < 1e-8 {
            return Err(self.error(Some(cam.up.span()), "camera.up", "must not be parallel to the view direction"));
        }
        for (v, name) in [(&cam.width, "camera.width"), (&cam.height, "camera.height")] {
            if !(1..=16384).contains(v.get_ref()) {
                return Err(self.error(Some(v.span()), name, format!("must be 1..=16384 pixels, got {}", v.get_ref())));
            }
        }
        let (width, height) = (*cam.width.get_ref(), *cam.height.get_ref());
        let kind = cam.kind.get_ref().as_str();
        match kind {
            "pinhole" | "thin_lens" => {}
            "sensor" => {
                let lens = self.sensor_camera(c)?;
                return Ok(CameraDesc { position, look_at, up, width, height, lens });
            }
            other => {
                return Err(self.error(
                    Some(cam.kind.span()),
                    "camera.type",
                    format!("unknown camera type '{other}' (known: pinhole, thin_lens, sensor)"),
                ));
            }
        }
        let fov = cam.fov_y_deg.as_ref().ok_or_else(|| {
            self.error(
                Some(c.span()),
                "camera.fov_y_deg",
                format!("a {kind} camera needs fov_y_deg (the full vertical field of view in degrees)"),
            )
        })?;
        let fov = self.scalar(
            *fov.get_ref(),
            &fov.span(),
            "camera.fov_y_deg",
            |v| v > 0.0 && v < 180.0,
            "between 0 and 180 degrees",
        )?;
        let lens = if kind == "pinhole" { LensDesc::Pinhole { fov_y_deg: fov } } else { self.thin_lens(c, fov)? };
        Ok(CameraDesc { position, look_at, up, width, height, lens })
    }

    /// A thin lens: its radius and the distance it focuses at.
    fn thin_lens(&self, c: &Spanned<CameraSection>, fov_y_deg: f32) -> Result<LensDesc, SceneError> {
        let cam = c.get_ref();
        let radius = cam.lens_radius.as_ref().ok_or_else(|| {
            self.error(Some(c.span()), "camera.lens_radius", "a thin_lens camera needs lens_radius (m)")
        })?;
        let focus = cam.focus_distance.as_ref().ok_or_else(|| {
            self.error(Some(c.span()), "camera.focus_distance", "a thin_lens camera needs focus_distance (m)")
        })?;
        Ok(LensDesc::Thin {
            fov_y_deg,
            radius: self.scalar(
                *radius.get_ref(),
                &radius.span(),
                "camera.lens_radius",
                |v| v > 0.0,
                "a positive number",
            )?,
            focus_distance: self.scalar(
                *focus.get_ref(),
                &focus.span(),
                "camera.focus_distance",
                |v| v > 0.0,
                "a positive number",
            )?,
        })
    }

    /// A sensor behind a lens of the scene: `position` is the sensor's centre, `look_at` a point along the
    /// optical axis in front of it, and `rear_element` names the lens surface nearest the sensor.
    fn sensor_camera(&self, c: &Spanned<CameraSection>) -> Result<LensDesc, SceneError> {
        let cam = c.get_ref();
        if let Some(fov) = &cam.fov_y_deg {
            return Err(self.error(
                Some(fov.span()),
                "camera.fov_y_deg",
                "a sensor camera's field of view follows from sensor_width and the lens: remove fov_y_deg",
            ));
        }
        let sensor_width = cam.sensor_width.as_ref().ok_or_else(|| {
            self.error(Some(c.span()), "camera.sensor_width", "a sensor camera needs sensor_width (m)")
        })?;
        let sensor_width = self.scalar(
            *sensor_width.get_ref(),
            &sensor_width.span(),
            "camera.sensor_width",
            |v| v > 0.0,
            "a positive width in metres",
        )?;
        let rear_name = cam.rear_element.as_ref().ok_or_else(|| {
            self.error(
                Some(c.span()),
                "camera.rear_element",
                "a sensor camera needs rear_element, the name of the lens_surface object nearest the sensor",
            )
        })?;
        Ok(LensDesc::Sensor {
            sensor_width,
            rear_element: rear_name.get_ref().clone(),
            rear_source: self.source(Some(rear_name.span()), "camera.rear_element"),
        })
    }
}
