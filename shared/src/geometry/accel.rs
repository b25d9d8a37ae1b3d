//! The scene's acceleration structure: a BVH over all triangles, built by obvhs (a compressed-wide BVH, the
//! default) or, with the `embree` feature, by Embree; the analytic surfaces are few and solved directly, behind
//! their boxes (`analytic_culling`).

use super::{
    analytic::Analytic,
    analytic_culling::{AnalyticCulling, Probe},
    bvh_cache::{BuildSettings, BvhCache, BvhCacheUse, CachedBvh},
    hit::SurfaceHit,
    mesh::MeshTriangle,
    per_triangle::PerTriangle,
    ray::{slab_entry, slab_inverse, Ray},
    surface_edges::SurfaceEdges,
    watertight::ShearedRay,
};
use glam::{Vec3, Vec3A};
use obvhs::{
    cwbvh::CwBvh,
    ray::{Ray as BvhRay, RayHit},
    triangle::Triangle,
    BvhBuildParams,
};
use rayon::prelude::*;
use std::ops::ControlFlow;

/// obvhs's build presets, from the fastest build to the most thorough (a better BVH should trace faster).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ObvhsPreset {
    /// `BvhBuildParams::fastest_build`: one triangle per leaf, no reinsertion.
    Fastest,
    /// `very_fast_build`.
    VeryFast,
    /// `fast_build`.
    Fast,
    /// `medium_build`: "around the same build time as Embree", in obvhs's words.
    Medium,
    /// `slow_build`, which also splits large triangles.
    Slow,
    /// `very_slow_build`.
    VerySlow,
}

impl ObvhsPreset {
    /// Every preset, fastest build first.
    pub const ALL: [ObvhsPreset; 6] = [
        ObvhsPreset::Fastest,
        ObvhsPreset::VeryFast,
        ObvhsPreset::Fast,
        ObvhsPreset::Medium,
        ObvhsPreset::Slow,
        ObvhsPreset::VerySlow,
    ];

    /// The preset photonfarm builds with. On the shipped scenes and the 1 M-triangle bench the thorough presets
    /// traced no faster (docs/measurements.md, "BVH build presets").
    pub const DEFAULT: ObvhsPreset = ObvhsPreset::Fastest;

    pub(crate) fn params(self) -> BvhBuildParams {
        match self {
            ObvhsPreset::Fastest => BvhBuildParams::fastest_build(),
            ObvhsPreset::VeryFast => BvhBuildParams::very_fast_build(),
            ObvhsPreset::Fast => BvhBuildParams::fast_build(),
            ObvhsPreset::Medium => BvhBuildParams::medium_build(),
            ObvhsPreset::Slow => BvhBuildParams::slow_build(),
            ObvhsPreset::VerySlow => BvhBuildParams::very_slow_build(),
        }
    }
}

/// The library that builds the BVH over a scene's triangles and traces rays through it. Both return the same
/// hits (up to rounding in the last bits of `t` and rays that graze a shared edge).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Backend {
    /// obvhs's compressed-wide BVH, pure Rust, built with the given preset.
    Obvhs(ObvhsPreset),
    /// Intel Embree 3 through the system's `libembree3` (the `embree` feature).
    #[cfg(feature = "embree")]
    Embree,
}

/// The environment variable that overrides the default backend, for measurements: a name from
/// `Backend::name`.
pub const BACKEND_VARIABLE: &str = "PHOTONFARM_BVH";

impl Backend {
    /// Every backend this build has, each obvhs preset included.
    pub fn all() -> Vec<Backend> {
        let obvhs = ObvhsPreset::ALL.iter().map(|&p| Backend::Obvhs(p));
        #[cfg(feature = "embree")]
        return obvhs.chain([Backend::Embree]).collect();
        #[cfg(not(feature = "embree"))]
        obvhs.collect()
    }

    /// The backend's name: `embree`, or `obvhs-` and the preset (`obvhs-fastest`, `obvhs-very-fast`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Backend::Obvhs(ObvhsPreset::Fastest) => "obvhs-fastest",
            Backend::Obvhs(ObvhsPreset::VeryFast) => "obvhs-very-fast",
            Backend::Obvhs(ObvhsPreset::Fast) => "obvhs-fast",
            Backend::Obvhs(ObvhsPreset::Medium) => "obvhs-medium",
            Backend::Obvhs(ObvhsPreset::Slow) => "obvhs-slow",
            Backend::Obvhs(ObvhsPreset::VerySlow) => "obvhs-very-slow",
            #[cfg(feature = "embree")]
            Backend::Embree => "embree",
        }
    }

    /// The backend of that name (`obvhs` alone is obvhs with its default preset).
    pub fn from_name(name: &str) -> Result<Backend, AccelError> {
        if name == "obvhs" {
            return Ok(Backend::Obvhs(ObvhsPreset::DEFAULT));
        }
        Backend::all().into_iter().find(|b| b.name() == name).ok_or_else(|| AccelError::UnknownBackend {
            name: name.to_string(),
            known: Backend::all().iter().map(|b| b.name()).collect::<Vec<_>>().join(", "),
            hint: if cfg!(feature = "embree") { "" } else { " (embree needs the `embree` feature)" },
        })
    }

    /// The default backend, or the one `PHOTONFARM_BVH` names.
    pub fn from_env() -> Result<Backend, AccelError> {
        match std::env::var(BACKEND_VARIABLE) {
            Err(std::env::VarError::NotPresent) => Ok(Backend::default()),
            Ok(name) => Backend::from_name(name.trim()),
            Err(std::env::VarError::NotUnicode(_)) => {
                Err(AccelError::UnknownBackend { name: "(not UTF-8)".into(), known: String::new(), hint: "" })
            }
        }
    }
}

