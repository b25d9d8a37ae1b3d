//! One thread's share of a group's forward pass: the light of its group's own light paths in a plain buffer of
//! its own (atomic adds, which contend and cost, only where other groups add), and the light vertices it holds back per map it
//! gathers into, its group's and each other group's open map it holds, to gather them in that map's bucket
//! order (`SortedGathers`). The vertices held back for another group's map must be gathered before the thread
//! releases that map, or the map could close without them: `flush_foreign` comes before every release.

use photonfarm::accumulation::AuxLayout;
use photonfarm::pbpm::{
    AtomicGatherBuffer, GatherBuffer, GatherPoint, Phase, PhotonMap, SortedGathers, SORTED_GATHER_BATCH,
};
use photonfarm::spectrum::PhaseSpectrum;

/// What decides a gather's adds besides the map and the vertex.
#[derive(Clone, Copy)]
pub struct GatherRules<'a> {
    pub spectrum: &'a PhaseSpectrum,
    pub max_depth: u32,
    pub backward_diffuse_depth: u32,
}

impl<'a> GatherRules<'a> {
    /// The rules of `phase`'s gathers.
    pub fn of(phase: &'a Phase) -> Self {
        GatherRules {
            spectrum: &phase.spectrum,
            max_depth: phase.max_depth,
            backward_diffuse_depth: phase.backward_diffuse_depth,
        }
    }
}

/// Bytes a held-back vertex takes: the vertex, its copy in gather order and its sort key.
const VERTEX_BYTES: usize = 2 * std::mem::size_of::<GatherPoint>() + 8;

/// Most bytes the held-back vertices of an engine take per image pixel (`batch_per_map`): at most one vertex
/// per pixel.
pub const HELD_BACK_BYTES_PER_PIXEL: usize = VERTEX_BYTES;

/// Bytes per image pixel the held-back vertices of an engine over `pixels` pixels take at most: one vertex per
/// pixel on small images, twice the single-threaded engine's batch in all on large ones.
pub fn held_back_bytes_per_pixel(pixels: usize) -> f64 {
    let pixels = pixels.max(1);
    (HELD_BACK_BYTES_PER_PIXEL * pixels.min(2 * SORTED_GATHER_BATCH)) as f64 / pixels as f64
}

/// Vertices one thread holds back for one map when `threads` threads each gather into `maps` maps of an image
/// of `pixels` pixels: the engine holds at most twice the single-threaded engine's batch in all (7.9 MB) and
/// at most one vertex per image pixel, so that the memory estimate can count it per pixel.
pub fn batch_per_map(pixels: usize, threads: usize, maps: usize) -> usize {
    (pixels.min(2 * SORTED_GATHER_BATCH) / (threads * maps).max(1)).clamp(1, SORTED_GATHER_BATCH)
}

/// A thread's plain buffer for its group's own light paths and its held-back vertices, one batch per map.
#[derive(Debug, Default)]
pub struct ThreadGathers {
    /// Light the thread's own paths gathered into its group's map; summed into the group's at the phase's
    /// close, which leaves it zero.
    pub gathered: GatherBuffer,
    own: SortedGathers,
    /// Vertices held back for each group's map, by slot index (the thread's own group's entry stays empty).
    foreign: Vec<SortedGathers>,
}

impl ThreadGathers {
    /// Sizes the plain buffer for `pixels` local pixels with the auxiliary channels of `aux`, all zero.
    pub fn reset(&mut self, pixels: usize, aux: &AuxLayout) {
        self.gathered.reset(pixels, aux);
    }

    /// Readies batches of `batch` vertices for `maps` maps (between forward passes, when nothing is held back).
    /// A batch allocates on its first vertex, so maps the thread never gathers into cost nothing.
    pub fn prepare(&mut self, maps: usize, batch: usize) {
        debug_assert!(self.is_empty(), "vertices held back across phases");
        let fresh = || SortedGathers::with_batch(batch);
        if self.own.batch() != fresh().batch() {
            self.own = fresh();
        }
        self.foreign.resize_with(maps, fresh);
        for f in &mut self.foreign {
            if f.batch() != self.own.batch() {
                *f = fresh();
            }
        }
    }

    /// Holds back a vertex of one of the thread's group's paths for the group's own `map`, and gathers the batch
    /// into the plain buffer once it is full. Returns the merges made.
    #[inline]
    pub fn push_own(&mut self, map: &PhotonMap, v: GatherPoint, rules: GatherRules) -> u64 {
        if self.own.is_empty() {
            self.own.reserve_batch();
        }
        self.own.push(map, v);
        if self.own.room() == 0 {
            self.flush_own(map, rules)
        } else {
            0
        }
    }

    /// Gathers every vertex held back for the group's own `map` into the plain buffer, in bucket order. Returns
    /// the merges made.
    pub fn flush_own(&mut self, map: &PhotonMap, rules: GatherRules) -> u64 {
        self.own.gather_into(map, rules.spectrum, rules.max_depth, rules.backward_diffuse_depth, &mut self.gathered)
    }

