//! The Mitsuba 3 XML reader and the serialized mesh format: transforms and spectra against values Mitsuba itself
//! printed (committed data), substitution, references, includes, refusals that name element and line, and
//! serialized round trips and damaged files.

use glam::{DMat4, DVec3};
use photonfarm::scene::mitsuba::serialized::{mesh_count, read_serialized, write_serialized, SerializedMesh};
use photonfarm::scene::mitsuba::{read_file, read_str, Category, Document, MitsubaError, Spectrum, SpectrumUse, Value};
use std::path::{Path, PathBuf};
use std::sync::Arc;

fn scene(body: &str) -> String {
    format!("<scene version=\"3.0.0\">\n{body}\n</scene>\n")
}

fn read(text: &str) -> Result<Document, MitsubaError> {
    read_str(text, Path::new("scene.xml"), &[])
}

fn data(name: &str) -> serde_json::Value {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/mitsuba").join(name);
    serde_json::from_str(&std::fs::read_to_string(&path).expect("test data")).expect("JSON")
}

fn to_world(document: &Document) -> DMat4 {
    match &document.shapes[0].param("to_world").expect("to_world").value {
        Value::Transform(m) => *m,
        other => panic!("to_world is {other:?}"),
    }
}

#[test]
fn transform_chains_compose_as_mitsuba_does() {
    let cases = data("transform-cases.json");
    let cases = cases["cases"].as_array().expect("cases");
    assert!(cases.len() >= 200);
    for case in cases {
        let chain = case["chain"].as_str().expect("chain");
        let text =
            scene(&format!("<shape type=\"rectangle\"><transform name=\"to_world\">{chain}</transform></shape>"));
        let result = read(&text);
        if let Some(error) = case.get("error") {
            let error_text = result.expect_err(chain).to_string();
            assert!(error_text.starts_with("scene.xml:2:"), "{error_text} (Mitsuba: {error})");
            continue;
        }
        let matrix = to_world(&result.unwrap_or_else(|e| panic!("{chain}: {e}")));
        let expected: Vec<f64> =
            case["matrix"].as_array().expect("matrix").iter().map(|v| v.as_f64().unwrap()).collect();
        // Mitsuba prints its single-precision matrix: agree to float precision relative to the entries' size.
        let size = expected.iter().fold(1.0f64, |m, v| m.max(v.abs()));
        for row in 0..4 {
            for col in 0..4 {
                let ours = matrix.col(col)[row];
                let theirs = expected[row * 4 + col];
                assert!((ours - theirs).abs() <= 4e-6 * size, "{chain}: [{row}][{col}] {ours} vs Mitsuba {theirs}");
            }
        }
    }
}

#[test]
fn spectra_convert_to_rgb_as_mitsuba_does() {
    let cases = data("spectrum-cases.json");
    for case in cases["cases"].as_array().expect("cases") {
        let value = case["value"].as_str().unwrap();
        // The places the script loads each spectrum in: a diffuse reflectance, a conductor's eta, an area light.
        let usage = match case["use"].as_str().unwrap() {
            "reflectance" => SpectrumUse::for_parameter("reflectance", false),
            "unbounded" => SpectrumUse::for_parameter("eta", false),
            "emission" => SpectrumUse::for_parameter("radiance", true),
            other => panic!("use {other}"),
        };
        let rgb = Spectrum::parse(value).unwrap().to_rgb(usage);
        for (k, expected) in case["rgb"].as_array().unwrap().iter().enumerate() {
            let expected = expected.as_f64().unwrap();
            // Mitsuba integrates in single precision and prints 7 digits.
            assert!(
                (rgb[k] - expected).abs() <= 2e-5 * expected.abs().max(1.0),
                "{value} as {usage:?}: {rgb:?} vs {expected}"
            );
        }
    }
}

