//! An on-disk cache of large meshes' BVHs, so that a scene rendered again (or by several processes on one
//! machine) reads its BVH and surface edges rather than building them. A file is named by a content hash of
//! what the build depends on (the triangles' positions, the build's settings, obvhs's version), so a changed
//! mesh or setting finds no file and nothing is ever invalidated by hand. Files carry a checksum and are
//! checked against the mesh before use; a damaged one is rebuilt and replaced. Writes go to a temporary file
//! renamed into place, so processes building the same mesh at once do not read each other's half-written file.
//!
//! `PHOTONFARM_BVH_CACHE` names the folder, or `off`; by default it is `photonfarm/bvh` in the user's cache
//! folder (`$XDG_CACHE_HOME`, else `~/.cache`). Meshes below a million triangles build in well under a second
//! and are not cached; the folder is kept below 4 GiB by removing the files used least recently.

use super::surface_edges::{SurfaceEdges, SAME_SURFACE_COS};
use glam::Vec3;
use obvhs::{aabb::Aabb, cwbvh::node::CwBvhNode, cwbvh::CwBvh};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::ffi::OsString;
use std::fs::{self, File};
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

/// The environment variable naming the cache's folder, or `off` for no cache.
pub const BVH_CACHE_VARIABLE: &str = "PHOTONFARM_BVH_CACHE";

/// The version of obvhs that builds and reads the cached BVHs, part of every key: another version's node layout
/// or traversal may differ. A test checks it against the build's `Cargo.lock`.
pub const OBVHS_VERSION: &str = "0.4.0";

/// Meshes with fewer triangles are not cached: they build in well under a second.
const MIN_TRIANGLES: usize = 1_000_000;

/// The most the cache's files may hold together (bytes); the least recently used go first.
const CAPACITY_BYTES: u64 = 4 << 30;

/// Temporary files older than this were left by a process that died while writing, and are removed.
const STALE_TEMPORARY: Duration = Duration::from_secs(24 * 3600);

/// The first bytes of a cache file, which name its layout and, being part of every key, the rules its contents
/// were made by: change it with the file's layout, with how `build_obvhs` builds a BVH from its settings, or with
/// how `SurfaceEdges::find` decides where a surface ends, and every older file finds no use.
const MAGIC: &[u8; 8] = b"PFBVHC01";

/// Triangles hashed together: the chunks' digests are computed in parallel and hashed in order.
const HASH_CHUNK: usize = 1 << 16;

/// The traversal's stack holds this many node groups: a deeper BVH could not be traversed.
const MAX_DEPTH: u8 = 32;

/// What the cache did for one build, as records report it.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BvhCacheUse {
    /// No cache: turned off, or a backend whose BVH is not cached.
    Off,
    /// The mesh is too small to be worth caching.
    Small,
    /// The BVH was read from the cache.
    Read,
    /// The BVH was built and stored in the cache.
    Written,
    /// The cache's file was damaged (why): the BVH was built and the file replaced.
    Replaced(String),
    /// The BVH was built but could not be stored (why).
    Unwritten(String),
}

/// Where large meshes' BVHs are kept between runs, and which meshes count as large.
#[derive(Clone, Debug)]
pub struct BvhCache {
    dir: PathBuf,
    min_triangles: usize,
    capacity_bytes: u64,
}

/// A BVH with the surface edges of its triangles, as the cache keeps them.
pub(crate) struct CachedBvh {
    pub bvh: CwBvh,
    pub edges: SurfaceEdges,
}

/// What a build depends on besides the triangles' positions.
pub(crate) struct BuildSettings<'a> {
    /// The obvhs preset's name.
    pub preset: &'a str,
    /// The most triangles in a leaf.
    pub leaf_size: u32,
    /// How far each triangle's box is widened, in scene units.
    pub box_margin: f32,
}

/// The content hash that names a cache file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct CacheKey([u8; 32]);

impl CacheKey {
    fn file_name(&self) -> String {
        let hex: String = self.0.iter().map(|b| format!("{b:02x}")).collect();
        format!("{hex}.bvh")
    }
}

impl BvhCache {
    /// The cache `PHOTONFARM_BVH_CACHE` names, or the default folder; None when it says `off` or there is no
    /// home folder to keep it in.
    pub fn from_env() -> Option<Self> {
        Self::from_vars(|name| std::env::var_os(name))
    }