impl Default for Backend {
    /// Embree when the build has it: it traces faster (docs/measurements.md, "Ray tracing").
    fn default() -> Self {
        #[cfg(feature = "embree")]
        return Backend::Embree;
        #[cfg(not(feature = "embree"))]
        return Backend::Obvhs(ObvhsPreset::DEFAULT);
    }
}

/// A backend could not build the scene's BVH, or none of the name asked for exists.
#[derive(Debug, thiserror::Error)]
pub enum AccelError {
    /// `PHOTONFARM_BVH` (or a caller) named no backend of this build.
    #[error("no ray-tracing backend is called `{name}` ({BACKEND_VARIABLE}): one of obvhs, {known}{hint}")]
    UnknownBackend { name: String, known: String, hint: &'static str },
    /// The backend failed to build the BVH.
    #[error("the {backend} ray-tracing backend could not build the scene: {message}")]
    Build { backend: &'static str, message: String },
}

/// What a hit needs of a triangle besides its vertices, stored in BVH order next to them (its vertex normals
/// are in `SceneGeometry::normals`, by index).
#[derive(Clone, Copy, Debug)]
struct TriangleData {
    object: u32,
    /// Index in the order triangles were added (stable across BVH builds).
    index: u32,
}

/// obvhs's BVH with the triangles in its leaf order, so that traversal reads them without indirection.
struct ObvhsTriangles {
    bvh: CwBvh,
    triangles: Vec<Triangle>,
    data: Vec<TriangleData>,
    /// Each triangle's place in `triangles`, by the index it was added with: the BVH's copy is the only one.
    slot: Vec<u32>,
}

impl ObvhsTriangles {
    /// The distance to triangle `id` (in BVH order) along the traversal ray `bounds` (`bvh_ray`'s, whose origin
    /// lies `BVH_ORIGIN_SHIFT` before the true one's) within its bounds, infinity for none, as obvhs's traversal
    /// asks: with the watertight test from the true origin rather than obvhs's own test, which lets rays
    /// through the shared edges of a closed mesh.
    #[inline]
    fn intersect(&self, ray: &ShearedRay, id: usize, bounds: &BvhRay) -> f32 {
        let t = &self.triangles[id];
        let (t_min, t_max) = (bounds.tmin - BVH_ORIGIN_SHIFT, bounds.tmax - BVH_ORIGIN_SHIFT);
        ray.intersect(t.v0, t.v1, t.v2, t_min, t_max).map_or(f32::INFINITY, |t| t + BVH_ORIGIN_SHIFT)
    }
}

/// The BVH over the triangles, by backend, which also keeps their vertices and objects; `None` when the scene
/// has no triangles.
enum TriangleAccel {
    None,
    Obvhs(ObvhsTriangles),
    #[cfg(feature = "embree")]
    Embree(super::embree::EmbreeTriangles),
}

impl TriangleAccel {
    /// Number of triangles.
    fn count(&self) -> usize {
        match self {
            TriangleAccel::None => 0,
            TriangleAccel::Obvhs(o) => o.slot.len(),
            #[cfg(feature = "embree")]
            TriangleAccel::Embree(e) => e.count(),
        }
    }

    /// The object and the vertices of the triangle added `index`-th; panics past the last, as indexing does.
    #[inline]
    fn triangle(&self, index: u32) -> (u32, [Vec3; 3]) {
        match self {
            TriangleAccel::None => panic!("triangle {index} of a geometry without triangles"),
            TriangleAccel::Obvhs(o) => {
                let s = o.slot[index as usize] as usize;
                let t = &o.triangles[s];
                (o.data[s].object, [t.v0.into(), t.v1.into(), t.v2.into()])
            }
            #[cfg(feature = "embree")]
            TriangleAccel::Embree(e) => e.triangle(index),
        }
    }
}

/// All surfaces of a scene, ready for intersection queries.
pub struct SceneGeometry {
    backend: Backend,
    /// The triangles' BVH, vertices and objects.
    accel: TriangleAccel,
    /// The triangles' vertex normals, by the index they were added with.
    normals: PerTriangle<[Vec3; 3]>,
    /// Which triangle edges end their surface, for the photons' gather discs.
    edges: SurfaceEdges,
    /// What the BVH cache did for this build.
    bvh_cache: BvhCacheUse,
    analytic: Vec<(u32, Analytic)>,
    culling: AnalyticCulling,
    /// The box around all triangles, widened for rounding: a ray segment that misses it skips the BVH, as rays
    /// between the surfaces of a lens away from the triangles do.
    triangle_box: (Vec3, Vec3),
    t_min: f32,
}

/// Scenes with at most this many analytic surfaces solve them in the order rays enter their boxes (the
/// entries sort on the stack); more are solved in index order, each still behind its box.
const SORTED_SURFACES: usize = 32;

/// How far the triangles' box is widened, relative to the scene's size: far more than a hit's rounding.
const TRIANGLE_BOX_MARGIN: f32 = 1e-5;

/// Minimum hit distance relative to the scene size: rays start on surfaces, offset by `offset_origin`.
const RELATIVE_T_MIN: f32 = 1e-7;

/// The scene's extent (its largest coordinate's magnitude, which scales the hit tolerances) and the
/// triangles' box, widened by `TRIANGLE_BOX_MARGIN` of that extent.
fn extent_and_box(vertices: impl Iterator<Item = Vec3>, analytic: &[(u32, Analytic)]) -> (f32, (Vec3, Vec3)) {
    let (lo, hi) = vertices
        .fold((Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)), |(lo, hi), v| (lo.min(v), hi.max(v)));
    // The largest coordinate's magnitude is at a face of the box (none without triangles).
    let mut extent = if lo.cmple(hi).all() { lo.abs().max(hi.abs()).max_element() } else { 0.0 };
    for (_, a) in analytic {
        let (c, r) = match a {
            Analytic::Sphere(s) => (s.center, s.radius),
            Analytic::Lens(l) => (l.vertex, l.curvature_radius.abs().max(l.aperture_radius)),
            Analytic::Annulus(a) => (a.center, a.outer_radius),
        };
        extent = extent.max(c.abs().max_element() + r);
    }
    let pad = Vec3::splat(TRIANGLE_BOX_MARGIN * (1.0 + extent));
    (extent, (lo - pad, hi + pad))
}

/// The box around the triangles' box and every analytic surface, when it is a finite one.
fn bounds_with_analytic(triangle_box: (Vec3, Vec3), analytic: &[(u32, Analytic)]) -> Option<(Vec3, Vec3)> {
    let (lo, hi) =
        analytic.iter().map(|(_, a)| a.bounds()).fold(triangle_box, |(lo, hi), b| (lo.min(b.min), hi.max(b.max)));
    (lo.cmple(hi).all() && lo.is_finite() && hi.is_finite()).then_some((lo, hi))
}

impl SceneGeometry {
    /// Builds the BVH with the default backend, or the one `PHOTONFARM_BVH` names. `triangles` pairs each
    /// triangle with the object it belongs to.
    pub fn build(triangles: Vec<(u32, MeshTriangle)>, analytic: Vec<(u32, Analytic)>) -> Result<Self, AccelError> {
        Self::build_with(Backend::from_env()?, triangles, analytic)
    }

