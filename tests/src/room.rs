//! A room of production size, generated rather than shipped: a box of diffuse walls lit by a ceiling panel,
//! holding one bumpy sphere of about N triangles, with a camera of any resolution. The mesh is written beside
//! the scene file, so a run reads and builds it as it would a modelled one; its bumps give the BVH real depth
//! complexity. It is written as `room.toml` with an OBJ, or as the same room in Mitsuba 3's `room.xml` with a
//! binary PLY, the format large production meshes usually come in. `production-scene` writes one from the
//! command line, and the tests make small ones.

use photonfarm::scene::SceneRenderSettings;
use std::fmt::Write as _;
use std::fs::File;
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

/// The format of the sphere's mesh, and with it the scene file's: photonfarm's TOML scenes read OBJ meshes, its
/// Mitsuba importer PLY ones.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MeshFormat {
    /// `room.toml` and `room/sphere.obj`.
    #[default]
    Obj,
    /// `room.xml` (Mitsuba 3) and `room/sphere.ply`, binary little-endian.
    Ply,
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
    write_room_as(dir, spec, MeshFormat::Obj)
}

/// Writes the room in `format` into `dir` (created if missing): `room.toml` and `room/sphere.obj`, or
/// `room.xml` and `room/sphere.ply`.
pub fn write_room_as(dir: &Path, spec: RoomSpec, format: MeshFormat) -> std::io::Result<Room> {
    std::fs::create_dir_all(dir.join("room"))?;
    let (mesh_name, scene_name) = match format {
        MeshFormat::Obj => ("sphere.obj", "room.toml"),
        MeshFormat::Ply => ("sphere.ply", "room.xml"),
    };
    let mesh = dir.join("room").join(mesh_name);
    let file = BufWriter::with_capacity(1 << 20, File::create(&mesh)?);
    let triangles = match format {
        MeshFormat::Obj => write_sphere(spec.triangles, &mut ObjWriter(file))?,
        MeshFormat::Ply => write_sphere(spec.triangles, &mut PlyWriter::new(file, spec.triangles)?)?,
    };
    let scene = dir.join(scene_name);
    let layout = Layout::of(spec);
    let text = match format {
        MeshFormat::Obj => layout.toml(),
        MeshFormat::Ply => layout.mitsuba(),
    };
    std::fs::write(&scene, text)?;
    Ok(Room { scene, mesh, triangles })
}

/// The camera, as both formats write it: the Cornell box's, looking along +z with +y up.
const CAMERA_POSITION: [f64; 3] = [0.278, 0.273, -0.8];
const CAMERA_LOOK_AT: [f64; 3] = [0.278, 0.273, 0.0];
const CAMERA_UP: [f64; 3] = [0.0, 1.0, 0.0];
const FOV_Y_DEG: f64 = 39.3;

/// The diffuse materials by name, linear RGB albedos.
const MATERIALS: [(&str, [f64; 3]); 3] =
    [("white", [0.8, 0.8, 0.8]), ("red", [0.57, 0.04, 0.04]), ("green", [0.1, 0.38, 0.08])];

/// One parallelogram of the room: its front faces along edge1 × edge2, which is the side a light emits from.
struct Quad {
    name: &'static str,
    material: &'static str,
    emission: Option<[f64; 3]>,
    corner: [f64; 3],
    edge1: [f64; 3],
    edge2: [f64; 3],
}

/// Everything in the room but the sphere, written out by either format from this one description so that the
/// two cannot drift apart.
struct Layout {
    spec: RoomSpec,
    quads: Vec<Quad>,
}