    /// `from_env` with the environment's variables as `get` gives them.
    fn from_vars(get: impl Fn(&str) -> Option<OsString>) -> Option<Self> {
        let var = |name: &str| get(name).filter(|v| !v.is_empty());
        if let Some(dir) = var(BVH_CACHE_VARIABLE) {
            return (!dir.eq_ignore_ascii_case("off")).then(|| Self::in_dir(dir));
        }
        let base = var("XDG_CACHE_HOME")
            .map(PathBuf::from)
            .filter(|p| p.is_absolute())
            .or_else(|| var("HOME").map(|home| Path::new(&home).join(".cache")))?;
        Some(Self::in_dir(base.join("photonfarm").join("bvh")))
    }

    /// A cache in `dir` (made when first written), for meshes of a million triangles or more.
    pub fn in_dir(dir: impl Into<PathBuf>) -> Self {
        BvhCache { dir: dir.into(), min_triangles: MIN_TRIANGLES, capacity_bytes: CAPACITY_BYTES }
    }

    /// The same cache for meshes of at least `triangles` triangles.
    pub fn keeping_from(self, triangles: usize) -> Self {
        BvhCache { min_triangles: triangles, ..self }
    }

    /// The same cache holding at most `bytes` in its files.
    pub fn holding_at_most(self, bytes: u64) -> Self {
        BvhCache { capacity_bytes: bytes, ..self }
    }

    /// The cache's folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Whether a mesh of `triangles` triangles is cached.
    pub(crate) fn keeps(&self, triangles: usize) -> bool {
        triangles >= self.min_triangles
    }

    /// The key of the BVH built with `settings` over `triangles` (only their positions count: the objects are
    /// stored beside the BVH, not in it).
    pub(crate) fn key(triangles: &[(u32, [Vec3; 3])], settings: &BuildSettings) -> CacheKey {
        let chunks: Vec<[u8; 32]> = triangles
            .par_chunks(HASH_CHUNK)
            .map(|chunk| {
                let mut hasher = Sha256::new();
                let mut bytes = Vec::with_capacity(36 * chunk.len());
                for (_, t) in chunk {
                    for v in t {
                        for c in v.to_array() {
                            bytes.extend_from_slice(&c.to_bits().to_le_bytes());
                        }
                    }
                }
                hasher.update(&bytes);
                hasher.finalize().into()
            })
            .collect();
        let mut hasher = Sha256::new();
        hasher.update(MAGIC);
        hasher.update(format!("obvhs {OBVHS_VERSION} {}", if cfg!(target_endian = "little") { "le" } else { "be" }));
        hasher.update(settings.preset.as_bytes());
        hasher.update([0]);
        hasher.update(settings.leaf_size.to_le_bytes());
        hasher.update(settings.box_margin.to_bits().to_le_bytes());
        hasher.update(SAME_SURFACE_COS.to_bits().to_le_bytes());
        hasher.update((triangles.len() as u64).to_le_bytes());
        for c in &chunks {
            hasher.update(c);
        }
        CacheKey(hasher.finalize().into())
    }

    fn path(&self, key: &CacheKey) -> PathBuf {
        self.dir.join(key.file_name())
    }

    /// The BVH stored under `key` for a mesh of `triangles` triangles: None when there is none, an error when
    /// the file is damaged or does not fit the mesh (the caller rebuilds and replaces it).
    pub(crate) fn read(&self, key: &CacheKey, triangles: usize) -> Result<Option<CachedBvh>, String> {
        let path = self.path(key);
        let file = match File::open(&path) {
            Ok(f) => f,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(format!("cannot open {}: {e}", path.display())),
        };
        let found = read_file(file, key, triangles).map_err(|e| format!("{}: {e}", path.display()))?;
        // Marks the file as recently used for the eviction; a read-only cache is still read.
        if let Ok(f) = File::options().write(true).open(&path) {
            let _ = f.set_modified(SystemTime::now());
        }
        Ok(Some(found))
    }

    /// Stores `cached` under `key`, then removes the least recently used files past the cache's capacity.
    pub(crate) fn write(&self, key: &CacheKey, cached: &CachedBvh) -> Result<(), String> {
        let path = self.path(key);
        fs::create_dir_all(&self.dir).map_err(|e| format!("cannot make {}: {e}", self.dir.display()))?;
        let nanos = SystemTime::now().duration_since(SystemTime::UNIX_EPOCH).map_or(0, |d| d.subsec_nanos());
        let temporary = self.dir.join(format!("{}.tmp-{}-{nanos}", key.file_name(), std::process::id()));
        let written = write_file(&temporary, key, cached).and_then(|()| fs::rename(&temporary, &path));
        if let Err(e) = written {
            let _ = fs::remove_file(&temporary);
            return Err(format!("cannot write {}: {e}", path.display()));
        }
        self.evict(&path);
        Ok(())
    }