    /// Builds the BVH with the given backend.
    pub fn build_with(
        backend: Backend,
        triangles: Vec<(u32, MeshTriangle)>,
        analytic: Vec<(u32, Analytic)>,
    ) -> Result<Self, AccelError> {
        let (objects, triangles) = triangles.into_iter().unzip();
        Self::build_objects_with(backend, triangles, objects, analytic, None)
    }

    /// `build` for triangles and the object of each, apart: how a scene's build gathers them, so that a mesh's
    /// triangles move into the geometry rather than being copied. A large mesh's BVH is read from the cache
    /// `PHOTONFARM_BVH_CACHE` names, or built and stored there (`BvhCache`).
    pub fn build_objects(
        triangles: Vec<MeshTriangle>,
        objects: Vec<u32>,
        analytic: Vec<(u32, Analytic)>,
    ) -> Result<Self, AccelError> {
        Self::build_objects_with(Backend::from_env()?, triangles, objects, analytic, BvhCache::from_env().as_ref())
    }

    /// `build_objects` with the given backend and BVH cache (None for none).
    pub fn build_objects_with(
        backend: Backend,
        triangles: Vec<MeshTriangle>,
        objects: Vec<u32>,
        analytic: Vec<(u32, Analytic)>,
        cache: Option<&BvhCache>,
    ) -> Result<Self, AccelError> {
        assert_eq!(triangles.len(), objects.len(), "one object per triangle");
        // Vertices and normals apart, so that a mesh without normals holds nothing for their absence. The list
        // is remade in its own memory (an iterator over a vector, collected into one of smaller items), which
        // saves a large mesh as many pages again to fault in; the memory its items no longer fill is let go.
        let mut normals = PerTriangle::default();
        let mut triangles: Vec<(u32, [Vec3; 3])> = triangles
            .into_iter()
            .enumerate()
            .map(|(i, t)| {
                normals.push(i as u32, t.n);
                (objects[i], t.v)
            })
            .collect();
        triangles.shrink_to_fit();
        drop(objects);
        let (extent, triangle_box) = extent_and_box(triangles.iter().flat_map(|(_, t)| *t), &analytic);
        // The backend keeps the only copy of the triangles: obvhs its own in BVH order, so the list as added is
        // let go once that is made.
        let (accel, edges, bvh_cache) = if triangles.is_empty() {
            (TriangleAccel::None, SurfaceEdges::default(), BvhCacheUse::Off)
        } else {
            match backend {
                Backend::Obvhs(preset) => {
                    let (accel, edges, cached) = build_obvhs(triangles, preset, extent, cache);
                    (TriangleAccel::Obvhs(accel), edges, cached)
                }
                #[cfg(feature = "embree")]
                Backend::Embree => {
                    let edges = SurfaceEdges::find(&triangles);
                    let accel = super::embree::EmbreeTriangles::build(triangles)
                        .map_err(|message| AccelError::Build { backend: "embree", message })?;
                    (TriangleAccel::Embree(accel), edges, BvhCacheUse::Off)
                }
            }
        };
        Ok(SceneGeometry {
            triangle_box,
            backend,
            accel,
            normals,
            edges,
            bvh_cache,
            culling: AnalyticCulling::new(&analytic),
            analytic,
            t_min: RELATIVE_T_MIN * (1.0 + extent),
        })
    }

    /// No surfaces at all: what a scene keeps once it has let its geometry go (`Scene::release_geometry`).
    pub fn empty() -> Self {
        Self::build_with(Backend::default(), Vec::new(), Vec::new()).expect("nothing to build cannot fail to build")
    }