impl Layout {
    /// A room as wide as the image's aspect needs, so the camera sees walls to its edges.
    fn of(spec: RoomSpec) -> Layout {
        let aspect = spec.width as f64 / spec.height as f64;
        // The Cornell box's height and depth; its width grows with the aspect so no edge of the image sees out.
        let (h, d) = (0.5488, 0.5592);
        let w = (0.556 * aspect).max(0.556);
        let x0 = 0.278 - w / 2.0;
        let x1 = x0 + w;
        let quad = |name, material, corner, edge1, edge2| Quad { name, material, emission: None, corner, edge1, edge2 };
        let quads = vec![
            quad("floor", "white", [x0, 0.0, 0.0], [w, 0.0, 0.0], [0.0, 0.0, d]),
            quad("ceiling", "white", [x0, h, 0.0], [w, 0.0, 0.0], [0.0, 0.0, d]),
            quad("back wall", "white", [x0, 0.0, d], [w, 0.0, 0.0], [0.0, h, 0.0]),
            quad("left wall", "red", [x1, 0.0, 0.0], [0.0, 0.0, d], [0.0, h, 0.0]),
            quad("right wall", "green", [x0, 0.0, 0.0], [0.0, 0.0, d], [0.0, h, 0.0]),
            // Just below the ceiling, facing down (x × z = −y).
            Quad {
                emission: Some([17.0, 12.0, 4.0]),
                ..quad("light", "white", [0.213, 0.5487, 0.227], [0.13, 0.0, 0.0], [0.0, 0.0, 0.105])
            },
        ];
        Layout { spec, quads }
    }

    /// The scene as photonfarm's TOML.
    fn toml(&self) -> String {
        let spec = self.spec;
        let mut text = format!(
            "# A generated room (tests/src/room.rs): a bumpy sphere of {tris} triangles in a box lit by a ceiling \
             panel.\n\n[camera]\ntype = \"pinhole\"\nposition = {position}\nlook_at = {look_at}\nup = {up}\n\
             fov_y_deg = {FOV_Y_DEG}\nwidth = {width}\nheight = {height}\n",
            tris = sphere_triangles(spec.triangles),
            position = toml_vec(CAMERA_POSITION),
            look_at = toml_vec(CAMERA_LOOK_AT),
            up = toml_vec(CAMERA_UP),
            width = spec.width,
            height = spec.height,
        );
        for (name, albedo) in MATERIALS {
            let _ = write!(text, "\n[materials.{name}]\ntype = \"diffuse\"\nalbedo = {}\n", toml_vec(albedo));
        }
        for q in &self.quads {
            let _ = write!(text, "\n[[objects]]\nname = \"{}\"\nmaterial = \"{}\"\n", q.name, q.material);
            if let Some(e) = q.emission {
                let _ = writeln!(text, "emission = {}", toml_vec(e));
            }
            let _ = writeln!(
                text,
                "quad = {{ corner = {}, edge1 = {}, edge2 = {} }}",
                toml_vec(q.corner),
                toml_vec(q.edge1),
                toml_vec(q.edge2)
            );
        }
        text + "\n[[objects]]\nname = \"sphere\"\nmaterial = \"white\"\nmesh = \"room/sphere.obj\"\n"
    }

