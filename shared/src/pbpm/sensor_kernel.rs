//! The sensor's disc for ghost chains (docs/estimator.md, "The ghost layer"). A ghost chain that registers on
//! one pixel is a point sample of a defocused image that covers thousands of pixels, so a pixel collects only a
//! few chains in a run. Spread over the pixels within r of where it landed, as eq. 4 spreads a light-path
//! vertex over a photon's disc, each chain serves all of them: a density estimate on the sensor. Its radius
//! shrinks with the phases by the photons' schedule (`RadiusSchedule`), so the average over phases converges,
//! and its blur is measured as theirs is, against an inner disc of r/√2 (`inner_disc`, `accumulation::blur`).

use super::radius::RadiusSchedule;

/// The disc a phase spreads each ghost registration over, in pixels of the image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorKernel {
    /// r², in pixels²: every pixel whose centre lies within r of the landing pixel's centre.
    radius2: f32,
    /// The factor that makes 2 × the disc's blur difference the disc's bias on a discrete grid (`blur_scale`).
    blur_scale: f32,
}

impl SensorKernel {
    /// One pixel: a registration stays where it landed.
    pub const POINT: SensorKernel = SensorKernel { radius2: 0.0, blur_scale: 0.0 };

    /// The disc of phase `j` (1-based) for an initial radius of `initial` pixels under `schedule`'s shrink.
    pub fn at_phase(initial: f32, schedule: &RadiusSchedule, j: u64) -> Self {
        let r = initial * schedule.shrink(j);
        if r < 1.0 {
            return SensorKernel::POINT;
        }
        SensorKernel { radius2: r * r, blur_scale: blur_scale(r * r) }
    }

    /// True when the disc holds only the landing pixel.
    #[inline]
    pub fn is_point(&self) -> bool {
        self.radius2 < 1.0
    }

    /// The disc's radius in pixels.
    pub fn radius(&self) -> f32 {
        self.radius2.sqrt()
    }

    /// Hands `add` every pixel of a `width` × `height` image within the disc about `pixel`, with its share of
    /// the registration and its share of the blur difference D per unit of the registration's luminance. The
    /// shares are 1 / (the disc's pixels inside the image), so a registration near the image's edge keeps all
    /// of its light, and the D shares sum to zero.
    #[inline]
    pub fn spread(&self, pixel: u32, width: u32, height: u32, mut add: impl FnMut(u32, f32, f32)) {
        if self.is_point() {
            add(pixel, 1.0, 0.0);
            return;
        }
        let (x, y) = ((pixel % width) as i32, (pixel / width) as i32);
        let outer = Disc::new(self.radius2, x, y, width, height);
        let inner = Disc::new(self.radius2 * super::inner_disc::INNER_RADIUS2, x, y, width, height);
        let (w_outer, w_inner) = (1.0 / outer.count() as f32, 1.0 / inner.count() as f32);
        for py in outer.rows() {
            let (Some(outer_x), inner_x) = (outer.columns(py), inner.columns(py)) else { continue };
            for px in outer_x {
                let in_inner = inner_x.as_ref().is_some_and(|c| c.contains(&px));
                let d = if in_inner { w_outer - w_inner } else { w_outer };
                add(py as u32 * width + px as u32, w_outer, d * self.blur_scale);
            }
        }
    }
}

/// A disc of pixel centres about (x, y), clipped to the image.
struct Disc {
    radius2: f32,
    x: i32,
    y: i32,
    reach: i32,
    width: i32,
    height: i32,
}

impl Disc {
    fn new(radius2: f32, x: i32, y: i32, width: u32, height: u32) -> Self {
        Disc { radius2, x, y, reach: radius2.sqrt() as i32, width: width as i32, height: height as i32 }
    }

    fn rows(&self) -> std::ops::RangeInclusive<i32> {
        (self.y - self.reach).max(0)..=(self.y + self.reach).min(self.height - 1)
    }

    /// The columns of row `py` inside the disc and the image; None for a row the disc does not reach.
    fn columns(&self, py: i32) -> Option<std::ops::RangeInclusive<i32>> {
        let dy = (py - self.y) as f32;
        let left = self.radius2 - dy * dy;
        if left < 0.0 {
            return None;
        }
        let half = left.sqrt() as i32;
        Some((self.x - half).max(0)..=(self.x + half).min(self.width - 1))
    }

    fn count(&self) -> u32 {
        self.rows().filter_map(|py| self.columns(py)).map(|c| c.count() as u32).sum()
    }
}