/// (scene body, line of the error, text the element part must hold, text the message must hold).
const REFUSED: &[(&str, u32, &str, &str)] = &[
    ("<shape type=\"sphere\">\n<float name=\"radius\" value=\"1.5x\"/></shape>", 3, "<float name=\"radius\">", "not a number"),
    ("<shape type=\"sphere\"><float name=\"radius\" value=\"nan\"/></shape>", 2, "<float name=\"radius\">", "finite"),
    ("<shape type=\"sphere\"><integer name=\"n\" value=\"1.5\"/></shape>", 2, "<integer name=\"n\">", "not an integer"),
    ("<shape type=\"sphere\"><boolean name=\"flip_normals\" value=\"1\"/></shape>", 2, "<boolean", "true or false"),
    ("<shape type=\"sphere\"><rgb name=\"c\" value=\"0.3, 0.2\"/></shape>", 2, "<rgb name=\"c\">", "one or three"),
    ("<shape type=\"sphere\"><spectrum name=\"c\" value=\"700:0.2, 400:0.5\"/></shape>", 2, "<spectrum name=\"c\">", "must increase"),
    ("<shape type=\"sphere\"><spectrum name=\"c\" value=\"500:0.5\"/></shape>", 2, "<spectrum", "at least two"),
    ("<shape type=\"sphere\"><spectrum name=\"c\" value=\"400:0.5, 700\"/></shape>", 2, "<spectrum", "wavelength:value"),
    ("<shape type=\"sphere\"><point name=\"center\" x=\"1\"/></shape>", 2, "<point name=\"center\">", "`y` is missing"),
    ("<shape type=\"sphere\"><color name=\"c\" value=\"1\"/></shape>", 2, "<color name=\"c\">", "unknown element"),
    ("<bsdf id=\"b\"/>", 2, "<bsdf id=\"b\">", "`type` is missing"),
    ("<shape type=\"sphere\"><float name=\"radius\" value=\"$r\"/></shape>", 2, "<float name=\"radius\">", "`$r`"),
    ("<shape type=\"sphere\">\n\n<ref id=\"nowhere\"/></shape>", 4, "<ref id=\"nowhere\">", "no plugin has the id"),
    ("<bsdf type=\"diffuse\" id=\"b\"/>\n<bsdf type=\"diffuse\" id=\"b\"/>", 3, "<bsdf type=\"diffuse\" id=\"b\">", "already used at scene.xml:2:1"),
    ("<shape type=\"sphere\"><float name=\"radius\" value=\"1\"/><float name=\"radius\" value=\"2\"/></shape>", 2, "<float name=\"radius\">", "already"),
    ("<shape type=\"sphere\"><transform name=\"to_world\"><translate x=\"1\" foo=\"2\"/></transform></shape>", 2, "<translate>", "unexpected attribute `foo`"),
    ("<shape type=\"sphere\"><transform name=\"to_world\"><matrix value=\"1 2 3\"/></transform></shape>", 2, "<matrix>", "9 or 16"),
    ("<shape type=\"sphere\"><transform name=\"to_world\"><scale value=\"1\" x=\"2\"/></transform></shape>", 2, "<scale>", "not both"),
    ("<shape type=\"sphere\"><transform name=\"to_world\"><rotate x=\"1\"/></transform></shape>", 2, "<rotate>", "`angle` is missing"),
    ("<shape type=\"sphere\"><transform name=\"to_world\"><lookat origin=\"0,0,0\" target=\"0,0,1\" up=\"0,0,1\"/></transform></shape>", 2, "<lookat>", "parallel"),
    ("<shape type=\"sphere\"><transform name=\"to_world\"><float name=\"x\" value=\"1\"/></transform></shape>", 2, "<float name=\"x\">", "not a transform element"),
    ("<translate x=\"1\"/>", 2, "<translate>", "inside <transform"),
    ("<float name=\"x\" value=\"1\"/>", 2, "<float name=\"x\">", "belongs inside a plugin"),
    ("<ref id=\"b\"/>", 2, "<ref id=\"b\">", "belongs inside a plugin"),
    ("<integrator type=\"path\"/>\n<integrator type=\"direct\"/>", 3, "<integrator type=\"direct\">", "second integrator"),
    ("<bsdf type=\"twosided\" id=\"a\"><ref id=\"a\"/></bsdf>", 2, "<ref id=\"a\">", "cycle"),
    ("<shape type=\"sphere\"><bsdf type=\"diffuse\" foo=\"1\"/></shape>", 2, "<bsdf type=\"diffuse\">", "unexpected attribute"),
    ("<shape type=\"sphere\"><include filename=\"missing.xml\"/></shape>", 2, "<include filename=\"missing.xml\">", "does not exist"),
    ("<path value=\"no/such/folder\"/>", 2, "<path>", "does not exist"),
    ("<alias id=\"nothing\" as=\"b\"/>", 2, "<alias id=\"nothing\">", "which no plugin has"),
    ("<shape type=\"sphere\"><float name=\"radius\" value=\"1\"><float name=\"x\" value=\"1\"/></float></shape>", 2, "<float name=\"x\">", "holds no elements"),
    ("<shape type=\"sphere\"><spectrum name=\"eta\" filename=\"missing.spd\"/></shape>", 2, "<spectrum name=\"eta\" filename=\"missing.spd\">", "cannot read the spectrum file"),
];

