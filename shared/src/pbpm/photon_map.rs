//! The backward photon map: a hashed uniform grid built by counting sort each phase. Each photon is entered in
//! every cell its sphere overlaps, so a gather looks at a single cell.

use super::executor::Executor;
use super::photon::{BackwardPhoton, StoredVertex};
use glam::Vec3;
use rayon::prelude::*;

/// Backward photons of one phase and the grid over them; buffers are kept and reused across phases so memory
/// stays flat.
#[derive(Default)]
pub struct PhotonMap {
    photons: Vec<BackwardPhoton>,
    /// The BSDFs of the photons that are not Lambertian, by `BackwardPhoton::stored`.
    vertices: Vec<StoredVertex>,
    grid: Grid,
    /// The grid is over the current photons. `starts` and `entries` keep their length from phase to phase, so
    /// that a build writes them once instead of zeroing them first.
    built: bool,
    /// starts[h]..starts[h+1] are the entries of bucket h.
    starts: Vec<u32>,
    entries: Vec<u32>,
    /// Build scratch: (bucket << 32 | photon) for every cell a photon overlaps, one list per part of the photons
    /// and range of the buckets, `pairs[part * parts + range]`, so that each build step splits among threads
    /// without locks.
    pairs: Vec<Vec<u64>>,
    /// Build scratch: each photon's place once the photons are in grid order.
    order: Vec<u32>,
}

/// Cells a photon's sphere may overlap for its buckets to be told apart by a scan rather than a sort.
const SCANNED_CELLS: usize = 8;

/// The grid's cell size and hash table size.
#[derive(Clone, Copy, Default)]
struct Grid {
    inv_cell: f32,
    mask: u32,
}

impl Grid {
    #[inline]
    fn bucket(&self, [ix, iy, iz]: [i32; 3]) -> usize {
        let h = (ix as u32).wrapping_mul(73_856_093)
            ^ (iy as u32).wrapping_mul(19_349_663)
            ^ (iz as u32).wrapping_mul(83_492_791);
        (h & self.mask) as usize
    }

    /// The integer cell of a point: floor without a libm call, which the baseline x86-64 target does not inline
    /// and which showed up in profiles of the forward pass.
    #[inline]
    fn cell(&self, p: Vec3) -> [i32; 3] {
        let q = p * self.inv_cell;
        let floor = |x: f32| {
            let i = x as i32;
            i - ((i as f32) > x) as i32
        };
        [floor(q.x), floor(q.y), floor(q.z)]
    }

    /// Buckets of the cells a photon's sphere overlaps, each once: a photon whose cells collide in one bucket
    /// must be entered there once, or it would be gathered twice. A sphere of about the mean radius overlaps at
    /// most eight cells of three mean radii, where a scan of the buckets found so far is cheaper than a sort;
    /// the rare large sphere is sorted.
    fn buckets_of(&self, p: &BackwardPhoton, out: &mut Vec<usize>) {
        let r = Vec3::splat(p.radius2.sqrt());
        let (lo, hi) = (self.cell(p.position - r), self.cell(p.position + r));
        let cells = (0..3).map(|a| (hi[a] - lo[a] + 1) as usize).product::<usize>();
        out.clear();
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    let b = self.bucket([x, y, z]);
                    if cells > SCANNED_CELLS || !out.contains(&b) {
                        out.push(b);
                    }
                }
            }
        }
        if cells > SCANNED_CELLS {
            out.sort_unstable();
            out.dedup();
        }
    }
}

/// The photons a build reads, by index: the map's own buffer, or a camera pass's lists one after another.
#[derive(Clone, Copy)]
enum Photons<'a> {
    Flat(&'a [BackwardPhoton]),
    /// The lists and the index of each list's first photon.
    Lists(&'a [Vec<BackwardPhoton>], &'a [usize]),
}

