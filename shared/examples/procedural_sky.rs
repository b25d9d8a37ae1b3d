//! Writes a procedural HDR sky with a sun disc as an equirectangular OpenEXR map, for the outdoor scenes'
//! environment light: a blue gradient from the zenith to a pale horizon, a glow around the sun, a grey ground
//! below the horizon and the sun's disc. Deterministic: the same arguments give the same file.
//!
//! `cargo run --release -p photonfarm --example procedural_sky -- OUT.exr [--width 2048] [--height 1024]
//! [--sun-elevation 35] [--sun-azimuth 120] [--sun-radius 0.267] [--sun-irradiance 30]`
//!
//! The map is in Mitsuba 3's `envmap` orientation (docs/estimator.md, "Infinite lights"): +Y up, the top row
//! the zenith. Angles are in degrees; the sun's azimuth turns from −Z (azimuth 0, the map's left edge) toward
//! +X (azimuth 90, a quarter across), which is the map's u = azimuth / 360. Its irradiance (on a plane facing
//! it) is in the map's radiance units times sr; the sky's zenith radiance is about 0.5 in blue.

use exr::prelude::{Encoding, Image, SpecificChannels, Vec2, WritableImage};
use glam::Vec3;
use std::f32::consts::PI;
use std::path::PathBuf;

/// The procedural sky's parameters.
struct Sky {
    width: usize,
    height: usize,
    sun: Vec3,
    /// The cosine of the sun's angular radius.
    cos_radius: f32,
    sun_radiance: Vec3,
}

/// Sub-samples per texel edge near the sun, so that its small disc keeps its irradiance.
const SUN_SUBSAMPLES: usize = 8;

impl Sky {
    /// The radiance of the sky without the sun's disc, arriving from `d` (unit).
    fn background(&self, d: Vec3) -> Vec3 {
        let zenith = Vec3::new(0.12, 0.25, 0.55);
        let horizon = Vec3::new(0.75, 0.85, 1.0);
        if d.y < 0.0 {
            // A grey ground lit by the sun and the sky, darker toward the nadir.
            return Vec3::new(0.22, 0.2, 0.18) * (0.6 + 0.4 * (1.0 + d.y));
        }
        let t = (1.0 - d.y).powi(4);
        let gamma = d.dot(self.sun).clamp(-1.0, 1.0).acos();
        let glow = Vec3::new(1.0, 0.85, 0.6) * (1.5 * (-gamma / 0.12).exp() + 0.3 * (-gamma / 0.6).exp());
        zenith * (1.0 - t) + horizon * t + glow
    }

    /// The direction of (u, v) of the map.
    fn direction(u: f32, v: f32) -> Vec3 {
        let (sin_theta, cos_theta) = (PI * v).sin_cos();
        let (sin_phi, cos_phi) = (2.0 * PI * u).sin_cos();
        Vec3::new(sin_phi * sin_theta, cos_theta, -cos_phi * sin_theta)
    }

    /// The texel (x, y): the background at its centre, plus the sun's disc averaged over the texel's area
    /// where the sun is near; and the sun's part alone.
    fn texel(&self, x: usize, y: usize) -> (Vec3, Vec3) {
        let u = (x as f32 + 0.5) / self.width as f32;
        let v = y as f32 / (self.height - 1) as f32;
        let centre = Self::direction(u, v);
        let background = self.background(centre);
        // Texels more than a few texel widths from the sun cannot touch its disc.
        let reach = (2.0 * PI / self.width as f32).max(PI / (self.height - 1) as f32) * 2.0;
        if centre.dot(self.sun) < (self.cos_radius.acos() + reach).min(PI).cos() {
            return (background, Vec3::ZERO);
        }
        let mut covered = 0usize;
        for i in 0..SUN_SUBSAMPLES {
            for j in 0..SUN_SUBSAMPLES {
                let du = ((i as f32 + 0.5) / SUN_SUBSAMPLES as f32 - 0.5) / self.width as f32;
                let dv = ((j as f32 + 0.5) / SUN_SUBSAMPLES as f32 - 0.5) / (self.height - 1) as f32;
                let d = Self::direction(u + du, (v + dv).clamp(0.0, 1.0));
                if d.dot(self.sun) >= self.cos_radius {
                    covered += 1;
                }
            }
        }
        let sun = self.sun_radiance * (covered as f32 / (SUN_SUBSAMPLES * SUN_SUBSAMPLES) as f32);
        (background + sun, sun)
    }
}

