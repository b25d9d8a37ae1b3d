//! Geometry: rays, triangle meshes, analytic optical surfaces (spheres, lens surfaces, annuli) and the acceleration structure over all of them.

pub mod accel;
pub mod analytic;
#[cfg(feature = "embree")]
mod embree;
pub mod hit;
pub mod mesh;
pub mod ray;

pub use accel::{AccelError, Backend, ObvhsPreset, SceneGeometry, BACKEND_VARIABLE};
pub use analytic::{Analytic, Annulus, LensSurface, Sphere};
pub use hit::SurfaceHit;
pub use mesh::{Mesh, MeshTriangle};
pub use ray::Ray;