    /// The same geometry solving every analytic surface for every ray, as if it kept no boxes around them, and
    /// searching the triangles' BVH for every ray: the reference the culling must agree with, for tests and
    /// measurements.
    pub fn without_analytic_culling(mut self) -> Self {
        self.culling.enabled = false;
        self
    }

    /// The same surfaces with their BVH built by another backend, to compare backends.
    pub fn rebuilt_with(&self, backend: Backend) -> Result<SceneGeometry, AccelError> {
        let triangles =
            (0..self.triangle_count() as u32).map(|i| (self.object_of_triangle(i), self.triangle(i))).collect();
        let mut g = Self::build_with(backend, triangles, self.analytic.clone())?;
        g.culling.enabled = self.culling.enabled;
        Ok(g)
    }

    /// The backend that traces this geometry's triangles.
    pub fn backend(&self) -> Backend {
        self.backend
    }

    /// What the BVH cache did when this geometry was built.
    pub fn bvh_cache(&self) -> &BvhCacheUse {
        &self.bvh_cache
    }

    /// The analytic surfaces and their objects, in the order they were added.
    pub fn analytic_surfaces(&self) -> &[(u32, Analytic)] {
        &self.analytic
    }

    /// The box around every surface, triangles and analytic ones (slightly widened for rounding); None for a
    /// scene without surfaces.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        bounds_with_analytic(self.triangle_box, &self.analytic)
    }

    /// The `bounds` the geometry of these surfaces would have, without building it: for a scene that keeps
    /// its lights and camera but is never traced (`Scene::load_untraced`).
    pub fn bounds_of(triangles: &[MeshTriangle], analytic: &[(u32, Analytic)]) -> Option<(Vec3, Vec3)> {
        let (_, triangle_box) = extent_and_box(triangles.iter().flat_map(|t| t.v), analytic);
        bounds_with_analytic(triangle_box, analytic)
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.accel.count()
    }

    /// A triangle by the index it was added with.
    #[inline]
    pub fn triangle(&self, index: u32) -> MeshTriangle {
        MeshTriangle { v: self.accel.triangle(index).1, n: self.normals.get(index).copied() }
    }

    /// The object a triangle (by the index it was added with) belongs to.
    pub fn object_of_triangle(&self, index: u32) -> u32 {
        self.accel.triangle(index).0
    }

    /// The edges of a triangle (by the index it was added with) beyond which its surface does not go on: bit i
    /// for the edge from vertex i to vertex i + 1.
    #[inline]
    pub fn surface_edges(&self, index: u32) -> u8 {
        self.edges.of(index)
    }

    /// The closest surface along the ray, if any.
    pub fn intersect(&self, ray: &Ray) -> Option<SurfaceHit> {
        let inv = slab_inverse(ray.direction);
        let Some(probe) = self.culling.probe(ray.origin, inv, self.t_min, ray.t_max) else {
            return self.intersect_triangles(ray, inv, ray.t_max);
        };
        if probe.enabled && self.analytic.len() <= SORTED_SURFACES {
            return self.intersect_sorted(ray, inv, &probe);
        }
        let mut best = self.intersect_triangles(ray, inv, ray.t_max);
        let mut best_t = best.as_ref().map_or(ray.t_max, |h| h.t);
        probe.each_crossing(&self.culling, self.t_min, best_t, |i, enter| {
            let (object, a) = &self.analytic[i];
            if enter <= best_t {
                if let Some((t, n)) = a.intersect(&Ray { t_max: best_t, ..*ray }, self.t_min) {
                    best_t = t;
                    best = Some(SurfaceHit { t, p: ray.at(t), ng: n, ns: n, object: *object, triangle: u32::MAX });
                }
            }
            ControlFlow::Continue(())
        });
        best
    }

    /// The `t_max` for `intersect_triangles` that still returns a triangle at distance `t`, so that a triangle
    /// wins a tie with an analytic surface: obvhs keeps hits before `t_max`, Embree up to it.
    #[inline]
    fn through(&self, t: f32) -> f32 {
        match self.accel {
            #[cfg(feature = "embree")]
            TriangleAccel::Embree(_) => t,
            _ if t.is_finite() => f32::from_bits(t.to_bits() + 1),
            _ => t,
        }
    }

    /// The closest triangle along the ray before `t_max` (up to it, with Embree); `inv` is
    /// `slab_inverse(ray.direction)`, for the box around all triangles.
    #[inline]
    fn intersect_triangles(&self, ray: &Ray, inv: Vec3, t_max: f32) -> Option<SurfaceHit> {
        let (lo, hi) = self.triangle_box;
        if self.culling.enabled && slab_entry(lo, hi, ray.origin, inv, self.t_min, t_max).is_none() {
            return None;
        }
        match &self.accel {
            TriangleAccel::None => None,
            TriangleAccel::Obvhs(o) => {
                let (origin, direction) = (Vec3A::from(ray.origin), Vec3A::from(ray.direction));
                let bray = bvh_ray(origin, direction, self.t_min, t_max);
                let sheared = ShearedRay::new(origin, direction);
                let mut hit = RayHit::none();
                if !o.bvh.ray_traverse(bray, &mut hit, |r, id| o.intersect(&sheared, id, r)) || hit.t >= bray.tmax {
                    return None;
                }
                hit.t -= BVH_ORIGIN_SHIFT;
                let id = hit.primitive_id as usize;
                let (tri, data) = (&o.triangles[id], &o.data[id]);
                let uv = || barycentrics(tri, ray);
                let normals = self.normals.get(data.index).copied();
                Some(triangle_hit(ray, hit.t, [tri.v0, tri.v1, tri.v2], normals, uv, data.object, data.index))
            }
            #[cfg(feature = "embree")]
            TriangleAccel::Embree(e) => {
                let h = e.intersect(&Ray { t_max, ..*ray }, self.t_min)?;
                let (object, tri) = e.triangle(h.index);
                let v = tri.map(Vec3A::from);
                let normals = self.normals.get(h.index).copied();
                Some(triangle_hit(ray, h.t, v, normals, || (h.u, h.v), object, h.index))
            }
        }
    }

