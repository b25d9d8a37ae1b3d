//! Light vertices held back and gathered in the order of the photon map's buckets. A light path's vertices
//! land anywhere in the scene, so gathering each as it is traced reads a random bucket's entries, photons and
//! pixels every time, and waits on memory for most of it. Gathered together in bucket order, a run of
//! vertices walks the map's entries and photons front to back (the map lays its photons out in bucket order)
//! and reuses what the previous vertex loaded. The gathers are the same; only the order of the additions into
//! each pixel changes, which moves the sums by f32 rounding.

use super::forward_pass::{gather_in_bucket, Gather, GatherPoint};
use super::photon_map::PhotonMap;
use crate::spectrum::PhaseSpectrum;

/// Vertices held back before a sorted gather; past this many the gather runs, so that the buffers stay bounded
/// whatever the image size.
pub const SORTED_GATHER_BATCH: usize = 1 << 15;

/// Light vertices waiting for one sorted gather into one map, with their buckets; every buffer keeps its room
/// from batch to batch.
#[derive(Debug)]
pub struct SortedGathers {
    /// The vertices in the order they came.
    points: Vec<GatherPoint>,
    /// (bucket << 32 | index into `points`): sorted, the gather order, ties in the order the vertices came.
    keys: Vec<u64>,
    /// The vertices in gather order: copied there first, so that the gathers read them front to back instead
    /// of waiting on each one.
    ordered: Vec<GatherPoint>,
    /// Vertices a batch holds.
    batch: usize,
}

impl Default for SortedGathers {
    fn default() -> Self {
        Self::with_batch(SORTED_GATHER_BATCH)
    }
}

impl SortedGathers {
    /// No vertex waiting, batches of `SORTED_GATHER_BATCH` vertices.
    pub fn new() -> Self {
        Self::default()
    }

    /// No vertex waiting, batches of `batch` vertices (at least one): for threads that hold vertices back for
    /// several maps at once, whose batches together must stay bounded.
    pub fn with_batch(batch: usize) -> Self {
        SortedGathers { points: Vec::new(), keys: Vec::new(), ordered: Vec::new(), batch: batch.max(1) }
    }

    /// Vertices a batch holds.
    pub fn batch(&self) -> usize {
        self.batch
    }

    /// Holds back a vertex that will gather into `map`. Call `gather_into` before `room` runs out: the
    /// buffers never grow past the batch.
    #[inline]
    pub fn push(&mut self, map: &PhotonMap, point: GatherPoint) {
        self.keys.push((map.bucket_of(point.p) as u64) << 32 | self.points.len() as u64);
        self.points.push(point);
    }

    /// Makes room for a whole batch at once, so that the buffers hold exactly a batch instead of growing by
    /// doubling past it.
    pub fn reserve_batch(&mut self) {
        self.points.reserve_exact(self.batch.saturating_sub(self.points.len()));
        self.keys.reserve_exact(self.batch.saturating_sub(self.keys.len()));
    }

    /// Vertices that can still be held back before the batch is full.
    pub fn room(&self) -> usize {
        self.batch.saturating_sub(self.points.len())
    }

    /// Vertices waiting.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// True when no vertex waits.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Gathers every waiting vertex, of a light path of the phase of wavelengths `phase`, into the `map` they
    /// were pushed for, in bucket order, as `forward_pass::gather` does one by one, and forgets them. Returns
    /// the merges.
    pub fn gather_into(
        &mut self,
        map: &PhotonMap,
        phase: &PhaseSpectrum,
        max_depth: u32,
        backward_diffuse_depth: u32,
        sink: &mut impl Gather,
    ) -> u64 {
        let Self { points, keys, ordered, .. } = self;
        keys.sort_unstable();
        ordered.clear();
        // Room for exactly this batch: `extend` would grow by doubling when a batch outgrows the last one, and
        // room for a whole batch would be held by threads and images that never fill one.
        ordered.reserve_exact(points.len());
        ordered.extend(keys.iter().map(|&k| points[k as u32 as usize]));
        let merges = keys
            .iter()
            .zip(ordered.iter())
            .map(|(&k, v)| gather_in_bucket(map, (k >> 32) as u32, v, phase, max_depth, backward_diffuse_depth, sink))
            .sum();
        points.clear();
        keys.clear();
        merges
    }

    /// Bytes held.
    pub fn capacity_bytes(&self) -> usize {
        (self.points.capacity() + self.ordered.capacity()) * std::mem::size_of::<GatherPoint>()
            + self.keys.capacity() * 8
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::color::Rgb;
    use crate::integrator::Layer;
    use crate::pbpm::forward_pass::gather_point;
    use crate::pbpm::{BackwardPhoton, PhotonKind};
    use crate::sampling::{Pass, Sampler};
    use glam::Vec3;

    /// Every add a gather makes, as (pixel, caustic, ghost, value bits).
    type Adds = Vec<(u32, bool, bool, [u32; 3])>;

    fn record(adds: &mut Adds) -> impl FnMut(u32, Layer, bool, Rgb) + '_ {
        |pixel, layer, ghost, v| adds.push((pixel, layer == Layer::Caustic, ghost, v.to_array().map(f32::to_bits)))
    }