    /// The scene as Mitsuba 3 XML. photonfarm's diffuse surfaces are two-sided and Mitsuba's are not, so each
    /// BSDF is wrapped in `twosided`; the quads are `rectangle`s, whose [−1, 1]² facing +z `to_world` stretches
    /// onto the quad with +z along its front, so the light emits to the same side.
    fn mitsuba(&self) -> String {
        let spec = self.spec;
        let xml_vec = |v: [f64; 3]| format!("{}, {}, {}", v[0], v[1], v[2]);
        let mut text = format!(
            r#"<?xml version="1.0" encoding="utf-8"?>
<!-- A generated room (tests/src/room.rs): a bumpy sphere of {tris} triangles in a box lit by a ceiling panel,
     the same room as the room.toml it writes with an OBJ. The sphere has no vertex normals: face_normals keeps
     Mitsuba from smoothing it, so that it is shaded flat as photonfarm shades the OBJ. -->
<scene version="3.0.0">
    <integrator type="path">
        <integer name="max_depth" value="{max_depth}"/>
    </integrator>

    <sensor type="perspective">
        <string name="fov_axis" value="y"/>
        <float name="fov" value="{FOV_Y_DEG}"/>
        <transform name="to_world">
            <lookat origin="{position}" target="{look_at}" up="{up}"/>
        </transform>
        <film type="hdrfilm">
            <integer name="width" value="{width}"/>
            <integer name="height" value="{height}"/>
            <rfilter type="box"/>
        </film>
    </sensor>
"#,
            tris = sphere_triangles(spec.triangles),
            // A TOML scene without a [render] table renders with the default depth: the same here.
            max_depth = SceneRenderSettings::default().max_depth,
            position = xml_vec(CAMERA_POSITION),
            look_at = xml_vec(CAMERA_LOOK_AT),
            up = xml_vec(CAMERA_UP),
            width = spec.width,
            height = spec.height,
        );
        text.push('\n');
        for (name, albedo) in MATERIALS {
            let _ = writeln!(
                text,
                "    <bsdf type=\"twosided\" id=\"{name}\">\n        <bsdf type=\"diffuse\"><rgb name=\"reflectance\" \
                 value=\"{}\"/></bsdf>\n    </bsdf>",
                xml_vec(albedo)
            );
        }
        for q in &self.quads {
            let _ = write!(
                text,
                "\n    <shape type=\"rectangle\" id=\"{}\">\n        <transform name=\"to_world\">\n            \
                 <matrix value=\"{}\"/>\n        </transform>\n        <ref id=\"{}\"/>\n",
                q.name.replace(' ', "-"),
                rectangle_matrix(q),
                q.material
            );
            if let Some(e) = q.emission {
                let _ = writeln!(
                    text,
                    "        <emitter type=\"area\">\n            <rgb name=\"radiance\" value=\"{}\"/>\n        \
                     </emitter>",
                    xml_vec(e)
                );
            }
            text.push_str("    </shape>\n");
        }
        text + r#"
    <shape type="ply" id="sphere">
        <string name="filename" value="room/sphere.ply"/>
        <boolean name="face_normals" value="true"/>
        <ref id="white"/>
    </shape>
</scene>
"#
    }
}

/// A TOML array of three floats; `{:?}` keeps the decimal point on whole numbers.
fn toml_vec(v: [f64; 3]) -> String {
    format!("[{:?}, {:?}, {:?}]", v[0], v[1], v[2])
}

/// Mitsuba's `matrix` value, row by row, that takes its rectangle onto `q`: (−1, −1) to the corner, +x along
/// edge1, +y along edge2 and +z to the unit normal edge1 × edge2. The rectangle's triangles then have the
/// quad's corners and winding, and its normal (the inverse transpose's +z) is that unit normal, the edges
/// being perpendicular.
fn rectangle_matrix(q: &Quad) -> String {
    let half = |e: [f64; 3]| e.map(|c| 0.5 * c);
    let (a, b) = (half(q.edge1), half(q.edge2));
    let (e1, e2) = (q.edge1, q.edge2);
    let n = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
    let length = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    let n = n.map(|c| c / length);
    let t: [f64; 3] = std::array::from_fn(|r| q.corner[r] + a[r] + b[r]);
    let mut rows: Vec<String> = (0..3).map(|r| format!("{} {} {} {}", a[r], b[r], n[r], t[r])).collect();
    rows.push("0 0 0 1".into());
    rows.join("  ")
}

/// Where the sphere's vertices and triangles go, in the order generated; indices count from 0.
trait MeshSink {
    fn vertex(&mut self, p: [f64; 3]) -> std::io::Result<()>;
    fn triangle(&mut self, t: [u64; 3]) -> std::io::Result<()>;
    fn finish(&mut self) -> std::io::Result<()>;
}

/// Wavefront OBJ text, six decimals (a micrometre in this room).
struct ObjWriter<W: Write>(W);

impl<W: Write> MeshSink for ObjWriter<W> {
    fn vertex(&mut self, p: [f64; 3]) -> std::io::Result<()> {
        writeln!(self.0, "v {:.6} {:.6} {:.6}", p[0], p[1], p[2])
    }