    /// Holds back a vertex for map `k`, another group's (`map`, gathering into `buffer`), and gathers the batch
    /// once it is full. `sole`: this thread is the only one adding into `buffer` while the map is open
    /// (`AtomicGatherBuffer::sole_writer_sink`).
    #[inline]
    pub fn push_foreign(
        &mut self,
        k: usize,
        map: &PhotonMap,
        buffer: &AtomicGatherBuffer,
        sole: bool,
        v: GatherPoint,
        rules: GatherRules,
    ) {
        if self.foreign[k].is_empty() {
            self.foreign[k].reserve_batch();
        }
        self.foreign[k].push(map, v);
        if self.foreign[k].room() == 0 {
            self.flush_foreign(k, map, buffer, sole, rules);
        }
    }

    /// Gathers every vertex held back for map `k` into its `buffer`, in bucket order, and counts the merges in
    /// it. Call it before releasing the map.
    pub fn flush_foreign(
        &mut self,
        k: usize,
        map: &PhotonMap,
        buffer: &AtomicGatherBuffer,
        sole: bool,
        r: GatherRules,
    ) {
        let sorted = &mut self.foreign[k];
        if sorted.is_empty() {
            return;
        }
        let mut sink = if sole { buffer.sole_writer_sink() } else { buffer.sink() };
        let merges = sorted.gather_into(map, r.spectrum, r.max_depth, r.backward_diffuse_depth, &mut sink);
        buffer.add_merges(merges);
    }

    /// True when no vertex is held back for any map.
    pub fn is_empty(&self) -> bool {
        self.own.is_empty() && self.foreign.iter().all(SortedGathers::is_empty)
    }

