//! The backward photon map: a hashed uniform grid built by counting sort each phase. Each photon is entered in
//! every cell its sphere overlaps, so a gather looks at a single cell.

use super::photon::BackwardPhoton;
use glam::Vec3;
use rayon::prelude::*;

/// Backward photons of one phase and the grid over them; buffers are kept and reused across phases so memory
/// stays flat.
#[derive(Default)]
pub struct PhotonMap {
    photons: Vec<BackwardPhoton>,
    inv_cell: f32,
    mask: u32,
    /// starts[h]..starts[h+1] are the entries of bucket h.
    starts: Vec<u32>,
    entries: Vec<u32>,
    /// Build scratch: (bucket << 32 | photon) for every cell a photon overlaps.
    pairs: Vec<u64>,
}

#[inline]
fn bucket(ix: i32, iy: i32, iz: i32, mask: u32) -> usize {
    let h = (ix as u32).wrapping_mul(73_856_093)
        ^ (iy as u32).wrapping_mul(19_349_663)
        ^ (iz as u32).wrapping_mul(83_492_791);
    (h & mask) as usize
}

impl PhotonMap {
    /// An empty map.
    pub fn new() -> Self {
        Self::default()
    }

    /// Forgets the photons of the previous phase (the grid is rebuilt by `build`).
    pub fn clear(&mut self) {
        self.photons.clear();
        self.entries.clear();
        self.starts.clear();
        self.pairs.clear();
    }

    /// Reserves room for `n` photons, so that a phase never grows the buffer (memory stays flat).
    pub fn reserve(&mut self, n: usize) {
        self.photons.reserve(n.saturating_sub(self.photons.len()));
    }

    /// Adds a photon; call `build` before gathering.
    pub fn push(&mut self, photon: BackwardPhoton) {
        self.photons.push(photon);
    }

    /// Adds many photons.
    pub fn extend(&mut self, photons: &[BackwardPhoton]) {
        self.photons.extend_from_slice(photons);
    }

    /// Bytes held by the map's buffers.
    pub fn capacity_bytes(&self) -> usize {
        self.photons.capacity() * std::mem::size_of::<BackwardPhoton>()
            + (self.starts.capacity() + self.entries.capacity()) * 4
            + self.pairs.capacity() * 8
    }

    fn cell_range(&self, p: Vec3, r: f32) -> ([i32; 3], [i32; 3]) {
        (self.cell((p - Vec3::splat(r)) * self.inv_cell), self.cell((p + Vec3::splat(r)) * self.inv_cell))
    }

    /// The integer cell of a point already scaled by `inv_cell`: floor without a libm call, which the baseline
    /// x86-64 target does not inline and which showed up in profiles of the forward pass.
    #[inline]
    fn cell(&self, q: Vec3) -> [i32; 3] {
        let floor = |x: f32| {
            let i = x as i32;
            i - ((i as f32) > x) as i32
        };
        [floor(q.x), floor(q.y), floor(q.z)]
    }

    /// Sets the cell size to three mean radii: larger cells mean more candidates per gather, smaller ones more
    /// cells per photon to enter; three radii measured fastest on `cornell` (build and forward pass together).
    fn set_cell_size(&mut self, mean_radius: f64) {
        self.inv_cell = 1.0 / (3.0 * mean_radius as f32).max(1e-12);
    }

    /// Sizes the hash table: a power of two near half the photon count. Nearby photons share cells, so this
    /// keeps the load low while the table stays in cache during the build; collisions only add candidates.
    fn set_table_size(&mut self) -> usize {
        let size = (self.photons.len() / 2).next_power_of_two().max(16);
        self.mask = (size - 1) as u32;
        size
    }

    /// Builds the grid over the current photons on the calling thread.
    pub fn build(&mut self) {
        self.build_with(false);
    }

    /// Builds the same grid as `build`, finding the photons' cells with the threads of the current rayon pool
    /// (a synchronous group); the result is identical to `build`'s.
    pub fn build_parallel(&mut self) {
        self.build_with(true);
    }

