//! `selection.glb`: the selected paths with the scene's geometry as one binary glTF 2.0 file, for any 3D viewer
//! (Blender, a web viewer). Each object is a mesh node named after it, with its material's base colour (glass
//! translucent, emitters emissive); each path is a node of line segments, each segment coloured by the event at
//! its end as in the overlay, all under a node `paths`. Coordinates are the scene's.

use super::canvas::event_colour;
use anyhow::{Context, Result};
use glam::Vec3;
use gltf_json as json;
use json::validation::Checked::Valid;
use json::validation::USize64;
use photonfarm::color::Rgb;
use photonfarm::material::{Material, Surface};
use photonfarm::ray_map::{PathKind, RecordedPath};
use photonfarm::scene::Scene;
use photonfarm::texture::Texture;
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::path::Path;

/// Builds the document and its binary buffer, appending each attribute's data to `bin`.
struct Builder {
    root: json::Root,
    bin: Vec<u8>,
    buffer: json::Index<json::Buffer>,
}

impl Builder {
    fn new() -> Self {
        let mut root = json::Root::default();
        root.asset.generator = Some(format!("photonfarm {} (rays select)", env!("CARGO_PKG_VERSION")));
        // The buffer's length is set once everything is in it.
        let buffer = root.push(json::Buffer {
            byte_length: USize64(0),
            extensions: None,
            extras: Default::default(),
            name: None,
            uri: None,
        });
        Builder { root, bin: Vec::new(), buffer }
    }

    /// An accessor of `Vec3` f32 values, with their bounds when `bounds` (positions need them).
    fn vec3(&mut self, values: &[Vec3], bounds: bool) -> json::Index<json::Accessor> {
        let offset = self.bin.len();
        for v in values {
            for c in v.to_array() {
                self.bin.extend_from_slice(&c.to_le_bytes());
            }
        }
        let view = self.root.push(json::buffer::View {
            buffer: self.buffer,
            byte_length: USize64::from(values.len() * 12),
            byte_offset: Some(USize64::from(offset)),
            byte_stride: None,
            extensions: None,
            extras: Default::default(),
            name: None,
            target: Some(Valid(json::buffer::Target::ArrayBuffer)),
        });
        let (min, max) = values.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(a, b), v| (a.min(*v), b.max(*v)));
        let bound = |v: Vec3| Some(json::Value::from(v.to_array().to_vec()));
        self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64::from(values.len()),
            component_type: Valid(json::accessor::GenericComponentType(json::accessor::ComponentType::F32)),
            extensions: None,
            extras: Default::default(),
            type_: Valid(json::accessor::Type::Vec3),
            min: if bounds { bound(min) } else { None },
            max: if bounds { bound(max) } else { None },
            name: None,
            normalized: false,
            sparse: None,
        })
    }

    fn material(
        &mut self,
        name: &str,
        base: [f32; 4],
        emissive: [f32; 3],
        metallic: f32,
    ) -> json::Index<json::Material> {
        self.root.push(json::Material {
            name: Some(name.to_string()),
            alpha_mode: Valid(if base[3] < 1.0 {
                json::material::AlphaMode::Blend
            } else {
                json::material::AlphaMode::Opaque
            }),
            double_sided: true,
            pbr_metallic_roughness: json::material::PbrMetallicRoughness {
                base_color_factor: json::material::PbrBaseColorFactor(base),
                metallic_factor: json::material::StrengthFactor(metallic),
                roughness_factor: json::material::StrengthFactor(if metallic > 0.0 { 0.05 } else { 0.8 }),
                ..Default::default()
            },
            emissive_factor: json::material::EmissiveFactor(emissive),
            ..Default::default()
        })
    }

    /// A node of one mesh of one primitive.
    fn node(&mut self, name: String, primitive: json::mesh::Primitive) -> json::Index<json::Node> {
        let mesh = self.root.push(json::Mesh {
            extensions: None,
            extras: Default::default(),
            name: Some(name.clone()),
            primitives: vec![primitive],
            weights: None,
        });
        self.root.push(json::Node { mesh: Some(mesh), name: Some(name), ..Default::default() })
    }

    fn primitive(
        attributes: Vec<(json::mesh::Semantic, json::Index<json::Accessor>)>,
        mode: json::mesh::Mode,
        material: json::Index<json::Material>,
    ) -> json::mesh::Primitive {
        json::mesh::Primitive {
            attributes: attributes.into_iter().map(|(s, a)| (Valid(s), a)).collect::<BTreeMap<_, _>>(),
            extensions: None,
            extras: Default::default(),
            indices: None,
            material: Some(material),
            mode: Valid(mode),
            targets: None,
        }
    }

    /// The file's bytes.
    fn finish(mut self, nodes: Vec<json::Index<json::Node>>) -> Result<Vec<u8>> {
        let scene = self.root.push(json::Scene { extensions: None, extras: Default::default(), name: None, nodes });
        self.root.scene = Some(scene);
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        self.root.buffers[self.buffer.value()].byte_length = USize64::from(self.bin.len());
        let text = json::serialize::to_string(&self.root).context("the glTF document does not serialise")?;
        let glb = gltf::binary::Glb {
            // `to_vec` writes the header's length itself.
            header: gltf::binary::Header { magic: *b"glTF", version: 2, length: 0 },
            json: Cow::Owned(text.into_bytes()),
            bin: Some(Cow::Owned(self.bin)),
        };
        glb.to_vec().context("the glTF binary cannot be written")
    }
}

