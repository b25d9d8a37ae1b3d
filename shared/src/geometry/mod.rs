//! Geometry: rays, triangle meshes, analytic optical surfaces (spheres, lens surfaces, annuli), the acceleration structure over all of them, where surfaces end, and a cache of large meshes' BVHs on disk.

pub mod accel;
pub mod analytic;
mod analytic_culling;
mod bvh_cache;
#[cfg(feature = "embree")]
mod embree;
pub mod hit;
pub mod mesh;
pub mod per_triangle;
pub mod ray;
pub mod surface_edges;
pub mod watertight;

pub use accel::{AccelError, Backend, ObvhsPreset, SceneGeometry, BACKEND_VARIABLE};
pub use analytic::{Analytic, Annulus, LensSurface, Sphere};
pub use bvh_cache::{BvhCache, BvhCacheUse, BVH_CACHE_VARIABLE};
pub use hit::SurfaceHit;
pub use mesh::{Mesh, MeshTriangle};
pub use per_triangle::PerTriangle;
pub use ray::Ray;
pub use surface_edges::{SurfaceEdges, SAME_SURFACE_COS};
