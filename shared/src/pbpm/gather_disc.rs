//! The area a backward photon gathers over. A light-path vertex merges with the photon when it lies within
//! the radius r on a surface that agrees with the photon's, so the photon estimates the flux density over the
//! part of its disc of radius r that lies on its own surface. Near the edge of a wall that part is smaller
//! than π r², and dividing by π r² would darken every pixel along every edge and corner; eq. 4 is therefore
//! normalised by the area of the disc on the surface, which is π r² wherever the surface goes on. The inner
//! disc that measures the photon's blur (`inner_disc`) gets its area on the surface from the same cuts.

use super::inner_disc::INNER_RADIUS2;
use crate::geometry::{SceneGeometry, SurfaceHit};
use glam::Vec3;
use std::f32::consts::PI;

/// The disc is never taken for less than this share of π r²: a photon in the very tip of a thin sliver would
/// otherwise carry a weight without bound for the little light that lands there.
const MIN_SHARE: f32 = 0.05;

/// Points of the disc where two or more ends of the surface cut it, a sunflower (Vogel) spiral of equal areas.
const SPIRAL_POINTS: usize = 256;

/// The areas on the surface of a photon's disc and of its inner disc, the concentric one of radius r/√2 and
/// half its area (`inner_disc::INNER_RADIUS2`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DiscAreas {
    pub whole: f32,
    pub inner: f32,
}

impl DiscAreas {
    /// The inner disc's share of the photon's gather area, A(r/√2) / A(r), in 256ths (`BackwardPhoton::
    /// inner_share`): exactly 128 where the disc lies whole on its surface. Both areas are on the surface, so
    /// that an edge or a corner does not look like blur.
    pub fn inner_share(self) -> u8 {
        (self.inner / self.whole * 256.0).round().clamp(1.0, 255.0) as u8
    }
}

/// The areas of the discs of radius `r` and r/√2 around `hit.p` that lie on `hit`'s surface: π r² (π r²/2)
/// minus what lies past the edges of the hit triangle that end the surface (`SceneGeometry::surface_edges`).
/// One such edge within r cuts off a circular segment, computed exactly; where two or more cut the disc (a
/// corner), the areas are counted on a fixed spiral of points. Analytic surfaces have no edges in a disc's
/// reach.
pub fn gather_disc_areas(geometry: &SceneGeometry, hit: &SurfaceHit, r: f32) -> DiscAreas {
    let full = PI * r * r;
    let whole_disc = DiscAreas { whole: full, inner: INNER_RADIUS2 * full };
    if hit.triangle == u32::MAX {
        return whole_disc;
    }
    let ends = geometry.surface_edges(hit.triangle);
    if ends == 0 {
        return whole_disc;
    }
    let t = geometry.triangle(hit.triangle);
    // Each cutting edge as (inward unit direction in the triangle's plane, distance of the centre from it).
    let mut cuts = [(Vec3::ZERO, 0.0f32); 3];
    let mut n = 0;
    for i in (0..3).filter(|i| ends & (1 << i) != 0) {
        let (a, b, c) = (t.v[i], t.v[(i + 1) % 3], t.v[(i + 2) % 3]);
        let edge = b - a;
        let inward = ((c - a) - edge * ((c - a).dot(edge) / edge.length_squared())).normalize_or_zero();
        let d = (hit.p - a).dot(inward).max(0.0);
        if inward != Vec3::ZERO && d < r {
            cuts[n] = (inward, d);
            n += 1;
        }
    }
    let (whole, inner) = match n {
        0 => return whole_disc,
        1 => (
            full - circular_segment(r, cuts[0].1),
            INNER_RADIUS2 * full - circular_segment(r * INNER_RADIUS2.sqrt(), cuts[0].1),
        ),
        _ => {
            let (whole, inner) = spiral_shares(&cuts[..n], r);
            (full * whole, INNER_RADIUS2 * full * inner)
        }
    };
    DiscAreas { whole: whole.max(MIN_SHARE * full), inner: inner.max(MIN_SHARE * INNER_RADIUS2 * full) }
}

/// Area of the part of a disc of radius r beyond a chord at distance d ≤ r from its centre.
fn circular_segment(r: f32, d: f32) -> f32 {
    let d = d.clamp(0.0, r);
    r * r * (d / r).acos() - d * (r * r - d * d).max(0.0).sqrt()
}