    /// Bytes held.
    pub fn capacity_bytes(&self) -> usize {
        self.gathered.capacity_bytes()
            + self.own.capacity_bytes()
            + self.foreign.iter().map(SortedGathers::capacity_bytes).sum::<usize>()
            + self.foreign.capacity() * std::mem::size_of::<SortedGathers>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use photonfarm::color::Rgb;
    use photonfarm::pbpm::{gather_point, BackwardPhoton, PhotonKind};
    use photonfarm::sampling::{Pass, Sampler};

    const PIXELS: u32 = 500;

    /// Photons on the three walls of a corner, facing into it, so that normals, layers and path lengths all
    /// decide some merges; every fifth photon's camera path is a ghost path.
    fn corner_map(s: &mut Sampler, photons: u32) -> PhotonMap {
        let mut map = PhotonMap::new();
        for i in 0..photons {
            let (position, normal) = corner(s, i);
            let r = 0.01 + 0.03 * s.next_f32();
            map.push(BackwardPhoton {
                position,
                normal,
                weight: Rgb::new(s.next_f32(), s.next_f32(), s.next_f32()),
                radius2: r * r,
                pixel: i % PIXELS,
                kind: PhotonKind::new(1 + (i % 2) as u8, true, i % 5 == 0),
                segments: 1 + (i % 5) as u8,
                spectrum: 0,
                inner_share: 100 + (i % 50) as u8,
                stored: photonfarm::pbpm::photon::LAMBERTIAN,
            });
        }
        map.build();
        map
    }

    fn corner(s: &mut Sampler, i: u32) -> (Vec3, Vec3) {
        let (u, v) = (s.next_f32(), s.next_f32());
        match i % 3 {
            0 => (Vec3::new(u, v, 0.0), Vec3::Z),
            1 => (Vec3::new(0.0, u, v), Vec3::X),
            _ => (Vec3::new(v, 0.0, u), Vec3::Y),
        }
    }

    fn ghost_layout() -> AuxLayout {
        use photonfarm::accumulation::AuxLayer;
        AuxLayout::new(vec![AuxLayer { name: photonfarm::ghost::GHOST_LAYER.into(), channels: 3 }])
    }

    /// Every value of a pixel: (indirect, caustic) and the ghost layer's channels.
    fn values(get: impl Fn(usize) -> [Rgb; 2], aux: impl Fn(usize, usize) -> f32) -> Vec<f32> {
        (0..PIXELS as usize)
            .flat_map(|p| {
                let [a, b] = get(p);
                let mut v = a.to_array().to_vec();
                v.extend(b.to_array());
                v.extend((0..3).map(|c| aux(p, c)));
                v
            })
            .collect()
    }

    fn assert_close(got: &[f32], expect: &[f32], what: &str) {
        assert_eq!(got.len(), expect.len());
        for (i, (&g, &e)) in got.iter().zip(expect).enumerate() {
            assert!((g - e).abs() <= 1e-5 * e.abs().max(1.0), "{what}: value {i} is {g}, gathered one by one {e}");
        }
    }

    #[test]
    fn held_back_gathers_add_what_gathering_each_vertex_as_it_comes_adds_into_every_map() {
        let mut s = Sampler::new(5, Pass::Camera, 1, 1);
        let (own_map, foreign_map) = (corner_map(&mut s, 6000), corner_map(&mut s, 6000));
        let points: Vec<GatherPoint> = (0..5000u32)
            .map(|i| {
                let (p, ng) = corner(&mut s, i / 2);
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
        let rules = GatherRules { spectrum: &phase, max_depth: 8, backward_diffuse_depth: 2 };
        let aux = ghost_layout();

        // Vertex by vertex, as the groups gathered before.
        let (mut own_expect, mut foreign_expect) = (GatherBuffer::default(), GatherBuffer::default());
        own_expect.reset(PIXELS as usize, &aux);
        foreign_expect.reset(PIXELS as usize, &aux);
        let (mut own_merges, mut foreign_merges) = (0, 0);
        for v in &points {
            own_merges += gather_point(&own_map, v, &phase, 8, 2, &mut own_expect);
            foreign_merges += gather_point(&foreign_map, v, &phase, 8, 2, &mut foreign_expect);
        }

        // Held back in batches smaller than the vertices, so that full batches gather mid-way too; map 1 is the
        // other group's, gathered by two threads (CAS adds) into its atomic buffer.
        let mut foreign_buffer = AtomicGatherBuffer::default();
        foreign_buffer.reset(PIXELS as usize, &aux);
        let halves: Vec<(u64, bool)> = std::thread::scope(|scope| {
            let threads: Vec<_> = points
                .chunks(points.len() / 2)
                .map(|chunk| {
                    let (own_map, foreign_map, foreign_buffer, aux) = (&own_map, &foreign_map, &foreign_buffer, &aux);
                    scope.spawn(move || {
                        let mut t = ThreadGathers::default();
                        t.reset(PIXELS as usize, aux);
                        t.prepare(2, 700);
                        let mut merges = 0;
                        for &v in chunk {
                            merges += t.push_own(own_map, v, rules);
                            t.push_foreign(1, foreign_map, foreign_buffer, false, v, rules);
                        }
                        let held = !t.is_empty();
                        merges += t.flush_own(own_map, rules);
                        t.flush_foreign(1, foreign_map, foreign_buffer, false, rules);
                        assert!(t.is_empty());
                        (merges, held, t.gathered)
                    })
                })
                .collect();
            let mut sum = GatherBuffer::default();
            sum.reset(PIXELS as usize, &aux);
            let mut out = Vec::new();
            for h in threads {
                let (merges, held, mut gathered) = h.join().unwrap();
                sum.absorb_plain(&mut gathered);
                out.push((merges, held));
            }
            assert_close(
                &values(|p| sum.get(p), |p, c| sum.get_aux(p, c)),
                &values(|p| own_expect.get(p), |p, c| own_expect.get_aux(p, c)),
                "own map",
            );
            out
        });
        assert!(halves.iter().all(|&(_, held)| held), "some vertices must wait for the last flush");
        assert!(own_merges > 5000 && foreign_merges > 5000, "too few merges for the test to bite");
        assert_eq!(halves.iter().map(|h| h.0).sum::<u64>(), own_merges);
        assert_eq!(foreign_buffer.merges(), foreign_merges);
        assert_close(
            &values(|p| foreign_buffer.get(p), |p, c| foreign_buffer.get_aux(p, c)),
            &values(|p| foreign_expect.get(p), |p, c| foreign_expect.get_aux(p, c)),
            "foreign map",
        );
    }

    #[test]
    fn batches_per_map_shrink_with_threads_maps_and_pixels_within_their_bounds() {
        let big = 1 << 20;
        assert_eq!(batch_per_map(big, 1, 1), SORTED_GATHER_BATCH);
        assert_eq!(batch_per_map(big, 2, 1), SORTED_GATHER_BATCH);
        assert_eq!(batch_per_map(big, 2, 2), SORTED_GATHER_BATCH / 2);
        assert_eq!(batch_per_map(big, 64, 16), 64);
        assert_eq!(batch_per_map(64 * 64, 4, 1), 1024, "one vertex per pixel at most");
        assert_eq!(batch_per_map(0, 0, 0), 1);
    }

    #[test]
    fn held_back_vertices_take_exactly_their_batch() {
        let map = corner_map(&mut Sampler::new(6, Pass::Camera, 1, 1), 100);
        let phase = PhaseSpectrum::RGB;
        let rules = GatherRules { spectrum: &phase, max_depth: 8, backward_diffuse_depth: 2 };
        let mut t = ThreadGathers::default();
        t.reset(PIXELS as usize, &AuxLayout::default());
        t.prepare(1, 1000);
        let empty = t.capacity_bytes();
        let v = GatherPoint {
            p: Vec3::ZERO,
            ng: Vec3::Z,
            wi: Vec3::Z,
            flux: Rgb::ONE,
            m: 2,
            all_specular: false,
            all_pass: false,
            spectrum: 0,
        };
        for _ in 0..2500 {
            t.push_own(&map, v, rules);
        }
        t.flush_own(&map, rules);
        assert_eq!(t.capacity_bytes() - empty, 1000 * HELD_BACK_BYTES_PER_PIXEL);
    }
}