#[test]
fn malformed_and_unsupported_inputs_are_refused_naming_element_and_line() {
    assert!(REFUSED.len() >= 20);
    for (body, line, element, message) in REFUSED {
        let error = read(&scene(body)).expect_err(body);
        let text = error.to_string();
        assert!(text.starts_with(&format!("scene.xml:{line}:")), "{body}: {text}");
        assert!(error.element.as_deref().is_some_and(|e| e.contains(element)), "{body}: {text}");
        assert!(error.message.contains(message), "{body}: {text}");
    }
}

#[test]
fn files_that_are_not_mitsuba_3_scenes_are_refused_with_their_position() {
    let cases: &[(&str, &str)] = &[
        ("<scene version=\"3.0.0\">\n<shape type=\"sphere\">\n</scene>", "scene.xml:3:"),
        ("<scene>\n</scene>", "`version` is missing"),
        ("<scene version=\"0.6.0\"/>", "version 0.6.0"),
        ("<scene version=\"4.0.0\"/>", "version 4.0.0"),
        ("<bsdf version=\"3.0.0\" type=\"diffuse\"/>", "root element"),
        ("<!DOCTYPE scene [<!ENTITY a \"b\">]><scene version=\"3.0.0\"/>", "not well-formed"),
        ("", "not well-formed"),
    ];
    for (text, expected) in cases {
        let error = read(text).expect_err(text).to_string();
        assert!(error.starts_with("scene.xml:") && error.contains(expected), "{text}: {error}");
    }
    assert_eq!(read("<scene version=\"2.1.0\"/>").expect("version 2").version, "2.1.0");
}

#[test]
fn deep_nesting_and_long_reference_chains_are_refused_not_overflowing_the_stack() {
    let deep = scene(&format!("{}{}", "<bsdf type=\"twosided\">".repeat(5000), "</bsdf>".repeat(5000)));
    let error = read(&deep).unwrap_err().to_string();
    assert!(error.starts_with("scene.xml:2:") && error.contains("nest deeper"), "{error}");
    // Each bsdf references the next: a chain through 20000 plugins.
    let chain: String =
        (0..20000).map(|i| format!("<bsdf type=\"twosided\" id=\"b{i}\"><ref id=\"b{}\"/></bsdf>\n", i + 1)).collect();
    let error = read(&scene(&format!("{chain}<bsdf type=\"diffuse\" id=\"b20000\"/>"))).unwrap_err().to_string();
    assert!(error.contains("deeper than"), "{error}");
    let short: String =
        (0..50).map(|i| format!("<bsdf type=\"twosided\" id=\"b{i}\"><ref id=\"b{}\"/></bsdf>", i + 1)).collect();
    assert!(read(&scene(&format!("{short}<bsdf type=\"diffuse\" id=\"b50\"/>"))).is_ok());
}