impl Photons<'_> {
    fn len(&self) -> usize {
        match *self {
            Photons::Flat(p) => p.len(),
            Photons::Lists(lists, firsts) => firsts.last().map_or(0, |f| f + lists[lists.len() - 1].len()),
        }
    }

    /// Calls `f` with the index and the photon of every photon in `range`, in index order.
    fn each_in(&self, range: std::ops::Range<usize>, mut f: impl FnMut(usize, &BackwardPhoton)) {
        match *self {
            Photons::Flat(p) => p[range.clone()].iter().enumerate().for_each(|(i, p)| f(range.start + i, p)),
            Photons::Lists(lists, firsts) => {
                // The last list that starts at or before the index holds it (empty lists start where the next
                // one does).
                let mut l = firsts.partition_point(|&s| s <= range.start).saturating_sub(1);
                let mut i = range.start;
                while i < range.end {
                    let end = (range.end - firsts[l]).min(lists[l].len());
                    for (k, p) in lists[l][i - firsts[l]..end].iter().enumerate() {
                        f(i + k, p);
                    }
                    i = firsts[l] + end;
                    l += 1;
                }
            }
        }
    }

    /// Σ of the photons' radii, with the current rayon pool's threads when `parallel`.
    fn radius_sum(&self, parallel: bool) -> f64 {
        let radius = |p: &BackwardPhoton| p.radius2.sqrt() as f64;
        match (*self, parallel) {
            (Photons::Flat(p), true) => p.par_iter().map(radius).sum(),
            (Photons::Flat(p), false) => p.iter().map(radius).sum(),
            (Photons::Lists(lists, _), true) => lists.par_iter().flatten().map(radius).sum(),
            (Photons::Lists(lists, _), false) => lists.iter().flatten().map(radius).sum(),
        }
    }
}

impl PhotonMap {
    /// An empty map.
    pub fn new() -> Self {
        Self::default()
    }

    /// Forgets the photons of the previous phase (the grid is rebuilt by `build`).
    pub fn clear(&mut self) {
        self.photons.clear();
        self.vertices.clear();
        self.built = false;
    }

    /// Reserves room for `n` photons, so that a phase never grows the buffer (memory stays flat).
    pub fn reserve(&mut self, n: usize) {
        self.photons.reserve(n.saturating_sub(self.photons.len()));
    }

    /// Adds a photon; call `build` before gathering.
    pub fn push(&mut self, photon: BackwardPhoton) {
        self.built = false;
        self.photons.push(photon);
    }

    /// Adds many photons.
    pub fn extend(&mut self, photons: &[BackwardPhoton]) {
        self.built = false;
        self.photons.extend_from_slice(photons);
    }

    /// Builds the grid over the lists' photons where they lie, with `exec`'s threads, and copies each photon once,
    /// straight to its place in grid order: the same map, entry for entry, as copying the lists and building.
    pub fn build_from_lists(&mut self, lists: &[Vec<BackwardPhoton>], exec: Executor) {
        let mut firsts = Vec::with_capacity(lists.len());
        let mut total = 0;
        for list in lists {
            firsts.push(total);
            total += list.len();
        }
        // Room for as many photons as the lists have room for, so that the buffer never grows by doubling past
        // them.
        let room = lists.iter().map(Vec::capacity).sum::<usize>().max(total);
        if self.photons.capacity() < room {
            self.photons.reserve_exact(room - self.photons.len());
        }
        let source = Photons::Lists(lists, &firsts);
        self.build_grid(source, exec.threads());
        self.photons.clear();
        if let Some(&any) = lists.iter().find_map(|l| l.first()) {
            // Every slot is overwritten: `order` is a permutation.
            self.photons.resize(total, any);
            let (photons, order) = (&mut self.photons, &self.order);
            source.each_in(0..total, |i, p| photons[order[i] as usize] = *p);
        }
    }

    /// Takes `photons` as the map's own and builds the grid over them with `exec`'s threads.
    pub fn build_from(&mut self, photons: Vec<BackwardPhoton>, exec: Executor) {
        self.photons = photons;
        self.build_in_place(exec.threads());
    }

    /// Hands the photon buffer over, emptied but with its room, for the next phase's camera pass to fill.
    pub fn take_photons(&mut self) -> Vec<BackwardPhoton> {
        self.built = false;
        let mut photons = std::mem::take(&mut self.photons);
        photons.clear();
        photons
    }

    /// Replaces the BSDFs of the map's non-Lambertian photons with those of `lists`, one after another (the
    /// photons' indices count through them in that order).
    pub fn set_vertices(&mut self, lists: &[Vec<StoredVertex>]) {
        self.vertices.clear();
        for list in lists {
            self.vertices.extend_from_slice(list);
        }
    }

