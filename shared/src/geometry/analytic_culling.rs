//! The analytic surfaces' boxes, so that a ray is solved only against the surfaces whose box its segment
//! crosses, and not at all when it misses the box around them all (most rays, in a room with a lens).
//!
//! A ray between the surfaces of a lens crosses nearly every box of the lens, so the boxes are tested four at
//! a time: their corners and margins are stored by lane, and one slab test in `Vec4`s answers for four boxes.

use super::analytic::{Analytic, Bounds};
use super::ray::slab_entry;
use glam::{Vec3, Vec4};
use std::ops::ControlFlow;

/// Four boxes, one per lane: corners per axis, the coefficients of their rounding margin (`Bounds::margin`), and
/// the distance of each box's anchor from the anchor of the box around all surfaces.
#[derive(Clone, Copy, Debug)]
struct FourBoxes {
    min: [Vec4; 3],
    max: [Vec4; 3],
    quadratic: Vec4,
    linear: Vec4,
    constant: Vec4,
    anchor_offset: Vec4,
}

/// The analytic surfaces' boxes (in the order of the surfaces), four to a `FourBoxes`.
pub(super) struct AnalyticCulling {
    boxes: Vec<FourBoxes>,
    count: usize,
    all: Option<Bounds>,
    pub(super) enabled: bool,
}

impl AnalyticCulling {
    /// The boxes of the given surfaces.
    pub(super) fn new(analytic: &[(u32, Analytic)]) -> Self {
        let bounds: Vec<Bounds> = analytic.iter().map(|(_, a)| a.bounds()).collect();
        let all = bounds
            .iter()
            .skip(1)
            .fold(bounds.first().copied(), |all, b| all.map(|all| all.union(b, (b.anchor - all.anchor).length())));
        let boxes = match &all {
            Some(all) => bounds
                .chunks(4)
                .map(|four| {
                    // A missing lane repeats the chunk's first box; `each_crossing` never reports it.
                    let lane = |l: usize| four.get(l).unwrap_or(&four[0]);
                    let per_lane =
                        |f: &dyn Fn(&Bounds) -> f32| Vec4::new(f(lane(0)), f(lane(1)), f(lane(2)), f(lane(3)));
                    let (quadratic, linear, constant) = (
                        per_lane(&|b| b.margin_coefficients().0),
                        per_lane(&|b| b.margin_coefficients().1),
                        per_lane(&|b| b.margin_coefficients().2),
                    );
                    FourBoxes {
                        min: [0, 1, 2].map(|k| per_lane(&|b| b.min[k])),
                        max: [0, 1, 2].map(|k| per_lane(&|b| b.max[k])),
                        quadratic,
                        linear,
                        constant,
                        anchor_offset: per_lane(&|b| (b.anchor - all.anchor).length()),
                    }
                })
                .collect(),
            None => Vec::new(),
        };
        AnalyticCulling { boxes, count: analytic.len(), all, enabled: true }
    }

    /// The culling state of the ray from `origin` with `inv` = `slab_inverse(direction)`, or `None` when its
    /// segment [t0, t1] misses every surface's box.
    #[inline]
    pub(super) fn probe(&self, origin: Vec3, inv: Vec3, t0: f32, t1: f32) -> Option<Probe> {
        let all = self.all.as_ref()?;
        let probe = Probe { origin, inv, distance: (origin - all.anchor).length(), enabled: self.enabled };
        (!self.enabled || probe.crosses(all, t0, t1)).then_some(probe)
    }
}

/// One ray against the analytic surfaces' boxes.
pub(super) struct Probe {
    origin: Vec3,
    inv: Vec3,
    /// The distance from the origin to the anchor of the box around all surfaces.
    distance: f32,
    pub(super) enabled: bool,
}

impl Probe {
    /// Calls `f` with the index of each surface whose box the segment [t0, t1] of the ray crosses, in index
    /// order, and where the segment enters it, until `f` breaks. With culling disabled every surface is
    /// reported, entered at `t0`.
    ///
    /// The slab test is against each box widened by twice its rounding margin, so that every point the surface's
    /// `intersect` returns lies inside it by a margin that also covers the slab test's own rounding.
    #[inline]
    pub(super) fn each_crossing(
        &self,
        culling: &AnalyticCulling,
        t0: f32,
        t1: f32,
        mut f: impl FnMut(usize, f32) -> ControlFlow<()>,
    ) {
        if !self.enabled {
            for i in 0..culling.count {
                if f(i, t0).is_break() {
                    return;
                }
            }
            return;
        }
        let origin = [self.origin.x, self.origin.y, self.origin.z].map(Vec4::splat);
        let inv = [self.inv.x, self.inv.y, self.inv.z].map(Vec4::splat);
        let distance = Vec4::splat(self.distance);
        for (q, four) in culling.boxes.iter().enumerate() {
            let d = distance + four.anchor_offset;
            let pad = ((four.quadratic * d + four.linear) * d + four.constant) * 2.0;
            let mut enter = Vec4::splat(t0);
            let mut exit = Vec4::splat(t1);
            for k in 0..3 {
                let a = (four.min[k] - pad - origin[k]) * inv[k];
                let c = (four.max[k] + pad - origin[k]) * inv[k];
                enter = enter.max(a.min(c));
                exit = exit.min(a.max(c));
            }
            let mut crossed = enter.cmple(exit).bitmask();
            while crossed != 0 {
                let lane = crossed.trailing_zeros() as usize;
                crossed &= crossed - 1;
                let i = 4 * q + lane;
                if i >= culling.count {
                    return;
                }
                if f(i, enter[lane]).is_break() {
                    return;
                }
            }
        }
    }

