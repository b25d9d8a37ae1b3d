//! Geometry: rays, triangle meshes, analytic optical surfaces and the acceleration structure over all of them.

pub mod accel;
pub mod analytic;
pub mod hit;
pub mod mesh;
pub mod ray;

pub use accel::SceneGeometry;
pub use analytic::{Analytic, LensSurface, Sphere};
pub use hit::SurfaceHit;
pub use mesh::{Mesh, MeshTriangle};
pub use ray::Ray;