    /// The BSDF of the non-Lambertian photon whose `stored` index is `i`.
    #[inline]
    pub fn vertex(&self, i: u32) -> &StoredVertex {
        &self.vertices[i as usize]
    }

    /// Bytes held by the map's buffers.
    pub fn capacity_bytes(&self) -> usize {
        self.photons.capacity() * std::mem::size_of::<BackwardPhoton>()
            + self.vertices.capacity() * std::mem::size_of::<StoredVertex>()
            + (self.starts.capacity() + self.entries.capacity()) * 4
            + self.pairs.iter().map(Vec::capacity).sum::<usize>() * 8
            + self.pairs.capacity() * std::mem::size_of::<Vec<u64>>()
            + self.order.capacity() * 4
    }

    /// Sets the cell size to three mean radii: larger cells mean more candidates per gather, smaller ones more
    /// cells per photon to enter; three radii measured fastest on `cornell` (build and forward pass together).
    /// Sizes the hash table to a power of two near half the photon count: nearby photons share cells, so this
    /// keeps the load low while the table stays in cache during the build; collisions only add candidates.
    fn set_grid(&mut self, mean_radius: f64, photons: usize) -> usize {
        let size = (photons / 2).next_power_of_two().max(16);
        self.grid = Grid { inv_cell: 1.0 / (3.0 * mean_radius as f32).max(1e-12), mask: (size - 1) as u32 };
        size
    }

    /// Builds the grid over the current photons on the calling thread.
    pub fn build(&mut self) {
        self.build_in_place(1);
    }

    /// Builds the same grid as `build`, entry for entry, with the threads of the current rayon pool (a
    /// synchronous group).
    pub fn build_parallel(&mut self) {
        self.build_in_place(rayon::current_num_threads().max(1));
    }

    /// Builds the grid over the map's own photons in `parts` parts and moves them into grid order.
    fn build_in_place(&mut self, parts: usize) {
        let photons = std::mem::take(&mut self.photons);
        self.build_grid(Photons::Flat(&photons), parts);
        self.photons = photons;
        self.put_photons_in_grid_order();
    }

    /// Counting sort of the (bucket, photon) pairs in `parts` parts: part p finds the pairs of the p-th slice of
    /// the photons, sorted into the bucket ranges; range r then counts and places its buckets' pairs, reading
    /// the parts in order. Each bucket therefore lists its photons in photon order, whatever `parts` is. Then
    /// `order` is each photon's place in grid order and the entries name those places.
    fn build_grid(&mut self, photons: Photons, parts: usize) {
        let len = photons.len();
        self.built = len > 0;
        if !self.built {
            return;
        }
        let size = self.set_grid(photons.radius_sum(parts > 1) / len as f64, len);
        let Self { grid, starts, entries, pairs, .. } = self;
        let grid = *grid;
        // Buckets range_start(r)..range_start(r + 1) form range r.
        let range_start = |r: usize| r * size / parts;
        let log_size = size.trailing_zeros();
        let range_of = |b: usize| ((b + 1) * parts - 1) >> log_size;

        // 1. The pairs, found once per photon: the expensive part.
        pairs.resize_with(parts * parts, Vec::new);
        let per_part = len.div_ceil(parts);
        let find_pairs = |(p, lists): (usize, &mut [Vec<u64>])| {
            lists.iter_mut().for_each(Vec::clear);
            let first = (p * per_part).min(len);
            let last = (first + per_part).min(len);
            let mut buckets = Vec::with_capacity(27);
            photons.each_in(first..last, |i, photon| {
                grid.buckets_of(photon, &mut buckets);
                let pair = |b: usize| ((b as u64) << 32) | i as u64;
                if let [list] = lists {
                    list.extend(buckets.iter().map(|&b| pair(b)));
                } else {
                    for &b in &buckets {
                        lists[range_of(b)].push(pair(b));
                    }
                }
            });
        };
        if parts > 1 {
            pairs.par_chunks_mut(parts).enumerate().for_each(find_pairs);
        } else {
            find_pairs((0, &mut pairs[..]));
        }

        // 2. Counting sort, one bucket range at a time, each range writing its own slices of `starts` and
        // `entries`.
        let pairs = &*pairs;
        let in_range = |r: usize| (0..parts).map(move |p| &pairs[p * parts + r]);
        starts.resize(size + 1, 0);
        let total: usize = pairs.iter().map(Vec::len).sum();
        entries.resize(total, 0);
        let mut ranges = Vec::with_capacity(parts);
        let (mut starts_rest, mut entries_rest, mut offset) = (&mut starts[..size], &mut entries[..], 0);
        for r in 0..parts {
            let count: usize = in_range(r).map(Vec::len).sum();
            let (s, s_rest) = starts_rest.split_at_mut(range_start(r + 1) - range_start(r));
            let (e, e_rest) = entries_rest.split_at_mut(count);
            ranges.push((r, s, e, offset as u32));
            (starts_rest, entries_rest, offset) = (s_rest, e_rest, offset + count);
        }
        let sort_range = |(r, starts, entries, offset): (usize, &mut [u32], &mut [u32], u32)| {
            let first = range_start(r);
            starts.fill(0);
            for &pair in in_range(r).flatten() {
                starts[(pair >> 32) as usize - first] += 1;
            }
            let mut sum = 0;
            for s in starts.iter_mut() {
                (*s, sum) = (sum, sum + *s);
            }
            // Fill with a moving cursor per bucket, kept in `starts` and shifted back afterwards.
            for &pair in in_range(r).flatten() {
                let b = (pair >> 32) as usize - first;
                entries[starts[b] as usize] = pair as u32;
                starts[b] += 1;
            }
            for h in (1..starts.len()).rev() {
                starts[h] = starts[h - 1] + offset;
            }
            if let Some(s) = starts.first_mut() {
                *s = offset;
            }
        };
        if parts > 1 {
            ranges.into_par_iter().for_each(sort_range);
        } else {
            ranges.into_iter().for_each(sort_range);
        }
        starts[size] = total as u32;
        self.grid_order(len);
    }

