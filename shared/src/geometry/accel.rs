//! The scene's acceleration structure: a BVH over all triangles, built by obvhs (a compressed-wide BVH, the
//! default) or, with the `embree` feature, by Embree; the analytic surfaces are few and tested directly.

use super::{
    analytic::{Analytic, Bounds},
    hit::SurfaceHit,
    mesh::MeshTriangle,
    ray::Ray,
    surface_edges::SurfaceEdges,
};
use glam::{Vec3, Vec3A};
use obvhs::{
    cwbvh::{builder::build_cwbvh_from_tris, CwBvh},
    ray::{Ray as BvhRay, RayHit},
    triangle::Triangle,
    BvhBuildParams,
};
use std::time::Duration;

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

    fn params(self) -> BvhBuildParams {
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

/// Shading data of one triangle, stored in BVH order next to its vertices.
#[derive(Clone, Copy, Debug)]
struct TriangleData {
    object: u32,
    /// Index in the order triangles were added (stable across BVH builds).
    index: u32,
    normals: Option<[Vec3; 3]>,
}

/// obvhs's BVH with the triangles in its leaf order, so that traversal reads them without indirection.
struct ObvhsTriangles {
    bvh: CwBvh,
    triangles: Vec<Triangle>,
    data: Vec<TriangleData>,
}

/// The BVH over the triangles, by backend; `None` when the scene has no triangles.
enum TriangleAccel {
    None,
    Obvhs(ObvhsTriangles),
    #[cfg(feature = "embree")]
    Embree(super::embree::EmbreeTriangles),
}

/// All surfaces of a scene, ready for intersection queries.
pub struct SceneGeometry {
    backend: Backend,
    accel: TriangleAccel,
    /// Triangles and their objects in the order they were added, for light sampling and shading.
    by_index: Vec<(u32, MeshTriangle)>,
    /// Which triangle edges end their surface, for the photons' gather discs.
    edges: SurfaceEdges,
    analytic: Vec<(u32, Analytic)>,
    culling: AnalyticCulling,
    t_min: f32,
}

/// The analytic surfaces' boxes, so that a ray is solved only against the surfaces whose box its segment
/// crosses, and not at all when it misses the box around them all (most rays, in a room with a lens).
struct AnalyticCulling {
    /// Each surface's bounds (in `analytic`'s order) and the distance of its anchor from `all`'s.
    boxes: Vec<(Bounds, f32)>,
    all: Option<Bounds>,
    enabled: bool,
}

impl AnalyticCulling {
    fn new(analytic: &[(u32, Analytic)]) -> Self {
        let bounds: Vec<Bounds> = analytic.iter().map(|(_, a)| a.bounds()).collect();
        let all = bounds
            .iter()
            .skip(1)
            .fold(bounds.first().copied(), |all, b| all.map(|all| all.union(b, (b.anchor - all.anchor).length())));
        let boxes = match &all {
            Some(all) => bounds.iter().map(|b| (*b, (b.anchor - all.anchor).length())).collect(),
            None => Vec::new(),
        };
        AnalyticCulling { boxes, all, enabled: true }
    }

    /// The ray's culling state, or `None` when its segment [t0, t1] misses every surface's box.
    #[inline]
    fn probe(&self, origin: Vec3, direction: Vec3, t0: f32, t1: f32) -> Option<Probe> {
        let all = self.all.as_ref()?;
        // A zero (or subnormal) component makes the ray parallel to that slab: ±MAX instead of ±inf keeps
        // 0 × inf = NaN out of the slab test, and a ray that never moves along that axis cannot enter the box
        // through it anyway (each box holds its surface with a margin to spare).
        let inv = direction.recip();
        let inv = Vec3::select(inv.is_finite_mask(), inv, Vec3::splat(f32::MAX).copysign(direction));
        let probe = Probe { origin, inv, distance: (origin - all.anchor).length(), enabled: self.enabled };
        (!self.enabled || probe.crosses(all, 0.0, t0, t1)).then_some(probe)
    }
}

/// One ray against the analytic surfaces' boxes.
struct Probe {
    origin: Vec3,
    inv: Vec3,
    /// The distance from the origin to the anchor of the box around all surfaces.
    distance: f32,
    enabled: bool,
}

impl Probe {
    /// Whether the segment [t0, t1] of the ray crosses surface `i`'s box.
    #[inline]
    fn may_hit(&self, culling: &AnalyticCulling, i: usize, t0: f32, t1: f32) -> bool {
        !self.enabled || self.entry(culling, i, t0, t1).is_some()
    }

    /// Where the segment [t0, t1] of the ray enters surface `i`'s box, if it crosses it.
    #[inline]
    fn entry(&self, culling: &AnalyticCulling, i: usize, t0: f32, t1: f32) -> Option<f32> {
        let (bounds, offset) = &culling.boxes[i];
        self.enter(bounds, *offset, t0, t1)
    }

    /// The slab test against the box widened by twice its rounding margin, so that every point the surface's
    /// `intersect` returns lies inside it by a margin that also covers the slab test's own rounding.
    #[inline]
    fn crosses(&self, b: &Bounds, anchor_offset: f32, t0: f32, t1: f32) -> bool {
        self.enter(b, anchor_offset, t0, t1).is_some()
    }

    /// Where `crosses` enters the box.
    #[inline]
    fn enter(&self, b: &Bounds, anchor_offset: f32, t0: f32, t1: f32) -> Option<f32> {
        let pad = Vec3::splat(2.0 * b.margin(self.distance + anchor_offset));
        let a = (b.min - pad - self.origin) * self.inv;
        let c = (b.max + pad - self.origin) * self.inv;
        let enter = a.min(c).max_element().max(t0);
        let exit = a.max(c).min_element().min(t1);
        (enter <= exit).then_some(enter)
    }
}

/// Scenes with at most this many analytic surfaces solve them in the order rays enter their boxes (the
/// entries sort on the stack); more are solved in index order, each still behind its box.
const SORTED_SURFACES: usize = 32;

/// Minimum hit distance relative to the scene size: rays start on surfaces, offset by `offset_origin`.
const RELATIVE_T_MIN: f32 = 1e-7;

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
        let mut extent = 0.0f32;
        for (_, t) in &triangles {
            for v in t.v {
                extent = extent.max(v.abs().max_element());
            }
        }
        for (_, a) in &analytic {
            let (c, r) = match a {
                Analytic::Sphere(s) => (s.center, s.radius),
                Analytic::Lens(l) => (l.vertex, l.curvature_radius.abs().max(l.aperture_radius)),
                Analytic::Annulus(a) => (a.center, a.outer_radius),
            };
            extent = extent.max(c.abs().max_element() + r);
        }
        let accel = if triangles.is_empty() {
            TriangleAccel::None
        } else {
            match backend {
                Backend::Obvhs(preset) => TriangleAccel::Obvhs(build_obvhs(&triangles, preset)),
                #[cfg(feature = "embree")]
                Backend::Embree => TriangleAccel::Embree(super::embree::EmbreeTriangles::build(&triangles)?),
            }
        };
        let edges = SurfaceEdges::find(&triangles);
        Ok(SceneGeometry {
            backend,
            accel,
            by_index: triangles,
            edges,
            culling: AnalyticCulling::new(&analytic),
            analytic,
            t_min: RELATIVE_T_MIN * (1.0 + extent),
        })
    }

    /// The same geometry solving every analytic surface for every ray, as if it kept no boxes around them: the
    /// reference the culling must agree with, for tests and measurements.
    pub fn without_analytic_culling(mut self) -> Self {
        self.culling.enabled = false;
        self
    }

    /// The same surfaces with their BVH built by another backend, to compare backends.
    pub fn rebuilt_with(&self, backend: Backend) -> Result<SceneGeometry, AccelError> {
        let mut g = Self::build_with(backend, self.by_index.clone(), self.analytic.clone())?;
        g.culling.enabled = self.culling.enabled;
        Ok(g)
    }

    /// The backend that traces this geometry's triangles.
    pub fn backend(&self) -> Backend {
        self.backend
    }

    /// The analytic surfaces and their objects, in the order they were added.
    pub fn analytic_surfaces(&self) -> &[(u32, Analytic)] {
        &self.analytic
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.by_index.len()
    }

    /// A triangle by the index it was added with.
    pub fn triangle(&self, index: u32) -> &MeshTriangle {
        &self.by_index[index as usize].1
    }

    /// The object a triangle (by the index it was added with) belongs to.
    pub fn object_of_triangle(&self, index: u32) -> u32 {
        self.by_index[index as usize].0
    }

    /// The edges of a triangle (by the index it was added with) beyond which its surface does not go on: bit i
    /// for the edge from vertex i to vertex i + 1.
    #[inline]
    pub fn surface_edges(&self, index: u32) -> u8 {
        self.edges.of(index)
    }

    /// The closest surface along the ray, if any.
    pub fn intersect(&self, ray: &Ray) -> Option<SurfaceHit> {
        let mut best_t = ray.t_max;
        let mut best: Option<SurfaceHit> = None;
        match &self.accel {
            TriangleAccel::None => {}
            TriangleAccel::Obvhs(o) => {
                let bray = BvhRay::new(Vec3A::from(ray.origin), Vec3A::from(ray.direction), self.t_min, ray.t_max);
                let mut hit = RayHit::none();
                if o.bvh.ray_traverse(bray, &mut hit, |r, id| o.triangles[id].intersect(r)) && hit.t < best_t {
                    let id = hit.primitive_id as usize;
                    let (tri, data) = (&o.triangles[id], &o.data[id]);
                    best_t = hit.t;
                    let uv = || barycentrics(tri, ray);
                    best = Some(triangle_hit(
                        ray,
                        hit.t,
                        [tri.v0, tri.v1, tri.v2],
                        data.normals,
                        uv,
                        data.object,
                        data.index,
                    ));
                }
            }
            #[cfg(feature = "embree")]
            TriangleAccel::Embree(e) => {
                if let Some(h) = e.intersect(ray, self.t_min) {
                    let (object, tri) = &self.by_index[h.index as usize];
                    let v = tri.v.map(Vec3A::from);
                    best_t = h.t;
                    best = Some(triangle_hit(ray, h.t, v, tri.n, || (h.u, h.v), *object, h.index));
                }
            }
        }
        let Some(probe) = self.culling.probe(ray.origin, ray.direction, self.t_min, best_t) else {
            return best;
        };
        if probe.enabled && self.analytic.len() <= SORTED_SURFACES {
            return self.intersect_analytic_sorted(ray, &probe, best_t, best);
        }
        for (i, (object, a)) in self.analytic.iter().enumerate() {
            if !probe.may_hit(&self.culling, i, self.t_min, best_t) {
                continue;
            }
            let r = Ray { t_max: best_t, ..*ray };
            if let Some((t, n)) = a.intersect(&r, self.t_min) {
                best_t = t;
                best = Some(SurfaceHit { t, p: ray.at(t), ng: n, ns: n, object: *object, triangle: u32::MAX });
            }
        }
        best
    }

    /// The analytic part of `intersect`, solving the surfaces in the order the ray enters their boxes, so that
    /// the nearest hit comes early and every box entered beyond it is skipped (in a lens, the surfaces are stacked
    /// along the ray, and index order solves all of them for the rays that cross the stack back to front). The
    /// answer is the one index order gives: the least t, ties to the lower index and to a triangle.
    fn intersect_analytic_sorted(
        &self,
        ray: &Ray,
        probe: &Probe,
        mut best_t: f32,
        mut best: Option<SurfaceHit>,
    ) -> Option<SurfaceHit> {
        let mut entries = [(0.0f32, 0u32); SORTED_SURFACES];
        let mut count = 0;
        for i in 0..self.analytic.len() {
            if let Some(enter) = probe.entry(&self.culling, i, self.t_min, best_t) {
                let mut j = count;
                while j > 0 && entries[j - 1].0 > enter {
                    entries[j] = entries[j - 1];
                    j -= 1;
                }
                entries[j] = (enter, i as u32);
                count += 1;
            }
        }
        let mut best_index: Option<u32> = None;
        for &(enter, i) in &entries[..count] {
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
                let bray = BvhRay::new(Vec3A::from(from), Vec3A::from(dir), self.t_min, t_max);
                !o.bvh.ray_traverse_miss(bray, |r, id| o.triangles[id].intersect(r))
            }
            #[cfg(feature = "embree")]
            TriangleAccel::Embree(e) => e.occluded(from, dir, self.t_min, t_max),
        };
        if blocked {
            return false;
        }
        let Some(probe) = self.culling.probe(from, dir, self.t_min, t_max) else {
            return true;
        };
        let r = Ray { origin: from, direction: dir, t_max };
        !self.analytic.iter().enumerate().any(|(i, (_, a))| {
            probe.may_hit(&self.culling, i, self.t_min, t_max) && a.intersect(&r, self.t_min).is_some()
        })
    }
}

fn build_obvhs(triangles: &[(u32, MeshTriangle)], preset: ObvhsPreset) -> ObvhsTriangles {
    let tris: Vec<Triangle> = triangles
        .iter()
        .map(|(_, t)| Triangle { v0: Vec3A::from(t.v[0]), v1: Vec3A::from(t.v[1]), v2: Vec3A::from(t.v[2]) })
        .collect();
    let bvh = build_cwbvh_from_tris(&tris, preset.params(), &mut Duration::default());
    let order: Vec<usize> = bvh.primitive_indices.iter().map(|&i| i as usize).collect();
    let triangles_bvh = order.iter().map(|&i| tris[i]).collect();
    let data = order
        .iter()
        .map(|&i| TriangleData { object: triangles[i].0, index: i as u32, normals: triangles[i].1.n })
        .collect();
    ObvhsTriangles { bvh, triangles: triangles_bvh, data }
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
            // Off the quads' shared diagonal: obvhs's Möller test is not watertight exactly on an edge.
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
}