    fn triangle(&mut self, t: [u64; 3]) -> std::io::Result<()> {
        // OBJ indices count from 1.
        writeln!(self.0, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1)
    }

    fn finish(&mut self) -> std::io::Result<()> {
        self.0.flush()
    }
}

/// Binary little-endian PLY 1.0. Its header gives the element counts before the data, which the sphere's grid
/// knows in advance, so the file streams out like the OBJ.
struct PlyWriter<W: Write>(W);

impl<W: Write> PlyWriter<W> {
    /// Writes the header for the sphere of about `triangles` triangles; refused when its vertices outnumber
    /// what the `int` indices can name.
    fn new(mut out: W, triangles: u64) -> std::io::Result<Self> {
        let (rings, segments) = grid(triangles);
        let vertices = 2 + (rings - 1) * segments;
        if vertices > i32::MAX as u64 {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!("{vertices} vertices are more than a PLY face's int indices can name"),
            ));
        }
        write!(
            out,
            "ply\nformat binary_little_endian 1.0\ncomment a generated room's sphere (tests/src/room.rs)\n\
             element vertex {vertices}\nproperty float x\nproperty float y\nproperty float z\n\
             element face {}\nproperty list uchar int vertex_indices\nend_header\n",
            sphere_triangles(triangles)
        )?;
        Ok(PlyWriter(out))
    }
}

impl<W: Write> MeshSink for PlyWriter<W> {
    fn vertex(&mut self, p: [f64; 3]) -> std::io::Result<()> {
        let mut record = [0u8; 12];
        for (bytes, c) in record.chunks_exact_mut(4).zip(p) {
            bytes.copy_from_slice(&(c as f32).to_le_bytes());
        }
        self.0.write_all(&record)
    }

    fn triangle(&mut self, t: [u64; 3]) -> std::io::Result<()> {
        let mut record = [3u8; 13];
        for (bytes, i) in record[1..].chunks_exact_mut(4).zip(t) {
            // `PlyWriter::new` checked that every index fits.
            bytes.copy_from_slice(&(i as i32).to_le_bytes());
        }
        self.0.write_all(&record)
    }

    fn finish(&mut self) -> std::io::Result<()> {
        self.0.flush()
    }
}

/// Writes the sphere into `out` and returns its triangle count. Vertices lie on a sphere of radius 0.14 m whose
/// radius is modulated by 3% in a pattern of bumps a few dozen triangles across; every triangle has a positive
/// area and faces outward (counter-clockwise seen from outside).
fn write_sphere(triangles: u64, out: &mut impl MeshSink) -> std::io::Result<u64> {
    let (rings, segments) = grid(triangles);
    let centre = [0.278, 0.16, 0.28];
    let radius = 0.14;
    let bumps = (rings as f64 / 24.0).max(3.0);
    let vertex = |theta: f64, phi: f64| {
        let r = radius * (1.0 + 0.03 * (bumps * theta).sin() * (bumps * phi).sin());
        let (st, ct) = theta.sin_cos();
        let (sp, cp) = phi.sin_cos();
        [centre[0] + r * st * cp, centre[1] + r * ct, centre[2] + r * st * sp]
    };
    let pi = std::f64::consts::PI;
    out.vertex(vertex(0.0, 0.0))?;
    for i in 1..rings {
        let theta = pi * i as f64 / rings as f64;
        for j in 0..segments {
            out.vertex(vertex(theta, 2.0 * pi * j as f64 / segments as f64))?;
        }
    }
    out.vertex(vertex(pi, 0.0))?;
    // The north pole is 0, ring i's segment j is 1 + (i − 1) · segments + j, the south pole last.
    let at = |i: u64, j: u64| 1 + (i - 1) * segments + j % segments;
    let south = 1 + (rings - 1) * segments;
    let mut count = 0;
    for j in 0..segments {
        out.triangle([0, at(1, j + 1), at(1, j)])?;
        count += 1;
    }
    for i in 1..rings - 1 {
        for j in 0..segments {
            let (a, b, c, d) = (at(i, j), at(i, j + 1), at(i + 1, j), at(i + 1, j + 1));
            out.triangle([a, b, d])?;
            out.triangle([a, d, c])?;
            count += 2;
        }
    }
    for j in 0..segments {
        out.triangle([south, at(rings - 1, j), at(rings - 1, j + 1)])?;
        count += 1;
    }
    out.finish()?;
    Ok(count)
}