    /// Gives each photon its place in the order in which the entries first name them, in `order`, and renames
    /// the entries to match, so that a bucket's candidates lie side by side in memory: a gather then reads a few
    /// runs of photons instead of one cache line per candidate. Entries keep their order, so the grid is the same
    /// whatever the threads that built it.
    fn grid_order(&mut self, photons: usize) {
        let Self { entries, order, .. } = self;
        order.clear();
        order.resize(photons, u32::MAX);
        let mut next = 0;
        for e in entries.iter_mut() {
            let place = &mut order[*e as usize];
            if *place == u32::MAX {
                *place = next;
                next += 1;
            }
            *e = *place;
        }
        // Every photon is entered in its own cell's bucket, so `order` is a permutation.
        debug_assert_eq!(next as usize, photons);
    }

    /// Moves the map's own photons to their places in `order`, one cycle of the permutation at a time.
    fn put_photons_in_grid_order(&mut self) {
        let Self { photons, order, .. } = self;
        for start in 0..photons.len() {
            let mut to = order[start] as usize;
            while to != start {
                photons.swap(start, to);
                order.swap(start, to);
                to = order[start] as usize;
            }
        }
    }

    /// The bucket a gather at `p` reads (0 before `build`): gathers in bucket order read the map's entries and
    /// photons front to back, as `put_photons_in_grid_order` laid them out.
    #[inline]
    pub fn bucket_of(&self, p: Vec3) -> u32 {
        if self.built {
            self.grid.bucket(self.grid.cell(p)) as u32
        } else {
            0
        }
    }

    /// Exactly the photons whose sphere contains `p`.
    #[inline]
    pub fn containing(&self, p: Vec3) -> impl Iterator<Item = &BackwardPhoton> {
        self.containing_in(self.bucket_of(p), p).map(|(b, _)| b)
    }