#[test]
fn defaults_are_substituted_everywhere_and_defines_override_them() {
    let text = scene(
        "<default name=\"spp\" value=\"16\"/>\n<default name=\"spp\" value=\"99\"/>\n<default name=\"kind\" value=\"diffuse\"/>\n\
         <sensor type=\"perspective\"><sampler type=\"independent\"><integer name=\"sample_count\" value=\"$spp\"/></sampler>\
         <string name=\"label\" value=\"$spp-$kind $\"/></sensor>\n<bsdf type=\"$kind\" id=\"b_$kind\"/>",
    );
    let document = read(&text).unwrap();
    let sensor = &document.sensors[0];
    let sampler = &sensor.children_of(Category::Sampler).next().unwrap().plugin;
    assert_eq!(sampler.param("sample_count").unwrap().value, Value::Integer(16));
    assert_eq!(sensor.param("label").unwrap().value, Value::String("16-diffuse $".into()));
    assert_eq!(document.bsdfs[0].kind, "diffuse");
    assert_eq!(document.bsdfs[0].id.as_deref(), Some("b_diffuse"));

    let defines = [("spp".to_string(), "4".to_string()), ("kind".to_string(), "conductor".to_string())];
    let document = read_str(&text, Path::new("scene.xml"), &defines).unwrap();
    let sampler = &document.sensors[0].children_of(Category::Sampler).next().unwrap().plugin;
    assert_eq!(sampler.param("sample_count").unwrap().value, Value::Integer(4));
    assert_eq!(document.bsdfs[0].kind, "conductor");

    let typo = [("sp".to_string(), "4".to_string())];
    let error = read_str(&text, Path::new("scene.xml"), &typo).unwrap_err().to_string();
    assert!(error.starts_with("scene.xml:1:1: ") && error.contains("`sp` is used nowhere"), "{error}");
}

#[test]
fn references_and_aliases_share_one_plugin_and_keep_their_names() {
    let text = scene(
        "<shape type=\"sphere\"><ref id=\"white\"/></shape>\n\
         <bsdf type=\"diffuse\" id=\"white\"><texture type=\"checkerboard\" name=\"reflectance\" id=\"checks\"/></bsdf>\n\
         <alias id=\"white\" as=\"paper\"/>\n\
         <shape type=\"cube\"><ref id=\"paper\"/></shape>\n\
         <bsdf type=\"diffuse\" id=\"other\"><ref name=\"reflectance\" id=\"checks\"/></bsdf>",
    );
    let document = read(&text).unwrap();
    let white = &document.shapes[0].children[0];
    assert_eq!(white.reference.as_deref(), Some("white"), "a forward reference resolves");
    assert!(Arc::ptr_eq(&white.plugin, &document.bsdfs[0]));
    assert!(Arc::ptr_eq(&document.shapes[1].children[0].plugin, &document.bsdfs[0]), "an alias names the same plugin");
    let named = &document.bsdfs[1].children[0];
    assert_eq!(named.name.as_deref(), Some("reflectance"));
    assert!(Arc::ptr_eq(&named.plugin, &document.bsdfs[0].children[0].plugin), "a nested plugin's id is referable");
    assert_eq!(white.position.line, 2);
}