fn parse_args() -> Result<(PathBuf, Sky, f32), String> {
    let mut args = std::env::args().skip(1);
    let mut output = None;
    let (mut width, mut height) = (2048usize, None);
    let (mut elevation, mut azimuth, mut radius, mut irradiance) = (35.0f32, 120.0f32, 0.267f32, 30.0f32);
    while let Some(arg) = args.next() {
        let mut value = |name: &str| args.next().ok_or(format!("{name} needs a value"));
        match arg.as_str() {
            "--width" => width = value("--width")?.parse().map_err(|e| format!("--width: {e}"))?,
            "--height" => height = Some(value("--height")?.parse().map_err(|e| format!("--height: {e}"))?),
            "--sun-elevation" => elevation = value(&arg)?.parse().map_err(|e| format!("{arg}: {e}"))?,
            "--sun-azimuth" => azimuth = value(&arg)?.parse().map_err(|e| format!("{arg}: {e}"))?,
            "--sun-radius" => radius = value(&arg)?.parse().map_err(|e| format!("{arg}: {e}"))?,
            "--sun-irradiance" => irradiance = value(&arg)?.parse().map_err(|e| format!("{arg}: {e}"))?,
            _ if arg.starts_with("--") => return Err(format!("unknown option {arg}")),
            _ if output.is_none() => output = Some(PathBuf::from(arg)),
            _ => return Err(format!("unexpected argument {arg}")),
        }
    }
    let output = output.ok_or("usage: procedural_sky OUT.exr [--width W] [--height H] [--sun-elevation DEG] [--sun-azimuth DEG] [--sun-radius DEG] [--sun-irradiance E]")?;
    let height = height.unwrap_or(width / 2);
    if width < 4 || height < 3 {
        return Err(format!("the map must be at least 4 × 3 texels, not {width} × {height}"));
    }
    if !(-90.0..=90.0).contains(&elevation) || !azimuth.is_finite() {
        return Err(format!("the sun's elevation {elevation} must lie in [−90, 90] and its azimuth be finite"));
    }
    if !(radius > 0.0 && radius < 10.0 && irradiance.is_finite() && irradiance >= 0.0) {
        return Err(format!(
            "the sun's radius {radius} must lie in (0, 10) degrees and its irradiance {irradiance} be ≥ 0"
        ));
    }
    let (el, az, r) = (elevation.to_radians(), azimuth.to_radians(), radius.to_radians());
    let sun = Vec3::new(az.sin() * el.cos(), el.sin(), -az.cos() * el.cos());
    // Uniform radiance L over a cone of radius α gives E = L π sin² α at normal incidence.
    let sun_radiance = Vec3::new(1.0, 0.93, 0.85) * (irradiance / (PI * r.sin().powi(2)));
    Ok((output, Sky { width, height, sun, cos_radius: r.cos(), sun_radiance }, irradiance))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (output, sky, irradiance) = parse_args()?;
    let (w, h) = (sky.width, sky.height);
    let mut texels = vec![Vec3::ZERO; w * h];
    // The sun's irradiance as the map holds it: its part of each texel times the texel's solid angle (of its
    // bilinear footprint, 2π/W · π/(H − 1) · sin θ) and the cosine to the sun.
    let mut sun_irradiance = 0.0f64;
    for y in 0..h {
        let sin_theta = (PI * y as f32 / (h - 1) as f32).sin();
        for x in 0..w {
            let (texel, sun) = sky.texel(x, y);
            texels[y * w + x] = texel;
            if sun != Vec3::ZERO {
                let d = Sky::direction((x as f32 + 0.5) / w as f32, y as f32 / (h - 1) as f32);
                let solid_angle = 2.0 * PI / w as f32 * PI / (h - 1) as f32 * sin_theta;
                sun_irradiance += (sun.x * solid_angle * d.dot(sky.sun)) as f64;
            }
        }
    }
    // ZIP-compressed, so that a small map can live in the repository.
    let image = Image::from_encoded_channels(
        (w, h),
        Encoding::SMALL_LOSSLESS,
        SpecificChannels::rgb(|p: Vec2<usize>| {
            let t = texels[p.y() * w + p.x()];
            (t.x, t.y, t.z)
        }),
    );
    image.write().to_file(&output)?;
    println!(
        "wrote {} ({w} × {h}); the sun's disc in the map gives irradiance {:.3} (red) for {irradiance:.3} asked",
        output.display(),
        sun_irradiance
    );
    Ok(())
}