    /// The slab test of `each_crossing` against one box.
    #[inline]
    fn crosses(&self, b: &Bounds, t0: f32, t1: f32) -> bool {
        let pad = Vec3::splat(2.0 * b.margin(self.distance));
        slab_entry(b.min - pad, b.max + pad, self.origin, self.inv, t0, t1).is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::analytic::{Annulus, LensSurface, Sphere};
    use crate::geometry::ray::slab_inverse;

    fn surfaces() -> Vec<(u32, Analytic)> {
        // Nine surfaces (two full lanes and one of a third), stacked along z like a lens, and a sphere off axis.
        let mut s: Vec<(u32, Analytic)> = (0..8)
            .map(|i| {
                let z = -0.004 * i as f32;
                let a = if i % 2 == 0 {
                    Analytic::Lens(LensSurface {
                        vertex: Vec3::new(0.0, 0.0, z),
                        axis: -Vec3::Z,
                        curvature_radius: 0.03 * if i % 4 == 0 { 1.0 } else { -1.0 },
                        aperture_radius: 0.01,
                    })
                } else {
                    Analytic::Annulus(Annulus {
                        center: Vec3::new(0.0, 0.0, z - 0.001),
                        axis: -Vec3::Z,
                        inner_radius: 0.01,
                        outer_radius: 0.02,
                    })
                };
                (i, a)
            })
            .collect();
        s.push((8, Analytic::Sphere(Sphere { center: Vec3::new(0.3, 0.1, 1.0), radius: 0.05 })));
        s
    }

    #[test]
    fn four_boxes_at_a_time_report_exactly_the_boxes_one_box_at_a_time_crosses() {
        let analytic = surfaces();
        let culling = AnalyticCulling::new(&analytic);
        let bounds: Vec<Bounds> = analytic.iter().map(|(_, a)| a.bounds()).collect();
        let all = culling.all.unwrap();
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let (mut crossings, mut misses) = (0, 0);
        for _ in 0..20_000 {
            let origin = Vec3::new(0.06 * (next() - 0.5), 0.06 * (next() - 0.5), 0.01 - 0.05 * next());
            let mut direction = Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5).normalize();
            if next() < 0.1 {
                direction = Vec3::Z * direction.z.signum(); // parallel to two slabs
            }
            let t1 = if next() < 0.5 { f32::INFINITY } else { 0.05 * next() };
            let Some(probe) = culling.probe(origin, slab_inverse(direction), 1e-7, t1) else { continue };
            let mut four = Vec::new();
            probe.each_crossing(&culling, 1e-7, t1, |i, enter| {
                four.push((i, enter));
                ControlFlow::Continue(())
            });
            let one: Vec<(usize, f32)> = bounds
                .iter()
                .enumerate()
                .filter_map(|(i, b)| {
                    let offset = (b.anchor - all.anchor).length();
                    let pad = Vec3::splat(2.0 * b.margin(probe.distance + offset));
                    let a = (b.min - pad - origin) * probe.inv;
                    let c = (b.max + pad - origin) * probe.inv;
                    let enter = a.min(c).max_element().max(1e-7);
                    (enter <= a.max(c).min_element().min(t1)).then_some((i, enter))
                })
                .collect();
            assert_eq!(four, one, "ray from {origin} toward {direction}, t1 = {t1}");
            crossings += one.len();
            misses += analytic.len() - one.len();
        }
        assert!(crossings > 10_000 && misses > 10_000, "{crossings} crossings, {misses} misses");
    }

    #[test]
    fn a_break_stops_the_crossings_and_disabled_culling_reports_every_surface() {
        let analytic = surfaces();
        let mut culling = AnalyticCulling::new(&analytic);
        let probe = culling.probe(Vec3::new(0.0, 0.0, 0.05), slab_inverse(-Vec3::Z), 1e-7, f32::INFINITY).unwrap();
        let mut seen = Vec::new();
        probe.each_crossing(&culling, 1e-7, f32::INFINITY, |i, _| {
            seen.push(i);
            if seen.len() == 3 {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        });
        assert_eq!(seen, [0, 1, 2]);
        culling.enabled = false;
        let probe = culling.probe(Vec3::new(5.0, 5.0, 5.0), slab_inverse(Vec3::X), 1e-7, f32::INFINITY).unwrap();
        let mut seen = Vec::new();
        probe.each_crossing(&culling, 1e-7, f32::INFINITY, |i, enter| {
            assert_eq!(enter, 1e-7);
            seen.push(i);
            ControlFlow::Continue(())
        });
        assert_eq!(seen, (0..analytic.len()).collect::<Vec<_>>());
    }
}