#[test]
fn typed_values_and_nesting_are_kept_with_positions() {
    let text = scene(
        "<sensor type=\"perspective\">\n\
         <float name=\"fov\" value=\"45\"/><film type=\"hdrfilm\"><integer name=\"width\" value=\"64\"/></film>\n\
         <transform name=\"to_world\"><translate x=\"1\"/><scale value=\"2\"/></transform>\n\
         </sensor>\n\
         <shape type=\"obj\"><string name=\"filename\" value=\"a.obj\"/><boolean name=\"face_normals\" value=\"TRUE\"/>\
         <emitter type=\"area\"><rgb name=\"radiance\" value=\"1 2, 3\"/></emitter>\
         <point name=\"p\" value=\"1, 2, 3\"/><vector name=\"v\" x=\"0\" y=\"1\" z=\"0\"/>\
         <spectrum name=\"s\" value=\"0.5\"/><spectrum type=\"blackbody\" name=\"t\"><float name=\"temperature\" value=\"3000\"/></spectrum></shape>\n\
         <emitter type=\"constant\"/><texture type=\"bitmap\" id=\"t\"/><medium type=\"homogeneous\" id=\"fog\"/>",
    );
    let document = read(&text).unwrap();
    let sensor = &document.sensors[0];
    assert_eq!(sensor.param("fov").unwrap().value, Value::Float(45.0));
    assert_eq!(sensor.param("fov").unwrap().position.line, 3);
    let film = &sensor.children_of(Category::Film).next().unwrap().plugin;
    assert_eq!(film.param("width").unwrap().value, Value::Integer(64));
    let Value::Transform(m) = sensor.param("to_world").unwrap().value else { panic!() };
    assert_eq!(m.transform_point3(DVec3::ONE), DVec3::new(4.0, 2.0, 2.0), "the scale applies after the translation");
    let shape = &document.shapes[0];
    assert_eq!(shape.param("face_normals").unwrap().value, Value::Boolean(true));
    assert_eq!(shape.param("p").unwrap().value, Value::Point(DVec3::new(1.0, 2.0, 3.0)));
    assert_eq!(shape.param("v").unwrap().value, Value::Vector(DVec3::Y));
    assert_eq!(shape.param("s").unwrap().value, Value::Spectrum(Spectrum::Uniform(0.5)));
    let emitter = &shape.children_of(Category::Emitter).next().unwrap().plugin;
    assert_eq!(emitter.param("radiance").unwrap().value, Value::Rgb([1.0, 2.0, 3.0]));
    let blackbody = shape.children_of(Category::Spectrum).next().unwrap();
    assert_eq!((blackbody.name.as_deref(), blackbody.plugin.kind.as_str()), (Some("t"), "blackbody"));
    assert_eq!(document.emitters.len(), 1);
    assert_eq!(document.textures.len(), 1);
    assert_eq!(document.others[0].element(), "<medium type=\"homogeneous\">");
    assert_eq!(document.others[0].position.line, 7);
}