/// A texture's mean over a whole period of (u, v): a bitmap's mean texel times its factor, a checkerboard's
/// two halves averaged.
fn mean(t: &Texture) -> Rgb {
    match t {
        Texture::Constant(c) => *c,
        Texture::Bitmap(b) => b.image.mean() * b.factor,
        Texture::Checkerboard(c) => (mean(&c.color0) + mean(&c.color1)) * 0.5,
    }
}

/// A material's base colour (with its opacity) and whether it is metal, as a viewer would show the surface: a
/// textured parameter shows its mean, a conductor its reflectance at normal incidence, a plastic its diffuse
/// base, every dielectric a pale translucent glass, and a principled surface its base colour, metallic and
/// transmission; an opacity texture scales the alpha by its mean.
fn look(material: &Material) -> ([f32; 4], f32) {
    let glass = [0.75, 0.88, 1.0, 0.25];
    let (colour, metallic) = match &material.front {
        Surface::Diffuse { reflectance } => {
            let c = mean(reflectance);
            ([c.x, c.y, c.z, 1.0], 0.0)
        }
        Surface::Conductor { fresnel, specular, .. } => {
            let c = fresnel.at(1.0) * mean(specular);
            ([c.x, c.y, c.z, 1.0], 1.0)
        }
        Surface::Dielectric { .. } | Surface::RoughDielectric { .. } | Surface::ThinDielectric { .. } => (glass, 0.0),
        Surface::Plastic { diffuse_reflectance, .. } => {
            let c = mean(diffuse_reflectance);
            ([c.x, c.y, c.z, 1.0], 0.0)
        }
        Surface::Principled(p) => {
            let c = mean(&p.base_color);
            let metallic = mean(&p.metallic).x.clamp(0.0, 1.0);
            let transmits = mean(&p.spec_trans).x.clamp(0.0, 1.0) * (1.0 - metallic);
            ([c.x, c.y, c.z, (1.0 - transmits).clamp(glass[3], 1.0)], metallic)
        }
        Surface::Coating { reflectance, transmittance } => {
            let t = (transmittance.x + transmittance.y + transmittance.z) / 3.0;
            ([reflectance.x, reflectance.y, reflectance.z, (1.0 - t).clamp(0.15, 1.0)], 0.0)
        }
    };
    let opacity = material.opacity.as_ref().map_or(1.0, |o| mean(o).x.clamp(0.0, 1.0));
    ([colour[0], colour[1], colour[2], colour[3] * opacity], metallic)
}