    /// Removes the least recently used cache files until the rest fit the capacity (never `keep`, just
    /// written), and temporary files left by processes that died writing.
    fn evict(&self, keep: &Path) {
        let Ok(entries) = fs::read_dir(&self.dir) else { return };
        let now = SystemTime::now();
        let mut files: Vec<(SystemTime, u64, PathBuf)> = Vec::new();
        for entry in entries.flatten() {
            let (path, Ok(meta)) = (entry.path(), entry.metadata()) else { continue };
            let modified = meta.modified().unwrap_or(now);
            let name = entry.file_name().to_string_lossy().into_owned();
            if name.contains(".bvh.tmp-") {
                if now.duration_since(modified).is_ok_and(|age| age > STALE_TEMPORARY) {
                    let _ = fs::remove_file(&path);
                }
            } else if name.ends_with(".bvh") {
                files.push((modified, meta.len(), path));
            }
        }
        let mut total: u64 = files.iter().map(|f| f.1).sum();
        files.sort();
        for (_, len, path) in files {
            if total <= self.capacity_bytes {
                break;
            }
            if path != keep && fs::remove_file(&path).is_ok() {
                total -= len;
            }
        }
    }
}

/// The header's counts, in the order the file stores them.
struct Header {
    triangles: u64,
    nodes: u64,
    primitives: u64,
    spatial_splits: u64,
}

/// Bytes before the arrays: magic, key, four counts, the total box.
const HEADER_BYTES: u64 = 8 + 32 + 4 * 8 + 6 * 4;

impl Header {
    /// The length of the whole file these counts describe, checksum included.
    fn file_len(&self) -> Option<u64> {
        let nodes = self.nodes.checked_mul(size_of::<CwBvhNode>() as u64)?;
        let primitives = self.primitives.checked_mul(4)?;
        HEADER_BYTES.checked_add(nodes)?.checked_add(primitives)?.checked_add(self.triangles)?.checked_add(32)
    }
}

/// A writer that hashes what passes through it, for the file's trailing checksum.
struct Hashing<W> {
    inner: W,
    hasher: Sha256,
}

impl<W: Write> Hashing<W> {
    fn put(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.hasher.update(bytes);
        self.inner.write_all(bytes)
    }
}

impl<R: Read> Hashing<R> {
    fn take(&mut self, bytes: &mut [u8]) -> std::io::Result<()> {
        self.inner.read_exact(bytes)?;
        self.hasher.update(&*bytes);
        Ok(())
    }
}

fn write_file(path: &Path, key: &CacheKey, cached: &CachedBvh) -> std::io::Result<()> {
    let bvh = &cached.bvh;
    let mut out = Hashing { inner: BufWriter::with_capacity(1 << 20, File::create(path)?), hasher: Sha256::new() };
    out.put(MAGIC)?;
    out.put(&key.0)?;
    let counts =
        [cached.edges.bits().len(), bvh.nodes.len(), bvh.primitive_indices.len(), bvh.uses_spatial_splits as usize];
    for c in counts {
        out.put(&(c as u64).to_le_bytes())?;
    }
    let (lo, hi) = (bvh.total_aabb.min, bvh.total_aabb.max);
    for c in [lo.x, lo.y, lo.z, hi.x, hi.y, hi.z] {
        out.put(&c.to_le_bytes())?;
    }
    out.put(bytemuck::cast_slice(&bvh.nodes))?;
    out.put(bytemuck::cast_slice(&bvh.primitive_indices))?;
    out.put(cached.edges.bits())?;
    let checksum: [u8; 32] = out.hasher.finalize_reset().into();
    out.inner.write_all(&checksum)?;
    // Not synced to disk: a file a crash leaves short or damaged fails its length or checksum check and is
    // rebuilt, and waiting for the disk would hold up the render for nothing.
    out.inner.flush()
}