    /// `intersect` for scenes with few analytic surfaces, solving them in the order the ray enters their boxes, so
    /// that the nearest hit comes early and every box entered beyond it is skipped (in a lens, the surfaces are
    /// stacked along the ray, and index order solves all of them for the rays that cross the stack back to front).
    /// A ray that starts inside a surface's box (between the surfaces of a lens) most often ends a few
    /// millimetres on, on one of them: those are solved before the triangles, whose BVH then needs to be searched
    /// only up to that hit. The answer is the one index order gives: the least t, ties to the lower index and to
    /// a triangle.
    fn intersect_sorted(&self, ray: &Ray, inv: Vec3, probe: &Probe) -> Option<SurfaceHit> {
        let mut entries = [(0.0f32, 0u32); SORTED_SURFACES];
        let mut count = 0;
        probe.each_crossing(&self.culling, self.t_min, ray.t_max, |i, enter| {
            let mut j = count;
            while j > 0 && entries[j - 1].0 > enter {
                entries[j] = entries[j - 1];
                j -= 1;
            }
            entries[j] = (enter, i as u32);
            count += 1;
            ControlFlow::Continue(())
        });
        let entries = &entries[..count];
        if entries.first().is_some_and(|&(enter, _)| enter <= self.t_min) {
            let analytic = self.solve_in_order(ray, entries, ray.t_max, None);
            let Some(a) = analytic else { return self.intersect_triangles(ray, inv, ray.t_max) };
            return self.intersect_triangles(ray, inv, self.through(a.t)).or(analytic);
        }
        let best = self.intersect_triangles(ray, inv, ray.t_max);
        self.solve_in_order(ray, entries, best.as_ref().map_or(ray.t_max, |h| h.t), best)
    }

    /// Solves the analytic surfaces of `entries` (sorted by where the ray enters their boxes) until the next box
    /// starts beyond the best hit so far, which is `best` at `best_t` (a triangle, or nothing).
    #[inline]
    fn solve_in_order(
        &self,
        ray: &Ray,
        entries: &[(f32, u32)],
        mut best_t: f32,
        mut best: Option<SurfaceHit>,
    ) -> Option<SurfaceHit> {
        let mut best_index: Option<u32> = None;
        for &(enter, i) in entries {
            if enter > best_t {
                break;
            }
            // One ulp past the best, so that a tie comes back and goes to the lower index, as in index order.
            let t_max = if best_t.is_finite() { f32::from_bits(best_t.to_bits() + 1) } else { best_t };
            let (object, a) = &self.analytic[i as usize];
            if let Some((t, n)) = a.intersect(&Ray { t_max, ..*ray }, self.t_min) {
                if t < best_t || (t == best_t && best_index.is_some_and(|b| i < b)) {
                    best_t = t;
                    best_index = Some(i);
                    best = Some(SurfaceHit { t, p: ray.at(t), ng: n, ns: n, object: *object, triangle: u32::MAX });
                }
            }
        }
        best
    }