    /// Photons on the three walls of a corner, facing into it, and light vertices on the same walls, so that
    /// normals, layers and path lengths all decide some merges.
    fn corner(s: &mut Sampler, pixel: u32) -> (Vec3, Vec3) {
        let (u, v) = (s.next_f32(), s.next_f32());
        match pixel % 3 {
            0 => (Vec3::new(u, v, 0.0), Vec3::Z),
            1 => (Vec3::new(0.0, u, v), Vec3::X),
            _ => (Vec3::new(v, 0.0, u), Vec3::Y),
        }
    }

    #[test]
    fn a_sorted_gather_makes_exactly_the_adds_of_gathering_each_vertex_as_it_comes() {
        let mut s = Sampler::new(3, Pass::Camera, 1, 1);
        let mut map = PhotonMap::new();
        for i in 0..20_000u32 {
            let (position, normal) = corner(&mut s, i);
            let r = 0.005 + 0.02 * s.next_f32();
            map.push(BackwardPhoton {
                position,
                normal,
                weight: Rgb::new(s.next_f32(), s.next_f32(), s.next_f32()),
                radius2: r * r,
                pixel: i % 997,
                kind: PhotonKind::new(1 + (i % 2) as u8, true, i % 7 == 0),
                segments: 1 + (i % 5) as u8,
                spectrum: 0,
                inner_share: 100 + (i % 50) as u8,
                stored: crate::pbpm::photon::LAMBERTIAN,
            });
        }
        map.build();
        // More vertices than a batch holds, so that the forward pass's mid-way gathers are exercised too.
        let points: Vec<GatherPoint> = (0..SORTED_GATHER_BATCH as u32 * 3 / 2)
            .map(|i| {
                let (p, ng) = corner(&mut s, i / 3);
                GatherPoint {
                    p,
                    ng,
                    wi: (ng + Vec3::new(s.next_f32(), s.next_f32(), s.next_f32()) - Vec3::splat(0.5)).normalize(),
                    flux: Rgb::new(s.next_f32(), s.next_f32(), s.next_f32()),
                    m: 2 + i % 9,
                    all_specular: i % 4 == 0,
                    all_pass: i % 4 == 0,
                    spectrum: 0,
                }
            })
            .collect();
        let phase = PhaseSpectrum::RGB;
        let (max_depth, bdd) = (8, 2);

        let mut one_by_one = Adds::new();
        let merges: u64 = {
            let mut sink = record(&mut one_by_one);
            points.iter().map(|v| gather_point(&map, v, &phase, max_depth, bdd, &mut sink)).sum()
        };

        let mut sorted_adds = Adds::new();
        let (sorted_merges, sorted_capacity) = {
            let mut sink = record(&mut sorted_adds);
            let mut sorted = SortedGathers::new();
            let mut merges = 0;
            for &v in &points {
                sorted.push(&map, v);
                if sorted.room() == 0 {
                    assert_eq!(sorted.len(), SORTED_GATHER_BATCH);
                    merges += sorted.gather_into(&map, &phase, max_depth, bdd, &mut sink);
                    assert!(sorted.is_empty());
                }
            }
            let merges = merges + sorted.gather_into(&map, &phase, max_depth, bdd, &mut sink);
            (merges, sorted.points.capacity().max(sorted.ordered.capacity()).max(sorted.keys.capacity()))
        };
        assert_eq!(sorted_capacity, SORTED_GATHER_BATCH, "the batch grew past its size");

        assert!(merges > 10_000, "too few merges for the test to bite: {merges}");
        assert_eq!(sorted_merges, merges);
        assert_ne!(sorted_adds, one_by_one, "the order must change for the test to bite");
        sorted_adds.sort_unstable();
        one_by_one.sort_unstable();
        assert_eq!(sorted_adds, one_by_one);
    }

    #[test]
    fn vertices_pushed_before_the_map_is_built_gather_nothing() {
        let map = PhotonMap::new();
        let mut sorted = SortedGathers::new();
        let v = GatherPoint {
            p: Vec3::ZERO,
            ng: Vec3::Y,
            wi: Vec3::Y,
            flux: Rgb::ONE,
            m: 2,
            all_specular: false,
            all_pass: false,
            spectrum: 0,
        };
        sorted.push(&map, v);
        assert_eq!(sorted.room(), SORTED_GATHER_BATCH - 1);
        let mut adds = Adds::new();
        let merges = sorted.gather_into(&map, &PhaseSpectrum::RGB, 8, 2, &mut record(&mut adds));
        assert_eq!(merges, 0);
        assert!(adds.is_empty() && sorted.is_empty());
    }
}