#[cfg(test)]
mod tests {
    use super::*;
    use photonfarm::light::Light;
    use photonfarm::scene::Scene;

    /// A small spec both formats are written from.
    const SMALL: RoomSpec = RoomSpec { triangles: 2_000, width: 48, height: 27 };

    #[test]
    fn the_generated_room_loads_with_the_triangles_it_reports_and_the_asked_resolution() {
        let dir = tempfile::tempdir().unwrap();
        let room = write_room(dir.path(), RoomSpec { triangles: 20_000, width: 192, height: 108 }).unwrap();
        let scene = Scene::load(&room.scene).unwrap();
        assert_eq!((scene.camera.width, scene.camera.height), (192, 108));
        // Six quads of two triangles each, and the sphere.
        assert_eq!(scene.geometry.triangle_count() as u64, 12 + room.triangles);
        assert!((room.triangles as f64 - 20_000.0).abs() < 0.05 * 20_000.0, "{}", room.triangles);
    }

    /// The room written in `format` into a new folder, loaded.
    fn load(format: MeshFormat) -> (tempfile::TempDir, Room, Scene) {
        let dir = tempfile::tempdir().unwrap();
        let room = write_room_as(dir.path(), SMALL, format).unwrap();
        let scene = Scene::load(&room.scene).unwrap_or_else(|e| panic!("{format:?}: {e}"));
        (dir, room, scene)
    }