    /// True when nothing blocks the open segment from `from` to `to`; `from` must already be offset.
    pub fn unoccluded(&self, from: Vec3, to: Vec3) -> bool {
        let d = to - from;
        let dist = d.length();
        if dist <= 0.0 {
            return true;
        }
        let dir = d / dist;
        let t_max = dist * (1.0 - 1e-4);
        let blocked = match &self.accel {
            TriangleAccel::None => false,
            TriangleAccel::Obvhs(o) => {
                let (origin, direction) = (Vec3A::from(from), Vec3A::from(dir));
                let bray = bvh_ray(origin, direction, self.t_min, t_max);
                let sheared = ShearedRay::new(origin, direction);
                !o.bvh.ray_traverse_miss(bray, |r, id| o.intersect(&sheared, id, r))
            }
            #[cfg(feature = "embree")]
            TriangleAccel::Embree(e) => e.occluded(from, dir, self.t_min, t_max),
        };
        if blocked {
            return false;
        }
        let Some(probe) = self.culling.probe(from, slab_inverse(dir), self.t_min, t_max) else {
            return true;
        };
        let r = Ray { origin: from, direction: dir, t_max };
        let mut blocked = false;
        probe.each_crossing(&self.culling, self.t_min, t_max, |i, _| {
            blocked = self.analytic[i].1.intersect(&r, self.t_min).is_some();
            if blocked {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        });
        !blocked
    }
}

/// How far before a ray's origin obvhs's traversal starts it. obvhs skips every box the ray leaves within 1e-4
/// of its origin (its `cwbvh::node::EPSILON`), whatever the ray's own t_min: a shadow ray from the ceiling
/// beside a light 0.1 mm below it missed the light. From this far back, the boxes near the true origin lie
/// beyond that distance; the triangle test still runs from the true origin.
const BVH_ORIGIN_SHIFT: f32 = 2e-4;

/// obvhs's ray for the segment [t_min, t_max] of the ray from `origin` along `direction` (unit length): started
/// `BVH_ORIGIN_SHIFT` back, its bounds shifted alike. A direction component of −0 becomes +0: obvhs takes the
/// inverse of −0 as negative but orders a box's slabs by `direction < 0`, which −0 is not, so such a ray (a
/// reflection off an axis-aligned wall gives them) would miss every box it runs along.
#[inline]
fn bvh_ray(origin: Vec3A, direction: Vec3A, t_min: f32, t_max: f32) -> BvhRay {
    let direction = direction + Vec3A::ZERO;
    let shift = BVH_ORIGIN_SHIFT;
    BvhRay::new(origin - direction * shift, direction, t_min + shift, t_max + shift)
}

/// How far each triangle's box is widened in obvhs's BVH, relative to the scene's size. obvhs tests a ray
/// against a box with a slab test that can miss by an ulp a ray through the box's edge, and a box's edge is a
/// triangle's wherever the geometry is axis-aligned (the corners of a room): widened boxes keep such rays for
/// the triangle test, which is watertight. Far more than the slab test's rounding, far less than a triangle.
const BVH_BOX_MARGIN: f32 = 1e-5;

/// The BVH over `triangles` and their surface edges, read from `cache` when it holds them, else built (see
/// `build_cwbvh`) and stored there when the mesh is large enough; with the triangles in the BVH's order.
fn build_obvhs(
    triangles: Vec<(u32, [Vec3; 3])>,
    preset: ObvhsPreset,
    extent: f32,
    cache: Option<&BvhCache>,
) -> (ObvhsTriangles, SurfaceEdges, BvhCacheUse) {
    let params = preset.params();
    let leaf_size = params.max_prims_per_leaf.clamp(1, 3);
    let box_margin = BVH_BOX_MARGIN * (1.0 + extent);
    let settings = BuildSettings { preset: Backend::Obvhs(preset).name(), leaf_size, box_margin };
    let build = |triangles: &[(u32, [Vec3; 3])]| {
        let (bvh, edges) = build_cwbvh(triangles, &params, leaf_size, box_margin);
        CachedBvh { bvh, edges }
    };
    let (built, cache_use) = match cache {
        None => (build(&triangles), BvhCacheUse::Off),
        Some(cache) if !cache.keeps(triangles.len()) => (build(&triangles), BvhCacheUse::Small),
        Some(cache) => {
            let key = BvhCache::key(&triangles, &settings);
            match cache.read(&key, triangles.len()) {
                Ok(Some(found)) => (found, BvhCacheUse::Read),
                found => {
                    let built = build(&triangles);
                    let stored = cache.write(&key, &built);
                    let cache_use = match (found, stored) {
                        (_, Err(why)) => BvhCacheUse::Unwritten(why),
                        (Err(damaged), Ok(())) => BvhCacheUse::Replaced(damaged),
                        (Ok(_), Ok(())) => BvhCacheUse::Written,
                    };
                    (built, cache_use)
                }
            }
        }
    };
    let CachedBvh { bvh, edges } = built;
    let order = &bvh.primitive_indices;
    let triangles_bvh = order.par_iter().map(|&i| obvhs_triangle(&triangles[i as usize].1)).collect();
    let data = order.par_iter().map(|&i| TriangleData { object: triangles[i as usize].0, index: i }).collect();
    // With spatial splits a triangle may lie in several leaves; any of its places will do.
    let mut slot = vec![u32::MAX; triangles.len()];
    drop(triangles);
    for (place, &i) in bvh.primitive_indices.iter().enumerate() {
        slot[i as usize] = place as u32;
    }
    debug_assert!(slot.iter().all(|&s| s != u32::MAX), "every triangle is in a leaf");
    (ObvhsTriangles { bvh, triangles: triangles_bvh, data, slot }, edges, cache_use)
}

/// A triangle as obvhs takes it.
pub(crate) fn obvhs_triangle(v: &[Vec3; 3]) -> Triangle {
    Triangle { v0: Vec3A::from(v[0]), v1: Vec3A::from(v[1]), v2: Vec3A::from(v[2]) }
}

/// obvhs's `build_cwbvh_from_tris` over triangle boxes widened by `box_margin`, and the triangles' surface
/// edges, found on the other cores while obvhs turns its binary BVH into the wide one, which it does on one
/// thread.
fn build_cwbvh(
    triangles: &[(u32, [Vec3; 3])],
    params: &BvhBuildParams,
    leaf_size: u32,
    box_margin: f32,
) -> (CwBvh, SurfaceEdges) {
    use obvhs::{bvh2::reinsertion::ReinsertionOptimizer, cwbvh::bvh2_to_cwbvh::bvh2_to_cwbvh, ploc::PlocBuilder};
    // Each intermediate (boxes, the binary BVH) is dropped as soon as the next is built: a large mesh's build
    // peaks at little more than what it keeps.
    let mut boxes: Vec<obvhs::aabb::Aabb> = triangles.iter().map(|(_, t)| obvhs_triangle(t).aabb()).collect();
    let mut indices: Vec<u32> = (0..triangles.len() as u32).collect();
    if params.pre_split {
        let tris: Vec<Triangle> = triangles.iter().map(|(_, t)| obvhs_triangle(t)).collect();
        let areas = boxes.iter().map(|b| b.half_area());
        let (largest, total) = areas.fold((0.0f32, 0.0f32), |(l, t), a| (l.max(a), t + a));
        let average = total / tris.len() as f32;
        obvhs::splits::split_aabbs_preset(&mut boxes, &mut indices, &tris, average, largest);
    }
    let margin = Vec3A::splat(box_margin);
    for b in &mut boxes {
        (b.min, b.max) = (b.min - margin, b.max + margin);
    }
    let mut bvh2 = PlocBuilder::with_capacity(boxes.len()).build(
        params.ploc_search_distance,
        &boxes,
        indices,
        params.sort_precision,
        params.search_depth_threshold,
    );
    drop(boxes);
    bvh2.uses_spatial_splits = params.pre_split;
    ReinsertionOptimizer::default().run(&mut bvh2, params.reinsertion_batch_ratio, None);
    rayon::join(|| bvh2_to_cwbvh(&bvh2, leaf_size, true, false), || SurfaceEdges::find(triangles))
}

/// The hit on triangle `v` at distance `t`; `uv` gives the hit's barycentrics (computed only when the
/// triangle has vertex normals to interpolate).
#[inline]
fn triangle_hit(
    ray: &Ray,
    t: f32,
    v: [Vec3A; 3],
    normals: Option<[Vec3; 3]>,
    uv: impl FnOnce() -> (f32, f32),
    object: u32,
    index: u32,
) -> SurfaceHit {
    let ng = Vec3::from((v[1] - v[0]).cross(v[2] - v[0])).normalize();
    let ns = match normals {
        Some(vn) => {
            let (u, v) = uv();
            let n = (vn[0] * (1.0 - u - v) + vn[1] * u + vn[2] * v).normalize_or_zero();
            if n == Vec3::ZERO || !n.is_finite() {
                ng
            } else if n.dot(ng) < 0.0 {
                -n
            } else {
                n
            }
        }
        None => ng,
    };
    SurfaceHit { t, p: ray.at(t), ng, ns, object, triangle: index }
}

/// Barycentrics (u, v) of the hit with p = (1−u−v) v0 + u v1 + v v2 (Embree's convention; obvhs 0.4's own
/// `compute_barycentric` is wrong).
fn barycentrics(tri: &Triangle, ray: &Ray) -> (f32, f32) {
    let o = Vec3A::from(ray.origin);
    let d = Vec3A::from(ray.direction);
    let e1 = tri.v0 - tri.v1;
    let e2 = tri.v2 - tri.v0;
    let n = e1.cross(e2);
    let r = d.cross(tri.v0 - o);
    let inv = 1.0 / n.dot(d);
    (r.dot(e2) * inv, r.dot(e1) * inv)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{analytic::Sphere, mesh::Mesh};

    fn two_quads(backend: Backend) -> SceneGeometry {
        let mut tris = Vec::new();
        for t in Mesh::quad(Vec3::new(-1.0, -1.0, 1.0), Vec3::X * 2.0, Vec3::Y * 2.0).triangles {
            tris.push((0, t));
        }
        for t in Mesh::quad(Vec3::new(-1.0, -1.0, 2.0), Vec3::X * 2.0, Vec3::Y * 2.0).triangles {
            tris.push((1, t));
        }
        SceneGeometry::build_with(backend, tris, vec![]).unwrap()
    }

    #[test]
    fn closest_hit_is_the_nearer_quad_with_its_winding_normal() {
        for &b in &Backend::all() {
            let g = two_quads(b);
            let h = g.intersect(&Ray::new(Vec3::new(0.2, 0.3, 0.0), Vec3::Z)).unwrap();
            assert_eq!(h.object, 0, "{b:?}");
            assert!((h.t - 1.0).abs() < 1e-5, "{b:?}");
            assert!((h.ng - Vec3::Z).length() < 1e-5, "{b:?}");
            // The triangle index is the one it was added with, whatever order the BVH keeps.
            let tri = g.triangle(h.triangle);
            assert!(tri.v.iter().all(|v| (v.z - 1.0).abs() < 1e-6), "{b:?}");
            // A ray that starts past the nearer quad sees the farther one; one bounded before it sees nothing.
            let h = g.intersect(&Ray::new(Vec3::new(0.2, 0.3, 1.5), Vec3::Z)).unwrap();
            assert_eq!(h.object, 1, "{b:?}");
            let short = Ray { t_max: 0.9, ..Ray::new(Vec3::new(0.2, 0.3, 0.0), Vec3::Z) };
            assert!(g.intersect(&short).is_none(), "{b:?}");
        }
    }

    #[test]
    fn occlusion_sees_the_blocker_between_the_points() {
        for &b in &Backend::all() {
            let g = two_quads(b);
            assert!(!g.unoccluded(Vec3::new(0.1, -0.2, 0.0), Vec3::new(0.1, -0.2, 1.5)), "{b:?}");
            assert!(g.unoccluded(Vec3::new(0.1, -0.2, 1.2), Vec3::new(0.1, -0.2, 1.8)), "{b:?}");
        }
    }

    #[test]
    fn backends_are_found_by_name_and_unknown_names_are_refused() {
        for &b in &Backend::all() {
            assert_eq!(Backend::from_name(b.name()).unwrap(), b);
        }
        assert_eq!(Backend::from_name("obvhs").unwrap(), Backend::Obvhs(ObvhsPreset::DEFAULT));
        let e = Backend::from_name("optix").unwrap_err().to_string();
        assert!(e.contains("`optix`") && e.contains("obvhs-medium"), "{e}");
    }

    #[test]
    fn interpolated_normals_use_the_right_barycentrics() {
        // A triangle whose vertex normals differ: the normal at a point near v1 must be close to v1's normal.
        let n0 = Vec3::Z;
        let n1 = Vec3::new(1.0, 0.0, 1.0).normalize();
        let n2 = Vec3::new(0.0, 1.0, 1.0).normalize();
        let t = MeshTriangle {
            v: [Vec3::new(0.0, 0.0, 1.0), Vec3::new(1.0, 0.0, 1.0), Vec3::new(0.0, 1.0, 1.0)],
            n: Some([n0, n1, n2]),
        };
        let expect = (n0 * 0.05 + n1 * 0.9 + n2 * 0.05).normalize();
        for &b in &Backend::all() {
            let g = SceneGeometry::build_with(b, vec![(0, t)], vec![]).unwrap();
            let h = g.intersect(&Ray::new(Vec3::new(0.9, 0.05, 0.0), Vec3::Z)).unwrap();
            assert!((h.ns - expect).length() < 1e-4, "{b:?}: {:?} vs {:?}", h.ns, expect);
        }
    }

    #[test]
    fn analytic_sphere_in_front_of_a_quad_wins() {
        let tris: Vec<_> = Mesh::quad(Vec3::new(-1.0, -1.0, 2.0), Vec3::X * 2.0, Vec3::Y * 2.0)
            .triangles
            .into_iter()
            .map(|t| (0, t))
            .collect();
        let sphere = Analytic::Sphere(Sphere { center: Vec3::new(0.0, 0.0, 1.0), radius: 0.25 });
        for &b in &Backend::all() {
            let g = SceneGeometry::build_with(b, tris.clone(), vec![(1, sphere)]).unwrap();
            let h = g.intersect(&Ray::new(Vec3::ZERO, Vec3::Z)).unwrap();
            assert_eq!(h.object, 1, "{b:?}");
            assert!((h.t - 0.75).abs() < 1e-5, "{b:?}");
            assert_eq!(h.triangle, u32::MAX, "{b:?}");
            // The sphere blocks the segment to the quad.
            assert!(!g.unoccluded(Vec3::ZERO, Vec3::new(0.0, 0.0, 1.9)), "{b:?}");
        }
    }

    /// A closed mesh: the 20 faces of an icosahedron around `centre`, turned off the axes so that no edge is
    /// axis-aligned, the shared vertices stored once.
    fn icosahedron(centre: Vec3, radius: f32) -> Vec<(u32, MeshTriangle)> {
        let g = (1.0 + 5f32.sqrt()) / 2.0;
        let turn = glam::Quat::from_euler(glam::EulerRot::XYZ, 0.3, 0.7, 1.1);
        let v: Vec<Vec3> = [
            (-1.0, g, 0.0),
            (1.0, g, 0.0),
            (-1.0, -g, 0.0),
            (1.0, -g, 0.0),
            (0.0, -1.0, g),
            (0.0, 1.0, g),
            (0.0, -1.0, -g),
            (0.0, 1.0, -g),
            (g, 0.0, -1.0),
            (g, 0.0, 1.0),
            (-g, 0.0, -1.0),
            (-g, 0.0, 1.0),
        ]
        .iter()
        .map(|&(x, y, z)| centre + turn * Vec3::new(x, y, z).normalize() * radius)
        .collect();
        let faces = [
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ];
        faces.iter().map(|f| (0, MeshTriangle { v: f.map(|i| v[i]), n: None })).collect()
    }

    #[test]
    fn rays_aimed_at_the_shared_edges_and_vertices_of_a_closed_mesh_never_pass_through() {
        let centre = Vec3::new(0.37, -0.21, 2.9);
        let meshes = [
            icosahedron(centre, 1.3),
            Mesh::axis_box(Vec3::new(-1.0, -0.5, 2.0), Vec3::new(0.75, 1.25, 3.5))
                .triangles
                .into_iter()
                .map(|t| (0, t))
                .collect(),
        ];
        for tris in meshes {
            // Every vertex, and points along every edge (the middle and off the middle).
            let mut targets = Vec::new();
            for (_, t) in &tris {
                for i in 0..3 {
                    let (a, b) = (t.v[i], t.v[(i + 1) % 3]);
                    targets.extend([a, (a + b) * 0.5, a + (b - a) * 0.25, a + (b - a) * 0.8125]);
                }
            }
            let inside = (tris.iter().flat_map(|(_, t)| t.v).sum::<Vec3>()) / (3 * tris.len()) as f32;
            let origins = [inside, inside + Vec3::new(0.11, -0.07, 0.05), inside + Vec3::new(-0.2, 0.13, -0.17)];
            for &b in &Backend::all() {
                let g = SceneGeometry::build_with(b, tris.clone(), vec![]).unwrap();
                let mut leaks = Vec::new();
                for &o in &origins {
                    for &p in &targets {
                        let d = (p - o).normalize();
                        // From inside, out through the edge or vertex: the mesh must stop it.
                        if g.intersect(&Ray::new(o, d)).is_none() || g.unoccluded(o, o + d * 10.0) {
                            leaks.push(("out", o, p));
                        }
                        // From outside, in through it and on to the inside point: the mesh must block it.
                        let outside = o + d * 10.0;
                        if g.intersect(&Ray::new(outside, -d)).is_none() || g.unoccluded(outside, o) {
                            leaks.push(("in", o, p));
                        }
                    }
                }
                assert!(
                    leaks.is_empty(),
                    "{b:?}: {} of {} rays through edges and vertices leak, e.g. {:?}",
                    leaks.len(),
                    2 * origins.len() * targets.len(),
                    &leaks[..leaks.len().min(3)]
                );
            }
        }
    }
}