    fn build_with(&mut self, parallel: bool) {
        self.starts.clear();
        self.entries.clear();
        self.pairs.clear();
        if self.photons.is_empty() {
            return;
        }
        let radius = |p: &BackwardPhoton| p.radius2.sqrt() as f64;
        let sum_r: f64 =
            if parallel { self.photons.par_iter().map(radius).sum() } else { self.photons.iter().map(radius).sum() };
        self.set_cell_size(sum_r / self.photons.len() as f64);
        let size = self.set_table_size();
        // (bucket, photon) pairs, found once per photon: the expensive part, so the part done in parallel.
        let mut pairs = std::mem::take(&mut self.pairs);
        if parallel {
            const CHUNK: usize = 4096;
            let this = &*self;
            let chunks: Vec<Vec<u64>> = this
                .photons
                .par_chunks(CHUNK)
                .enumerate()
                .map(|(c, chunk)| {
                    let mut out = Vec::with_capacity(chunk.len() * 8);
                    this.pairs_of(c * CHUNK, chunk, &mut out);
                    out
                })
                .collect();
            for c in &chunks {
                pairs.extend_from_slice(c);
            }
        } else {
            self.pairs_of(0, &self.photons, &mut pairs);
        }
        // Counting sort by bucket; pairs are in photon order, so each bucket lists its photons in order.
        self.starts.resize(size + 1, 0);
        for &pair in &pairs {
            self.starts[(pair >> 32) as usize + 1] += 1;
        }
        for h in 0..size {
            self.starts[h + 1] += self.starts[h];
        }
        self.entries.resize(pairs.len(), 0);
        // Fill with a moving cursor per bucket, kept in `starts` and shifted back afterwards.
        for &pair in &pairs {
            let b = (pair >> 32) as usize;
            self.entries[self.starts[b] as usize] = pair as u32;
            self.starts[b] += 1;
        }
        for h in (1..=size).rev() {
            self.starts[h] = self.starts[h - 1];
        }
        self.starts[0] = 0;
        self.pairs = pairs;
    }

    /// Appends (bucket << 32 | index) for every bucket of `photons`, the first of which has index `first`.
    fn pairs_of(&self, first: usize, photons: &[BackwardPhoton], out: &mut Vec<u64>) {
        let mut buckets = Vec::with_capacity(27);
        for (j, p) in photons.iter().enumerate() {
            self.buckets_of(p, &mut buckets);
            out.extend(buckets.iter().map(|&b| ((b as u64) << 32) | (first + j) as u64));
        }
    }

    /// Buckets of the cells a photon's sphere overlaps, each once: a photon whose cells collide in one bucket
    /// must be entered there once, or it would be gathered twice.
    fn buckets_of(&self, p: &BackwardPhoton, out: &mut Vec<usize>) {
        let (lo, hi) = self.cell_range(p.position, p.radius2.sqrt());
        out.clear();
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    out.push(bucket(x, y, z, self.mask));
                }
            }
        }
        out.sort_unstable();
        out.dedup();
    }

    /// Exactly the photons whose sphere contains `p`.
    #[inline]
    pub fn containing(&self, p: Vec3) -> impl Iterator<Item = &BackwardPhoton> {
        let range = if self.starts.is_empty() {
            0..0
        } else {
            let [x, y, z] = self.cell(p * self.inv_cell);
            let b = bucket(x, y, z, self.mask);
            self.starts[b] as usize..self.starts[b + 1] as usize
        };
        self.entries[range]
            .iter()
            .map(move |&i| &self.photons[i as usize])
            .filter(move |b| (b.position - p).length_squared() <= b.radius2)
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
            k: 1,
            segments: 1,
            spectrum: 0,
            ghost: false,
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
    fn parallel_build_finds_the_same_photons_as_the_sequential_build() {
        let mut s = Sampler::new(2, Pass::Camera, 1, 1);
        let mut a = PhotonMap::new();
        let mut b = PhotonMap::new();
        for i in 0..3000 {
            let p = photon(Vec3::new(s.next_f32(), s.next_f32(), s.next_f32()), 0.01 + 0.05 * s.next_f32(), i);
            a.push(p);
            b.push(p);
        }
        a.build();
        b.build_parallel();
        for _ in 0..300 {
            let q = Vec3::new(s.next_f32(), s.next_f32(), s.next_f32());
            let mut x: Vec<u32> = a.containing(q).map(|p| p.pixel).collect();
            let mut y: Vec<u32> = b.containing(q).map(|p| p.pixel).collect();
            x.sort();
            y.sort();
            assert_eq!(x, y);
        }
    }

    #[test]
    fn empty_map_contains_no_photon() {
        let mut map = PhotonMap::new();
        map.build();
        assert_eq!(map.containing(Vec3::ZERO).count(), 0);
    }
}