/// The share of the disc's spiral points on the inner side of every cut, and the same share among the inner
/// disc's points: the spiral's first half, which is a spiral of equal areas over the disc of radius r/√2. The
/// cuts' directions lie in the disc's plane, so any orthonormal pair of that plane places the spiral; the first
/// cut's direction and its normal within the plane are used.
fn spiral_shares(cuts: &[(Vec3, f32)], r: f32) -> (f32, f32) {
    let u = cuts[0].0;
    let plane_normal = u.cross(cuts[1].0).normalize_or_zero();
    // Parallel cuts (a thin strip) leave the plane's normal unknown, but then every cut is ±u and only the
    // points' u coordinates matter.
    let v = plane_normal.cross(u);
    let golden_angle = PI * (3.0 - 5f32.sqrt());
    let inside = |k: &usize| {
        let rho = r * ((*k as f32 + 0.5) / SPIRAL_POINTS as f32).sqrt();
        let (s, c) = (*k as f32 * golden_angle).sin_cos();
        let q = u * (rho * c) + v * (rho * s);
        cuts.iter().all(|&(inward, d)| q.dot(inward) + d >= 0.0)
    };
    // The points of an equal-area spiral within r/√2 are its first INNER_RADIUS2 share.
    let half = (SPIRAL_POINTS as f32 * INNER_RADIUS2) as usize;
    let inner = (0..half).filter(inside).count();
    let outer = (half..SPIRAL_POINTS).filter(inside).count();
    ((inner + outer) as f32 / SPIRAL_POINTS as f32, inner as f32 / half as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_chord_through_the_centre_cuts_off_half_the_disc_and_one_at_the_rim_nothing() {
        assert!((circular_segment(2.0, 0.0) - 0.5 * PI * 4.0).abs() < 1e-5);
        assert!(circular_segment(2.0, 2.0).abs() < 1e-6);
        // A chord at r/2 cuts off r²(π/3 − √3/4).
        let expect = 4.0 * (PI / 3.0 - 3f32.sqrt() / 4.0);
        assert!((circular_segment(2.0, 1.0) - expect).abs() < 1e-5);
    }

    #[test]
    fn the_spiral_counts_a_right_angled_corner_at_the_centre_as_a_quarter_of_the_disc() {
        let cuts = [(Vec3::X, 0.0), (Vec3::Y, 0.0)];
        assert!((spiral_shares(&cuts, 1.0).0 - 0.25).abs() < 0.01);
        // Two cuts at half the radius, against a fine grid's count of the disc's points with x, y ≥ −r/2.
        let cuts = [(Vec3::X, 0.5), (Vec3::Y, 0.5)];
        let fine = (0..2000 * 2000)
            .filter(|i| {
                let (x, y) = ((i % 2000) as f32 / 1000.0 - 1.0, (i / 2000) as f32 / 1000.0 - 1.0);
                x * x + y * y <= 1.0 && x >= -0.5 && y >= -0.5
            })
            .count() as f32
            / (2000.0 * 2000.0 / 4.0)
            / PI;
        assert!((spiral_shares(&cuts, 1.0).0 - fine).abs() < 0.01, "{} against {fine}", spiral_shares(&cuts, 1.0).0);
    }

    #[test]
    fn the_spirals_first_half_counts_the_inner_disc() {
        // A corner at the centre leaves a quarter of both discs.
        let (whole, inner) = spiral_shares(&[(Vec3::X, 0.0), (Vec3::Y, 0.0)], 1.0);
        assert!((whole - 0.25).abs() < 0.01 && (inner - 0.25).abs() < 0.02, "{whole} {inner}");
        // Two cuts at 0.4: the inner disc (radius 1/√2) against a fine grid's count of its points with x, y ≥ −0.4.
        let ri2 = 0.5f32;
        let (mut inside, mut all) = (0, 0);
        for i in 0..2000 * 2000 {
            let (x, y) = ((i % 2000) as f32 / 1000.0 - 1.0, (i / 2000) as f32 / 1000.0 - 1.0);
            if x * x + y * y <= ri2 {
                all += 1;
                inside += (x >= -0.4 && y >= -0.4) as u32;
            }
        }
        let fine = inside as f32 / all as f32;
        let (_, inner) = spiral_shares(&[(Vec3::X, 0.4), (Vec3::Y, 0.4)], 1.0);
        assert!((inner - fine).abs() < 0.02, "{inner} against {fine}");
    }

    #[test]
    fn parallel_cuts_of_a_strip_leave_the_strip() {
        // A strip |x| ≤ r/2: share = (area of the disc within the strip) / π r².
        let cuts = [(Vec3::X, 0.5), (-Vec3::X, 0.5)];
        let strip = (PI - 2.0 * circular_segment(1.0, 0.5)) / PI;
        assert!((spiral_shares(&cuts, 1.0).0 - strip).abs() < 0.01);
    }
}