fn read_file(file: File, key: &CacheKey, triangles: usize) -> Result<CachedBvh, String> {
    let len = file.metadata().map_err(|e| e.to_string())?.len();
    let mut input = Hashing { inner: BufReader::with_capacity(1 << 20, file), hasher: Sha256::new() };
    let io = |e: std::io::Error| format!("cannot read it: {e}");
    let mut magic = [0u8; 8];
    input.take(&mut magic).map_err(io)?;
    if &magic != MAGIC {
        return Err("not a cache file of this version".into());
    }
    let mut stored_key = [0u8; 32];
    input.take(&mut stored_key).map_err(io)?;
    if stored_key != key.0 {
        return Err("its key is not its name's".into());
    }
    let mut u64s = [0u64; 4];
    for c in &mut u64s {
        let mut b = [0u8; 8];
        input.take(&mut b).map_err(io)?;
        *c = u64::from_le_bytes(b);
    }
    let header = Header { triangles: u64s[0], nodes: u64s[1], primitives: u64s[2], spatial_splits: u64s[3] };
    if header.triangles != triangles as u64 {
        return Err(format!("it holds {} triangles, not {triangles}", header.triangles));
    }
    if header.file_len() != Some(len) {
        return Err(format!("{len} bytes do not hold what its header counts"));
    }
    let mut f32s = [0f32; 6];
    for c in &mut f32s {
        let mut b = [0u8; 4];
        input.take(&mut b).map_err(io)?;
        *c = f32::from_le_bytes(b);
    }
    // The counts fit the file's length, so these allocations are no larger than the file.
    let mut nodes = vec![CwBvhNode::default(); header.nodes as usize];
    input.take(bytemuck::cast_slice_mut(&mut nodes)).map_err(io)?;
    let mut primitive_indices = vec![0u32; header.primitives as usize];
    input.take(bytemuck::cast_slice_mut(&mut primitive_indices)).map_err(io)?;
    let mut bits = vec![0u8; triangles];
    input.take(&mut bits).map_err(io)?;
    let computed: [u8; 32] = input.hasher.finalize_reset().into();
    let mut checksum = [0u8; 32];
    input.inner.read_exact(&mut checksum).map_err(io)?;
    if checksum != computed {
        return Err("its checksum does not match its contents".into());
    }
    let bvh = CwBvh {
        nodes,
        primitive_indices,
        total_aabb: Aabb {
            min: Vec3::new(f32s[0], f32s[1], f32s[2]).into(),
            max: Vec3::new(f32s[3], f32s[4], f32s[5]).into(),
        },
        exact_node_aabbs: None,
        uses_spatial_splits: header.spatial_splits != 0,
    };
    check_structure(&bvh, triangles)?;
    Ok(CachedBvh { bvh, edges: SurfaceEdges::from_bits(bits) })
}

