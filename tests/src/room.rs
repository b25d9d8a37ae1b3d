//! A room of production size, generated rather than shipped: a box of diffuse walls lit by a ceiling panel,
//! holding one bumpy sphere of about N triangles, with a camera of any resolution. The mesh is written as an OBJ
//! beside the scene file, so a run reads and builds it as it would a modelled one; its bumps give the BVH real
//! depth complexity. `production-scene` writes one from the command line, and the tests make small ones.

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// What to generate.
#[derive(Clone, Copy, Debug)]
pub struct RoomSpec {
    /// About this many triangles in the sphere (rounded to a whole grid of rings and segments).
    pub triangles: u64,
    pub width: u32,
    pub height: u32,
}

/// The written scene.
#[derive(Clone, Debug)]
pub struct Room {
    /// The scene file.
    pub scene: PathBuf,
    /// The sphere's mesh file.
    pub mesh: PathBuf,
    /// Triangles in the sphere.
    pub triangles: u64,
}

/// Rings and segments of a sphere of about `triangles` triangles, two segments per ring: the pole fans give
/// `segments` each and every band between rings 2 × `segments`, so 2 × segments × (rings − 1) in all.
fn grid(triangles: u64) -> (u64, u64) {
    let rings = ((triangles as f64 / 4.0).sqrt().round() as u64).max(3);
    (rings, 2 * rings)
}

/// The triangles of the sphere generated for about `triangles`.
pub fn sphere_triangles(triangles: u64) -> u64 {
    let (rings, segments) = grid(triangles);
    2 * segments * (rings - 1)
}

/// Writes `room.toml` and `room/sphere.obj` into `dir` (created if missing).
pub fn write_room(dir: &Path, spec: RoomSpec) -> std::io::Result<Room> {
    std::fs::create_dir_all(dir.join("room"))?;
    let mesh = dir.join("room").join("sphere.obj");
    let triangles = write_sphere(&mesh, spec.triangles)?;
    let scene = dir.join("room.toml");
    std::fs::write(&scene, scene_text(spec))?;
    Ok(Room { scene, mesh, triangles })
}

/// The scene file: a room as wide as the image's aspect needs, so the camera sees walls to its edges.
fn scene_text(spec: RoomSpec) -> String {
    let aspect = spec.width as f64 / spec.height as f64;
    // The Cornell box's height and depth; its width grows with the aspect so no edge of the image sees out.
    let (h, d) = (0.5488, 0.5592);
    let w = (0.556 * aspect).max(0.556);
    let x0 = 0.278 - w / 2.0;
    let x1 = x0 + w;
    format!(
        r#"# A generated room (tests/src/room.rs): a bumpy sphere of {tris} triangles in a box lit by a ceiling panel.

[camera]
type = "pinhole"
position = [0.278, 0.273, -0.8]
look_at = [0.278, 0.273, 0.0]
fov_y_deg = 39.3
width = {width}
height = {height}

[materials.white]
type = "diffuse"
albedo = [0.8, 0.8, 0.8]

[materials.red]
type = "diffuse"
albedo = [0.57, 0.04, 0.04]

[materials.green]
type = "diffuse"
albedo = [0.1, 0.38, 0.08]

[[objects]]
name = "floor"
material = "white"
quad = {{ corner = [{x0}, 0.0, 0.0], edge1 = [{w}, 0.0, 0.0], edge2 = [0.0, 0.0, {d}] }}

[[objects]]
name = "ceiling"
material = "white"
quad = {{ corner = [{x0}, {h}, 0.0], edge1 = [{w}, 0.0, 0.0], edge2 = [0.0, 0.0, {d}] }}

[[objects]]
name = "back wall"
material = "white"
quad = {{ corner = [{x0}, 0.0, {d}], edge1 = [{w}, 0.0, 0.0], edge2 = [0.0, {h}, 0.0] }}

[[objects]]
name = "left wall"
material = "red"
quad = {{ corner = [{x1}, 0.0, 0.0], edge1 = [0.0, 0.0, {d}], edge2 = [0.0, {h}, 0.0] }}

[[objects]]
name = "right wall"
material = "green"
quad = {{ corner = [{x0}, 0.0, 0.0], edge1 = [0.0, 0.0, {d}], edge2 = [0.0, {h}, 0.0] }}

[[objects]]
name = "light"
material = "white"
emission = [17.0, 12.0, 4.0]
quad = {{ corner = [0.213, 0.5487, 0.227], edge1 = [0.13, 0.0, 0.0], edge2 = [0.0, 0.0, 0.105] }}

[[objects]]
name = "sphere"
material = "white"
mesh = "room/sphere.obj"
"#,
        tris = sphere_triangles(spec.triangles),
        width = spec.width,
        height = spec.height,
    )
}