/// The factor k that makes 2 k E[D] the bias of the disc's estimate of a smooth image: the bias of an average
/// over a set of offsets is m/4 · ∇²E for m their mean squared distance (m/2 per axis), so b(outer) /
/// (b(outer) − b(inner)) = m_outer / (m_outer − m_inner), which is the 2 of `accumulation::blur` for continuous
/// discs and differs from it on a grid of a few pixels.
fn blur_scale(radius2: f32) -> f32 {
    // The disc's offsets, as a disc about the centre of an image just large enough to hold it.
    let mean_square = |r2: f32| {
        let reach = r2.sqrt() as i32;
        let side = (2 * reach + 1) as u32;
        let disc = Disc::new(r2, reach, reach, side, side);
        let sum: f64 = disc
            .rows()
            .filter_map(|py| Some((py - reach, disc.columns(py)?)))
            .flat_map(|(dy, columns)| columns.map(move |px| ((px - reach).pow(2) + dy * dy) as f64))
            .sum();
        sum / disc.count() as f64
    };
    let (outer, inner) = (mean_square(radius2), mean_square(radius2 * super::inner_disc::INNER_RADIUS2));
    if outer <= inner {
        return 0.0;
    }
    (outer / (outer - inner) / crate::accumulation::blur::BIAS_PER_DIFFERENCE) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    fn schedule() -> RadiusSchedule {
        RadiusSchedule { scale: 1.0, alpha: 2.0 / 3.0, pixel_angle: 0.01 }
    }

    #[test]
    fn a_registration_keeps_its_light_anywhere_on_the_image_and_its_blur_differences_cancel() {
        let kernel = SensorKernel::at_phase(4.5, &schedule(), 1);
        let (width, height) = (40u32, 30u32);
        for pixel in [0, 5, 39, 40 * 15 + 20, 40 * 29 + 39, 40 * 28 + 2] {
            let (mut light, mut d, mut pixels) = (0.0f64, 0.0f64, 0);
            kernel.spread(pixel, width, height, |p, w, b| {
                assert!(p < width * height);
                light += w as f64;
                d += b as f64;
                pixels += 1;
            });
            assert!((light - 1.0).abs() < 1e-5, "pixel {pixel}: {light}");
            assert!(d.abs() < 1e-5, "pixel {pixel}: {d}");
            assert!(pixels > 1);
        }
        // Inside the image the disc of r = 4.5 holds the 69 pixel centres within it.
        let mut inside = 0;
        kernel.spread(40 * 15 + 20, width, height, |_, _, _| inside += 1);
        assert_eq!(inside, 69);
    }

    #[test]
    fn the_disc_shrinks_by_the_photons_schedule_down_to_the_landing_pixel() {
        let s = schedule();
        let r = |j| SensorKernel::at_phase(6.0, &s, j).radius();
        assert!((r(1) - 6.0).abs() < 1e-5);
        assert!((r(64) - 6.0 * 64f32.powf(-1.0 / 6.0)).abs() < 1e-4);
        assert!(SensorKernel::at_phase(6.0, &s, 1 << 20).is_point());
        let mut seen = Vec::new();
        SensorKernel::POINT.spread(7, 10, 10, |p, w, d| seen.push((p, w, d)));
        assert_eq!(seen, vec![(7, 1.0, 0.0)]);
    }

    #[test]
    fn twice_the_scaled_blur_difference_is_the_discs_bias_on_a_quadratic_image() {
        // E = x² + y² about the landing pixel: the disc's estimate at its centre is off by its mean d², and
        // 2 × Σ D (over the registrations a uniform E brings, weighted by E at their landing points) is that.
        for r in [1.2f32, 2.0, 3.0, 4.5, 7.0] {
            let kernel = SensorKernel::at_phase(r, &schedule(), 1);
            let (width, height) = (64u32, 64u32);
            let centre = 32 * width + 32;
            // Every pixel's registration carries E at its landing pixel; sum what reaches the centre.
            let (mut estimate, mut d) = (0.0f64, 0.0f64);
            for landing in 0..width * height {
                let (dx, dy) = ((landing % width) as f64 - 32.0, (landing / width) as f64 - 32.0);
                let e = dx * dx + dy * dy;
                kernel.spread(landing, width, height, |p, w, b| {
                    if p == centre {
                        estimate += e * w as f64;
                        d += e * b as f64;
                    }
                });
            }
            let bias = estimate; // E at the centre is 0.
            let predicted = crate::accumulation::blur::BIAS_PER_DIFFERENCE * d;
            assert!((predicted - bias).abs() < 1e-3 * bias, "r {r}: bias {bias}, 2 D {predicted}");
        }
    }
}