/// Writes the scene's objects (their `triangles`, by object) and the paths (with their world points
/// `polylines`) to `path` as a binary glTF file.
pub fn write_glb(
    path: &Path,
    scene: &Scene,
    triangles: &[Vec<[Vec3; 3]>],
    paths: &[RecordedPath],
    polylines: &[Vec<Vec3>],
) -> Result<()> {
    let mut b = Builder::new();
    let mut nodes = Vec::new();
    for (object, tris) in scene.objects.iter().zip(triangles) {
        if tris.is_empty() {
            continue;
        }
        let (base, metallic) = look(&scene.materials[object.material as usize]);
        // An emitter glows in its emission's colour, scaled to the brightest channel.
        let emissive = object.emission.map_or([0.0; 3], |e| {
            let m = e.max_element();
            if m > 0.0 {
                (e / m).to_array()
            } else {
                [0.0; 3]
            }
        });
        let material = b.material(&object.name, base, emissive, metallic);
        let positions: Vec<Vec3> = tris.iter().flatten().copied().collect();
        let positions = b.vec3(&positions, true);
        let primitive = Builder::primitive(
            vec![(json::mesh::Semantic::Positions, positions)],
            json::mesh::Mode::Triangles,
            material,
        );
        nodes.push(b.node(object.name.clone(), primitive));
    }
    // Lines take their colour from their vertices; viewers show lines unlit.
    let line_material = b.material("paths", [1.0; 4], [0.0; 3], 0.0);
    let mut path_nodes = Vec::new();
    for (i, (p, points)) in paths.iter().zip(polylines).enumerate() {
        if points.len() < 2 {
            continue;
        }
        // Each segment on its own pair of vertices, in the colour of the events at its end.
        let (mut positions, mut colours) = (Vec::new(), Vec::new());
        for (k, pair) in points.windows(2).enumerate() {
            let c = Vec3::from_array(event_colour(p.vertices[k + 1].events).0);
            positions.extend_from_slice(pair);
            colours.extend([c, c]);
        }
        let positions = b.vec3(&positions, true);
        let colours = b.vec3(&colours, false);
        let primitive = Builder::primitive(
            vec![(json::mesh::Semantic::Positions, positions), (json::mesh::Semantic::Colors(0), colours)],
            json::mesh::Mode::Lines,
            line_material,
        );
        let kind = if p.kind == PathKind::Camera { "camera" } else { "light" };
        path_nodes.push(b.node(format!("path{i}_{kind}_phase{}_item{}", p.phase, p.item), primitive));
    }
    nodes.push(b.root.push(json::Node {
        children: Some(path_nodes),
        name: Some("paths".into()),
        ..Default::default()
    }));
    let bytes = b.finish(nodes)?;
    std::fs::write(path, bytes).with_context(|| format!("cannot write {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use photonfarm::ray_map::{Events, Vertex};

    #[test]
    fn the_glb_validates_and_holds_the_scenes_objects_and_every_paths_vertices() {
        let scene = Scene::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/lens.toml")).unwrap();
        let triangles = super::super::surfaces::object_triangles(&scene);
        let paths: Vec<RecordedPath> = (0..5)
            .map(|i| {
                let mut p = RecordedPath::new(if i % 2 == 0 { PathKind::Camera } else { PathKind::Light }, 1, i, i);
                p.begin(Vec3::new(i as f32, 0.0, 0.0), Vec3::Y);
                for k in 1..=i + 1 {
                    let events = if k % 2 == 0 { Events::REFLECT } else { Events::DIFFUSE };
                    p.vertices.push(Vertex {
                        point: [i as f32, k as f32, 0.5],
                        normal: 0,
                        object: 0,
                        primitive: 0,
                        events,
                    });
                }
                p
            })
            .collect();
        let polylines: Vec<Vec<Vec3>> =
            paths.iter().map(|p| p.vertices.iter().map(|v| v.position()).collect()).collect();
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("selection.glb");
        write_glb(&file, &scene, &triangles, &paths, &polylines).unwrap();
        let bytes = std::fs::read(&file).unwrap();
        // Parsing validates the document against the specification.
        let gltf = gltf::Gltf::from_slice(&bytes).expect("a valid glTF binary");
        let blob = gltf.blob.as_deref().expect("a binary chunk");
        let mut objects = 0;
        let mut found = Vec::new();
        for node in gltf.nodes() {
            let Some(mesh) = node.mesh() else { continue };
            for primitive in mesh.primitives() {
                let reader = primitive.reader(|_| Some(blob));
                let points: Vec<[f32; 3]> = reader.read_positions().unwrap().collect();
                match primitive.mode() {
                    gltf::mesh::Mode::Triangles => {
                        objects += 1;
                        assert!(points.len().is_multiple_of(3) && !points.is_empty());
                    }
                    gltf::mesh::Mode::Lines => {
                        let colours = reader.read_colors(0).unwrap().into_rgb_f32().count();
                        assert_eq!(colours, points.len());
                        found.push((node.name().unwrap().to_string(), points));
                    }
                    other => panic!("unexpected {other:?}"),
                }
            }
        }
        assert_eq!(objects, triangles.iter().filter(|t| !t.is_empty()).count());
        assert!(gltf.nodes().any(|n| n.name() == Some("s5")), "the lens surfaces are named");
        assert_eq!(found.len(), paths.len());
        for (p, (name, points)) in paths.iter().zip(&found) {
            assert!(name.starts_with(&format!("path{}_", p.item)), "{name}");
            // Segment after segment, every vertex in order.
            let mut expected = Vec::new();
            for w in p.vertices.windows(2) {
                expected.extend([w[0].point, w[1].point]);
            }
            assert_eq!(points, &expected);
        }
    }
}