/// Writes the sphere and returns its triangle count. Vertices lie on a sphere of radius 0.14 m whose radius is
/// modulated by 3% in a pattern of bumps a few dozen triangles across; every triangle has a positive area.
fn write_sphere(path: &Path, triangles: u64) -> std::io::Result<u64> {
    let (rings, segments) = grid(triangles);
    let centre = [0.278, 0.16, 0.28];
    let radius = 0.14;
    let bumps = (rings as f64 / 24.0).max(3.0);
    let mut out = BufWriter::with_capacity(1 << 20, std::fs::File::create(path)?);
    let vertex = |theta: f64, phi: f64, out: &mut BufWriter<std::fs::File>| -> std::io::Result<()> {
        let r = radius * (1.0 + 0.03 * (bumps * theta).sin() * (bumps * phi).sin());
        let (st, ct) = theta.sin_cos();
        let (sp, cp) = phi.sin_cos();
        writeln!(out, "v {:.6} {:.6} {:.6}", centre[0] + r * st * cp, centre[1] + r * ct, centre[2] + r * st * sp)
    };
    let pi = std::f64::consts::PI;
    vertex(0.0, 0.0, &mut out)?;
    for i in 1..rings {
        let theta = pi * i as f64 / rings as f64;
        for j in 0..segments {
            vertex(theta, 2.0 * pi * j as f64 / segments as f64, &mut out)?;
        }
    }
    vertex(pi, 0.0, &mut out)?;
    // OBJ indices count from 1: the north pole is 1, ring i's segment j is 2 + (i − 1) · segments + j.
    let at = |i: u64, j: u64| 2 + (i - 1) * segments + j % segments;
    let south = 2 + (rings - 1) * segments;
    let mut count = 0;
    for j in 0..segments {
        writeln!(out, "f 1 {} {}", at(1, j + 1), at(1, j))?;
        count += 1;
    }
    for i in 1..rings - 1 {
        for j in 0..segments {
            let (a, b, c, d) = (at(i, j), at(i, j + 1), at(i + 1, j), at(i + 1, j + 1));
            writeln!(out, "f {a} {b} {d}\nf {a} {d} {c}")?;
            count += 2;
        }
    }
    for j in 0..segments {
        writeln!(out, "f {south} {} {}", at(rings - 1, j), at(rings - 1, j + 1))?;
        count += 1;
    }
    out.flush()?;
    Ok(count)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_generated_room_loads_with_the_triangles_it_reports_and_the_asked_resolution() {
        let dir = tempfile::tempdir().unwrap();
        let room = write_room(dir.path(), RoomSpec { triangles: 20_000, width: 192, height: 108 }).unwrap();
        let scene = photonfarm::scene::Scene::load(&room.scene).unwrap();
        assert_eq!((scene.camera.width, scene.camera.height), (192, 108));
        // Six quads of two triangles each, and the sphere.
        assert_eq!(scene.geometry.triangle_count() as u64, 12 + room.triangles);
        assert!((room.triangles as f64 - 20_000.0).abs() < 0.05 * 20_000.0, "{}", room.triangles);
    }
}