    #[test]
    fn the_ply_room_is_the_obj_room() {
        let (_obj_dir, obj_room, obj) = load(MeshFormat::Obj);
        let (_ply_dir, ply_room, ply) = load(MeshFormat::Ply);
        assert_eq!(obj_room.triangles, ply_room.triangles);
        assert_eq!(obj.geometry.triangle_count(), ply.geometry.triangle_count());
        assert_eq!(obj.geometry.triangle_count() as u64, 12 + ply_room.triangles);

        let (lo, hi) = obj.geometry.bounds().unwrap();
        let (plo, phi) = ply.geometry.bounds().unwrap();
        let tolerance = 1e-4 * lo.distance(hi);
        assert!(lo.distance(plo) < tolerance && hi.distance(phi) < tolerance, "{lo} {hi} against {plo} {phi}");

        let (c, p) = (&obj.camera, &ply.camera);
        assert_eq!((c.width, c.height), (p.width, p.height));
        assert_eq!((p.width, p.height), (SMALL.width, SMALL.height));
        assert!(c.position.distance(p.position) < 1e-6, "{} {}", c.position, p.position);
        for (a, b) in [(c.forward(), p.forward()), (c.up(), p.up()), (c.right(), p.right())] {
            assert!(a.distance(b) < 1e-5, "{a} {b}");
        }
        // A grid of pixels from corner to corner: a field of view or aspect mapped wrongly moves the outer ones.
        let (w, h) = (SMALL.width - 1, SMALL.height - 1);
        for (x, y) in (0..=4).flat_map(|i| (0..=4).map(move |j| (i * w / 4, j * h / 4))) {
            let a = c.generate_ray(x, y, [0.5, 0.5].into(), Default::default()).ray;
            let b = p.generate_ray(x, y, [0.5, 0.5].into(), Default::default()).ray;
            assert!(a.direction.distance(b.direction) < 1e-5, "pixel ({x}, {y}): {} {}", a.direction, b.direction);
            // They meet the same surface at the same distance, or (the top row, past the open front) both escape.
            match (obj.geometry.intersect(&a), ply.geometry.intersect(&b)) {
                (None, None) => {}
                (Some(ha), Some(hb)) => {
                    let material =
                        |s: &Scene, object: u32| s.materials[s.objects[object as usize].material as usize].clone();
                    assert_eq!(material(&obj, ha.object), material(&ply, hb.object), "pixel ({x}, {y})");
                    assert!((ha.t - hb.t).abs() < 1e-4 * ha.t, "pixel ({x}, {y}): {} {}", ha.t, hb.t);
                    assert!(ha.ng.distance(hb.ng) < 1e-3, "pixel ({x}, {y}): {} {}", ha.ng, hb.ng);
                }
                (ha, hb) => panic!("pixel ({x}, {y}): {ha:?} against {hb:?}"),
            }
        }

        // Object by object in the order written: the same material and emission.
        assert_eq!(obj.objects.len(), ply.objects.len());
        for (a, b) in obj.objects.iter().zip(&ply.objects) {
            let (ma, mb) = (&obj.materials[a.material as usize], &ply.materials[b.material as usize]);
            assert_eq!(ma, mb, "{} against {}", a.name, b.name);
            assert_eq!(a.emission, b.emission, "{} against {}", a.name, b.name);
        }

        // The ceiling panel: two triangles of the same radiance, area and emitting side.
        let area_lights = |s: &Scene| -> Vec<(f32, [f32; 3], [f32; 3])> {
            s.lights
                .all()
                .iter()
                .map(|l| match *l {
                    Light::Area { emission, area, normal, .. } => (area, emission.to_array(), normal.to_array()),
                    ref other => panic!("an unexpected light {other:?}"),
                })
                .collect()
        };
        let (la, lb) = (area_lights(&obj), area_lights(&ply));
        assert_eq!(la.len(), 2);
        assert_eq!(la.len(), lb.len());
        for (a, b) in la.iter().zip(&lb) {
            assert!((a.0 - b.0).abs() < 1e-5 * a.0, "area {} against {}", a.0, b.0);
            assert_eq!(a.1, b.1);
            assert!((0..3).all(|k| (a.2[k] - b.2[k]).abs() < 1e-5), "normal {:?} against {:?}", a.2, b.2);
            assert_eq!(a.2, [0.0, -1.0, 0.0]);
        }
        let power = |s: &Scene| s.lights.all().iter().map(|l| l.power(&s.lights.scene_sphere())).sum::<f32>();
        assert!((power(&obj) - power(&ply)).abs() < 1e-5 * power(&obj));
        assert_eq!(obj.render, ply.render);
    }

    #[test]
    fn the_ply_sphere_is_binary_little_endian_with_the_counts_its_header_gives() {
        let dir = tempfile::tempdir().unwrap();
        let room = write_room_as(dir.path(), SMALL, MeshFormat::Ply).unwrap();
        let bytes = std::fs::read(&room.mesh).unwrap();
        let end = b"end_header\n";
        let body = bytes.windows(end.len()).position(|w| w == end).unwrap() + end.len();
        let header = std::str::from_utf8(&bytes[..body]).unwrap();
        assert!(header.starts_with("ply\nformat binary_little_endian 1.0\n"), "{header}");
        let count = |element: &str| -> u64 {
            let line = header.lines().find(|l| l.starts_with(&format!("element {element} "))).unwrap();
            line.rsplit(' ').next().unwrap().parse().unwrap()
        };
        let (vertices, faces) = (count("vertex"), count("face"));
        assert_eq!(faces, room.triangles);
        // Three floats a vertex; a count byte and three ints a face.
        assert_eq!(bytes.len() as u64 - body as u64, 12 * vertices + 13 * faces);
        let first = |k: usize| f32::from_le_bytes(bytes[body + 4 * k..body + 4 * k + 4].try_into().unwrap());
        // The north pole: above the sphere's centre by its radius.
        assert_eq!([first(0), first(1), first(2)], [0.278, 0.3, 0.28]);
    }
}