#[test]
fn includes_read_relative_to_the_including_file_and_cycles_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("parts/meshes")).unwrap();
    std::fs::create_dir_all(dir.path().join("common/meshes")).unwrap();
    std::fs::write(dir.path().join("common/meshes/m.serialized"), b"").unwrap();
    std::fs::write(dir.path().join("common/gold.eta.spd"), "# eta\n400 0.5\n\n700 0.25\n").unwrap();
    std::fs::write(
        dir.path().join("main.xml"),
        scene(
            "<path value=\"common\"/>\n<include filename=\"parts/bsdfs.xml\"/>\n<shape type=\"sphere\"><ref id=\"red\"/></shape>\n\
             <bsdf type=\"conductor\"><spectrum name=\"eta\" filename=\"gold.eta.spd\"/></bsdf>",
        ),
    )
    .unwrap();
    std::fs::write(
        dir.path().join("parts/bsdfs.xml"),
        scene("<include filename=\"more.xml\"/>\n<bsdf type=\"diffuse\" id=\"red\"/>"),
    )
    .unwrap();
    std::fs::write(
        dir.path().join("parts/more.xml"),
        scene("<bsdf type=\"conductor\" id=\"gold\">\n<float name=\"x\" value=\"1\"/></bsdf>"),
    )
    .unwrap();
    let document = read_file(&dir.path().join("main.xml"), &[]).unwrap();
    assert_eq!(document.bsdfs.len(), 3);
    let eta = Spectrum::Sampled { wavelengths: vec![400.0, 700.0], values: vec![0.5, 0.25] };
    assert_eq!(document.bsdfs[2].param("eta").unwrap().value, Value::Spectrum(eta), "a .spd file in a <path> folder");
    assert_eq!(document.bsdfs[0].kind, "conductor");
    assert!(document.bsdfs[0].position.file.ends_with("parts/more.xml"));
    assert_eq!(document.bsdfs[0].param("x").unwrap().position.line, 3);
    assert!(Arc::ptr_eq(&document.shapes[0].children[0].plugin, &document.bsdfs[1]));
    assert_eq!(document.resolve_file("meshes/m.serialized"), dir.path().join("common/meshes/m.serialized"));
    assert_eq!(document.resolve_file("x.obj"), dir.path().join("x.obj"));

    std::fs::write(dir.path().join("parts/more.xml"), scene("<include filename=\"bsdfs.xml\"/>")).unwrap();
    let error = read_file(&dir.path().join("main.xml"), &[]).unwrap_err().to_string();
    assert!(
        error.contains("more.xml:2:1: <include filename=\"bsdfs.xml\">") && error.contains("include cycle"),
        "{error}"
    );

    std::fs::write(dir.path().join("parts/more.xml"), scene("<bsdf type=\"x\">")).unwrap();
    let error = read_file(&dir.path().join("main.xml"), &[]).unwrap_err().to_string();
    assert!(error.contains("more.xml:3:") && error.contains("not well-formed"), "{error}");
}

fn mesh(normals: bool, uvs: bool, name: &str, shift: f32) -> SerializedMesh {
    let positions = vec![[0.0, 0.0, shift], [1.0, 0.0, 0.1], [0.0, 1.0, 0.3], [1.0, 1.0, 1.0 / 3.0]];
    SerializedMesh {
        name: name.to_string(),
        normals: normals.then(|| vec![[0.0, 0.0, 1.0], [0.0, 0.6, 0.8], [0.6, 0.0, 0.8], [0.0, 0.0, -1.0]]),
        uvs: uvs.then(|| vec![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [0.25, 0.75]]),
        positions,
        triangles: vec![[0, 1, 2], [2, 1, 3]],
        face_normals: !normals,
    }
}

#[test]
fn serialized_meshes_round_trip_in_both_precisions_with_and_without_normals_and_uvs() {
    for double in [false, true] {
        for normals in [false, true] {
            for uvs in [false, true] {
                let meshes =
                    [mesh(normals, uvs, "first", 0.0), mesh(!normals, uvs, "", 2.0), mesh(normals, !uvs, "third", 7.5)];
                let bytes = write_serialized(&meshes, double).unwrap();
                assert_eq!(mesh_count(&bytes).unwrap(), 3);
                for (index, expected) in meshes.iter().enumerate() {
                    assert_eq!(
                        &read_serialized(&bytes, index as u32).unwrap(),
                        expected,
                        "double {double} mesh {index}"
                    );
                }
                let error = read_serialized(&bytes, 3).unwrap_err().to_string();
                assert!(error.contains("out of range") && error.contains("3 meshes"), "{error}");
            }
        }
    }
}

/// A mesh of a hand-made version 3 file: flags, positions, triangles.
type Version3Mesh = (u32, Vec<[f32; 3]>, Vec<[u32; 3]>);