    /// `containing(p)` for a `p` in `bucket`, found before by `bucket_of(p)`, each photon with its squared
    /// distance from `p`.
    #[inline]
    pub fn containing_in(&self, bucket: u32, p: Vec3) -> impl Iterator<Item = (&BackwardPhoton, f32)> {
        let b = bucket as usize;
        let range = if self.built { self.starts[b] as usize..self.starts[b + 1] as usize } else { 0..0 };
        self.entries[range]
            .iter()
            .map(move |&i| {
                let b = &self.photons[i as usize];
                (b, (b.position - p).length_squared())
            })
            .filter(|(b, d2)| *d2 <= b.radius2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::color::Rgb;
    use crate::sampling::{Pass, Sampler};

    fn photon(p: Vec3, r: f32, pixel: u32) -> BackwardPhoton {
        BackwardPhoton {
            position: p,
            normal: Vec3::Y,
            weight: Rgb::ONE,
            radius2: r * r,
            pixel,
            kind: crate::pbpm::PhotonKind::new(1, true, false),
            segments: 1,
            spectrum: 0,
            inner_share: 128,
            stored: crate::pbpm::photon::LAMBERTIAN,
        }
    }

    #[test]
    fn gather_finds_exactly_the_photons_whose_sphere_contains_the_point() {
        let mut s = Sampler::new(1, Pass::Camera, 1, 1);
        let mut map = PhotonMap::new();
        let mut all = Vec::new();
        // Straddling the origin, so that cells of negative coordinates are exercised.
        let point = |s: &mut Sampler| Vec3::new(s.next_f32(), s.next_f32(), s.next_f32()) - Vec3::splat(0.5);
        for i in 0..2000 {
            let p = point(&mut s);
            let r = 0.01 + 0.08 * s.next_f32();
            all.push(photon(p, r, i));
            map.push(photon(p, r, i));
        }
        map.build();
        for _ in 0..500 {
            let q = point(&mut s);
            let mut expect: Vec<u32> =
                all.iter().filter(|b| (b.position - q).length_squared() <= b.radius2).map(|b| b.pixel).collect();
            let mut got: Vec<u32> = map.containing(q).map(|b| b.pixel).collect();
            expect.sort();
            got.sort();
            assert_eq!(got, expect);
        }
    }

    #[test]
    fn every_build_makes_the_sequential_grid_entry_for_entry() {
        let mut s = Sampler::new(2, Pass::Camera, 1, 1);
        let photons: Vec<BackwardPhoton> = (0..3000)
            .map(|i| photon(Vec3::new(s.next_f32(), s.next_f32(), s.next_f32()), 0.01 + 0.05 * s.next_f32(), i))
            .collect();
        let mut sequential = PhotonMap::new();
        sequential.extend(&photons);
        sequential.build();
        assert!(sequential.entries.len() > photons.len(), "photons must straddle cells for the test to bite");
        // Uneven lists, an empty one among them, as a group's backward pass leaves them.
        let lists = vec![photons[..1000].to_vec(), Vec::new(), photons[1000..2999].to_vec(), photons[2999..].to_vec()];
        let mut parallel = PhotonMap::new();
        for threads in [1, 2, 3, 4] {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| {
                parallel.clear();
                parallel.extend(&photons);
                parallel.build_parallel();
            });
            assert_eq!(parallel.photons, sequential.photons, "{threads} threads");
            assert_eq!(parallel.starts, sequential.starts, "{threads} threads");
            assert_eq!(parallel.entries, sequential.entries, "{threads} threads");
            // Built over the lists where they lie, each photon then copied straight to its place.
            for exec in [Executor::CurrentPool, Executor::CallingThread] {
                let mut from_lists = PhotonMap::new();
                pool.install(|| from_lists.build_from_lists(&lists, exec));
                assert_eq!(from_lists.photons, sequential.photons, "{threads} threads, {exec:?}");
                assert_eq!(from_lists.starts, sequential.starts, "{threads} threads, {exec:?}");
                assert_eq!(from_lists.entries, sequential.entries, "{threads} threads, {exec:?}");
            }
        }
        // Fewer photons than last phase: the map holds the new lists' photons only.
        let mut from_lists = PhotonMap::new();
        from_lists.build_from_lists(&lists, Executor::CallingThread);
        from_lists.build_from_lists(&lists[..1], Executor::CallingThread);
        let mut pixels: Vec<u32> = from_lists.photons.iter().map(|p| p.pixel).collect();
        pixels.sort();
        assert_eq!(pixels, (0..1000).collect::<Vec<u32>>());
    }

    #[test]
    fn empty_map_contains_no_photon() {
        let mut map = PhotonMap::new();
        map.build();
        assert_eq!(map.containing(Vec3::ZERO).count(), 0);
    }
}