/// Whether `bvh` can be traversed over `triangles` triangles without reading past its arrays or looping: every
/// child index within the nodes and after its parent, no deeper than the traversal's stack, every leaf's
/// primitives within the primitive list and every triangle in a leaf.
pub(crate) fn check_structure(bvh: &CwBvh, triangles: usize) -> Result<(), String> {
    let (nodes, primitives) = (&bvh.nodes, &bvh.primitive_indices);
    if nodes.is_empty() || (primitives.len() != triangles && !bvh.uses_spatial_splits) {
        return Err(format!("{} nodes over {} primitives for {triangles} triangles", nodes.len(), primitives.len()));
    }
    let mut depth = vec![0u8; nodes.len()];
    let mut in_leaf = vec![false; triangles];
    for (i, node) in nodes.iter().enumerate() {
        let inner = node.imask.count_ones() as usize;
        let base = node.child_base_idx as usize;
        if inner > 0 && (base <= i || base + inner > nodes.len()) {
            return Err(format!("node {i}'s children {base}..{} lie outside the nodes after it", base + inner));
        }
        for (slot, &meta) in node.child_meta.iter().enumerate() {
            let is_inner = node.imask & (1 << slot) != 0;
            if meta == 0 {
                if is_inner {
                    return Err(format!("node {i}'s empty slot {slot} is marked inner"));
                }
                continue;
            }
            let offset = (meta & 0b11111) as usize;
            if is_inner != (offset >= 24 && meta >> 5 == 1) {
                return Err(format!("node {i}'s slot {slot} is not the kind its mask says"));
            }
            if is_inner {
                let child = base + (node.imask as u32 & !(u32::MAX << (offset - 24))).count_ones() as usize;
                depth[child] = depth[i] + 1;
                if depth[child] >= MAX_DEPTH {
                    return Err(format!("node {child} lies deeper than the traversal's stack"));
                }
                continue;
            }
            for k in (0..3).filter(|k| meta & (0b1_00000 << k) != 0) {
                let place = node.primitive_base_idx as usize + offset + k;
                let Some(&triangle) = primitives.get(place) else {
                    return Err(format!("node {i}'s leaf reads primitive {place} of {}", primitives.len()));
                };
                let Some(seen) = in_leaf.get_mut(triangle as usize) else {
                    return Err(format!("primitive {place} is triangle {triangle} of {triangles}"));
                };
                *seen = true;
            }
        }
    }
    match in_leaf.iter().position(|&seen| !seen) {
        Some(t) => Err(format!("triangle {t} is in no leaf")),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Backend, Mesh, MeshTriangle, ObvhsPreset, Ray, SceneGeometry};

    /// Boxes scattered over a unit cube, each two triangles per face: a mesh with edges that end the surface
    /// (the boxes' edges) and edges that continue it (the faces' diagonals).
    fn boxes(count: usize) -> Vec<MeshTriangle> {
        use rand_core::{RngCore, SeedableRng};
        let mut rng = rand_pcg::Pcg32::seed_from_u64(7);
        let mut random = move || (rng.next_u32() >> 8) as f32 / (1 << 24) as f32;
        (0..count)
            .flat_map(|_| {
                let min = Vec3::new(random(), random(), random());
                Mesh::axis_box(min, min + Vec3::splat(0.02 + 0.05 * random())).triangles
            })
            .collect()
    }

    fn build(triangles: &[MeshTriangle], preset: ObvhsPreset, cache: &BvhCache) -> SceneGeometry {
        let objects = (0..triangles.len() as u32).map(|i| i % 3).collect();
        SceneGeometry::build_objects_with(Backend::Obvhs(preset), triangles.to_vec(), objects, vec![], Some(cache))
            .unwrap()
    }

    /// A ray's hit: its distance's bits, the triangle and its object.
    type Seen = Option<(u32, u32, u32)>;

    /// Every hit of a fan of rays through the boxes, and every triangle's edges.
    fn what_rays_see(g: &SceneGeometry) -> (Vec<Seen>, Vec<u8>) {
        let hits = (0..4096)
            .map(|i| {
                let (u, v) = ((i % 64) as f32 / 64.0, (i / 64) as f32 / 64.0);
                let ray = Ray::new(Vec3::new(-1.0, 0.5, 0.5), Vec3::new(2.0, u - 0.5, v - 0.5).normalize());
                g.intersect(&ray).map(|h| (h.t.to_bits(), h.triangle, h.object))
            })
            .collect();
        (hits, (0..g.triangle_count() as u32).map(|i| g.surface_edges(i)).collect())
    }

    fn files(dir: &Path) -> Vec<PathBuf> {
        let mut names: Vec<PathBuf> = fs::read_dir(dir).map_or(Vec::new(), |d| d.flatten().map(|e| e.path()).collect());
        names.sort();
        names
    }

    #[test]
    fn a_bvh_read_from_the_cache_sees_what_the_one_built_sees() {
        let dir = tempfile::tempdir().unwrap();
        let cache = BvhCache::in_dir(dir.path()).keeping_from(1);
        let mesh = boxes(400);
        let built = build(&mesh, ObvhsPreset::Medium, &cache);
        assert_eq!(built.bvh_cache(), &BvhCacheUse::Written);
        let read = build(&mesh, ObvhsPreset::Medium, &cache);
        assert_eq!(read.bvh_cache(), &BvhCacheUse::Read);
        let seen = what_rays_see(&built);
        assert!(seen.0.iter().filter(|h| h.is_some()).count() > 1000, "the rays hit the boxes");
        assert!(seen.1.iter().all(|&e| e != 0 && e != 0b111), "edges of both kinds in every triangle");
        assert_eq!(what_rays_see(&read), seen);
        // Objects are not in the key: a scene with the same mesh in other objects reads the file with its own.
        let objects = vec![9; mesh.len()];
        let other = SceneGeometry::build_objects_with(
            Backend::Obvhs(ObvhsPreset::Medium),
            mesh.clone(),
            objects,
            vec![],
            Some(&cache),
        )
        .unwrap();
        assert_eq!(other.bvh_cache(), &BvhCacheUse::Read);
        assert!(what_rays_see(&other).0.iter().flatten().all(|h| h.2 == 9));
        assert_eq!(files(dir.path()).len(), 1);
    }

    #[test]
    fn a_moved_vertex_or_another_preset_finds_no_file_and_small_meshes_are_not_cached() {
        let dir = tempfile::tempdir().unwrap();
        let cache = BvhCache::in_dir(dir.path()).keeping_from(1);
        let mut mesh = boxes(50);
        assert_eq!(build(&mesh, ObvhsPreset::Medium, &cache).bvh_cache(), &BvhCacheUse::Written);
        mesh[17].v[1].x = f32::from_bits(mesh[17].v[1].x.to_bits() + 1);
        assert_eq!(build(&mesh, ObvhsPreset::Medium, &cache).bvh_cache(), &BvhCacheUse::Written);
        assert_eq!(build(&mesh, ObvhsPreset::Fast, &cache).bvh_cache(), &BvhCacheUse::Written);
        assert_eq!(files(dir.path()).len(), 3);
        let small = BvhCache::in_dir(dir.path().join("small")).keeping_from(mesh.len() + 1);
        assert_eq!(build(&mesh, ObvhsPreset::Medium, &small).bvh_cache(), &BvhCacheUse::Small);
        assert!(!small.dir().exists(), "nothing written for a small mesh");
    }

    #[test]
    fn a_damaged_or_truncated_file_is_rebuilt_and_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let cache = BvhCache::in_dir(dir.path()).keeping_from(1);
        let mesh = boxes(200);
        let seen = what_rays_see(&build(&mesh, ObvhsPreset::Medium, &cache));
        let file = files(dir.path()).pop().unwrap();
        let mut bytes = fs::read(&file).unwrap();
        let middle = bytes.len() / 2;
        bytes[middle] ^= 0x10;
        fs::write(&file, &bytes).unwrap();
        let replaced = build(&mesh, ObvhsPreset::Medium, &cache);
        assert!(
            matches!(replaced.bvh_cache(), BvhCacheUse::Replaced(why) if why.contains("checksum")),
            "{:?}",
            replaced.bvh_cache()
        );
        assert_eq!(what_rays_see(&replaced), seen);
        let len = fs::metadata(&file).unwrap().len();
        File::options().write(true).open(&file).unwrap().set_len(len - 100).unwrap();
        let replaced = build(&mesh, ObvhsPreset::Medium, &cache);
        assert!(
            matches!(replaced.bvh_cache(), BvhCacheUse::Replaced(why) if why.contains("bytes")),
            "{:?}",
            replaced.bvh_cache()
        );
        assert_eq!(build(&mesh, ObvhsPreset::Medium, &cache).bvh_cache(), &BvhCacheUse::Read);
    }

    #[test]
    fn a_folder_that_cannot_be_written_leaves_the_build_as_it_was() {
        let dir = tempfile::tempdir().unwrap();
        let not_a_folder = dir.path().join("file");
        fs::write(&not_a_folder, b"").unwrap();
        let cache = BvhCache::in_dir(&not_a_folder).keeping_from(1);
        let mesh = boxes(50);
        let g = build(&mesh, ObvhsPreset::Medium, &cache);
        assert!(matches!(g.bvh_cache(), BvhCacheUse::Unwritten(_)), "{:?}", g.bvh_cache());
        let uncached = BvhCache::in_dir(dir.path().join("other")).keeping_from(usize::MAX);
        assert_eq!(what_rays_see(&g), what_rays_see(&build(&mesh, ObvhsPreset::Medium, &uncached)));
    }

    #[test]
    fn the_folder_keeps_within_its_capacity_by_removing_the_least_recently_used_files() {
        let dir = tempfile::tempdir().unwrap();
        let probe = BvhCache::in_dir(dir.path().join("probe")).keeping_from(1);
        let meshes: Vec<Vec<MeshTriangle>> = (0..3).map(|i| boxes(100 + i)).collect();
        build(&meshes[0], ObvhsPreset::Medium, &probe);
        let one = fs::metadata(files(probe.dir()).pop().unwrap()).unwrap().len();
        // Room for two files of about this size, not three.
        let cache = BvhCache::in_dir(dir.path().join("cache")).keeping_from(1).holding_at_most(2 * one + one / 2);
        let (a, b) = (files_after(&cache, &meshes[0]), files_after(&cache, &meshes[1]));
        assert_eq!((a.len(), b.len()), (1, 2));
        // Reading the first makes it the most recently used, so the third file takes the second's place.
        std::thread::sleep(Duration::from_millis(20));
        assert_eq!(build(&meshes[0], ObvhsPreset::Medium, &cache).bvh_cache(), &BvhCacheUse::Read);
        std::thread::sleep(Duration::from_millis(20));
        let c = files_after(&cache, &meshes[2]);
        let second = b.iter().find(|f| !a.contains(f)).unwrap();
        assert_eq!(c.len(), 2);
        assert!(c.contains(&a[0]) && !c.contains(second), "{c:?}");
    }

    /// The cache's files once `mesh` has been built with it.
    fn files_after(cache: &BvhCache, mesh: &[MeshTriangle]) -> Vec<PathBuf> {
        build(mesh, ObvhsPreset::Medium, cache);
        files(cache.dir())
    }

    #[test]
    fn every_presets_bvh_passes_the_structure_check_and_broken_ones_do_not() {
        let mesh: Vec<(u32, [Vec3; 3])> = boxes(300).into_iter().map(|t| (0, t.v)).collect();
        for preset in [ObvhsPreset::Fastest, ObvhsPreset::Medium, ObvhsPreset::Slow] {
            let tris: Vec<obvhs::triangle::Triangle> =
                mesh.iter().map(|(_, v)| crate::geometry::accel::obvhs_triangle(v)).collect();
            let bvh = obvhs::cwbvh::builder::build_cwbvh_from_tris(&tris, preset.params(), &mut Duration::default());
            assert_eq!(check_structure(&bvh, mesh.len()), Ok(()), "{preset:?}");
            let inner = bvh.nodes.iter().position(|n| n.imask != 0).unwrap();
            let mut broken = bvh.clone();
            broken.nodes[inner].child_base_idx = inner as u32;
            assert!(check_structure(&broken, mesh.len()).is_err(), "a cycle");
            let mut broken = bvh.clone();
            broken.nodes[inner].child_base_idx = broken.nodes.len() as u32;
            assert!(check_structure(&broken, mesh.len()).is_err(), "children past the end");
            let mut broken = bvh.clone();
            broken.primitive_indices[0] = mesh.len() as u32;
            assert!(check_structure(&broken, mesh.len()).is_err(), "a triangle past the end");
            let mut broken = bvh.clone();
            let leaf = broken.nodes.iter().position(|n| n.imask == 0).unwrap();
            broken.nodes[leaf].primitive_base_idx = broken.primitive_indices.len() as u32;
            assert!(check_structure(&broken, mesh.len()).is_err(), "a leaf past the primitives");
        }
    }

    #[test]
    fn the_obvhs_version_in_the_keys_is_the_one_the_build_uses() {
        let lock = include_str!("../../../Cargo.lock");
        let entry = lock.split("[[package]]").find(|p| p.contains("name = \"obvhs\"")).expect("obvhs in Cargo.lock");
        assert!(entry.contains(&format!("version = \"{OBVHS_VERSION}\"")), "{entry}");
    }

    #[test]
    fn the_variable_names_the_folder_or_turns_the_cache_off_and_the_default_is_the_users_cache() {
        let dir = |pairs: &[(&str, &str)]| {
            let get = |name: &str| pairs.iter().find(|(n, _)| *n == name).map(|(_, v)| OsString::from(v));
            BvhCache::from_vars(get).map(|c| c.dir().to_path_buf())
        };
        let both = [(BVH_CACHE_VARIABLE, "/some/where"), ("HOME", "/home/u")];
        assert_eq!(dir(&both), Some(PathBuf::from("/some/where")));
        assert_eq!(dir(&[(BVH_CACHE_VARIABLE, "OFF"), ("HOME", "/home/u")]), None);
        assert_eq!(dir(&[("HOME", "/home/u")]), Some(PathBuf::from("/home/u/.cache/photonfarm/bvh")));
        let xdg = [("XDG_CACHE_HOME", "/xdg"), ("HOME", "/home/u")];
        assert_eq!(dir(&xdg), Some(PathBuf::from("/xdg/photonfarm/bvh")));
        // A relative XDG folder is ignored, as the specification asks; without a home there is no default.
        let relative = [("XDG_CACHE_HOME", "xdg"), ("HOME", "/home/u")];
        assert_eq!(dir(&relative), Some(PathBuf::from("/home/u/.cache/photonfarm/bvh")));
        assert_eq!(dir(&[]), None);
    }
}