/// A version 3 file (no mesh names, 32-bit dictionary offsets), as older Mitsuba versions wrote, by hand.
fn version_3_file(meshes: &[Version3Mesh]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut offsets = Vec::new();
    for (flags, positions, triangles) in meshes {
        offsets.push(out.len() as u32);
        out.extend_from_slice(&[0x1C, 0x04, 3, 0]);
        let mut body = flags.to_le_bytes().to_vec();
        body.extend_from_slice(&(positions.len() as u64).to_le_bytes());
        body.extend_from_slice(&(triangles.len() as u64).to_le_bytes());
        body.extend(positions.iter().flatten().flat_map(|v| v.to_le_bytes()));
        body.extend(triangles.iter().flatten().flat_map(|i| i.to_le_bytes()));
        let mut encoder = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        std::io::Write::write_all(&mut encoder, &body).unwrap();
        out.extend(encoder.finish().unwrap());
    }
    out.extend(offsets.iter().flat_map(|o| o.to_le_bytes()));
    out.extend_from_slice(&(meshes.len() as u32).to_le_bytes());
    out
}

#[test]
fn version_3_serialized_files_are_read_by_shape_index() {
    let first = (0x1000, vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], vec![[0, 1, 2]]);
    let second =
        (0x1010, vec![[5.0, 0.0, 0.0], [6.0, 0.0, 0.0], [5.0, 1.0, 0.0], [6.0, 1.0, 2.0]], vec![[0, 1, 2], [1, 3, 2]]);
    let bytes = version_3_file(&[first.clone(), second.clone()]);
    assert_eq!(mesh_count(&bytes).unwrap(), 2);
    for (index, (flags, positions, triangles)) in [first, second].into_iter().enumerate() {
        let mesh = read_serialized(&bytes, index as u32).unwrap();
        assert_eq!((mesh.name.as_str(), &mesh.positions, &mesh.triangles), ("", &positions, &triangles));
        assert_eq!((mesh.normals, mesh.uvs, mesh.face_normals), (None, None, flags & 0x10 != 0));
    }
}

#[test]
fn truncated_and_damaged_serialized_files_are_refused_without_panic() {
    let bytes = write_serialized(&[mesh(true, true, "a", 0.0), mesh(false, true, "b", 1.0)], false).unwrap();
    for len in 0..bytes.len() {
        for index in [0, 1] {
            // A prefix may still hold mesh 0 whole; it must then read as written, never as something else.
            if let Ok(read) = read_serialized(&bytes[..len], index) {
                assert_eq!(read, mesh(true, true, "a", 0.0), "prefix of {len} bytes, mesh {index}");
            }
        }
    }
    // Any changed byte of the first mesh is caught (by the zlib checksum if nothing else); elsewhere, reading
    // must not panic.
    let first_len = write_serialized(&[mesh(true, true, "a", 0.0)], false).unwrap().len() - 12;
    for at in 0..bytes.len() {
        let mut damaged = bytes.clone();
        damaged[at] ^= 0x5A;
        let first = read_serialized(&damaged, 0);
        assert!(at >= first_len || first.is_err(), "a change at byte {at} went unnoticed");
        let _ = read_serialized(&damaged, 1);
    }
    // A body that claims a huge mesh is refused before anything is allocated.
    let mut body = Vec::new();
    body.extend_from_slice(&0x1000u32.to_le_bytes());
    body.push(0);
    body.extend_from_slice(&(u32::MAX as u64).to_le_bytes());
    body.extend_from_slice(&(1u64 << 40).to_le_bytes());
    let mut encoder = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
    std::io::Write::write_all(&mut encoder, &body).unwrap();
    let mut hostile = vec![0x1C, 0x04, 4, 0];
    hostile.extend(encoder.finish().unwrap());
    let error = read_serialized(&hostile, 0).unwrap_err().to_string();
    assert!(error.contains("truncated or damaged"), "{error}");
    let error = read_serialized(&[0x1C, 0x04, 5, 0, 0, 0], 0).unwrap_err().to_string();
    assert!(error.contains("version 5"), "{error}");
    let error = read_serialized(b"PLY\n", 0).unwrap_err().to_string();
    assert!(error.contains("not a serialized mesh"), "{error}");
}
