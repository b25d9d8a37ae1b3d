//! Ray maps: recorded paths read back exactly, recording leaves the image bit-identical, selection agrees with
//! a brute-force filter and with an analytic scene, and damaged maps give clear errors without losing whole
//! portions.

use crate::common::{scene, settings};
use photonfarm::ray_map::format::{decode_paths, encode_path, path_views, MapHeader, VERSION};
use photonfarm::ray_map::reader::{read_all, StreamReader};
use photonfarm::ray_map::select::{parse, Expr};
use photonfarm::ray_map::writer::stream_file;
use photonfarm::ray_map::{header_for, Events, PathKind, RayMapError, RecordedPath, Recorder, Vertex};
use photonfarm::render::{Engine, Method};
use photonfarm::scene::Scene;
use proptest::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// A folder for one test's ray maps and its path: the folder is removed when the first goes out of scope, so
/// bind it to a name (`_scratch`), not to `_`.
fn scratch(name: &str) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::Builder::new().prefix(&format!("photonfarm-raymap-{name}-")).tempdir().unwrap();
    let path = dir.path().to_path_buf();
    (dir, path)
}

/// A point light at (0, 1, 0) under a small ceiling mirror at y = 2, with a black shade just below the light
/// so that no light reaches the floor's middle directly: the floor within 1.4 of the axis is lit only by way
/// of the mirror (the light's direct shadow reaches 3 from the axis, the mirror's image 1.5).
const MIRROR_SCENE: &str = "[camera]\nposition = [0.0, 6.0, -0.01]\nlook_at = [0.0, 0.0, 0.0]\nup = [0.0, 0.0, 1.0]\n\
    fov_y_deg = 50\nwidth = 24\nheight = 24\n\
    [materials.floor]\ntype = \"diffuse\"\nalbedo = [0.5, 0.5, 0.5]\n\
    [materials.black]\ntype = \"diffuse\"\nalbedo = [0.0, 0.0, 0.0]\n\
    [materials.mirror]\ntype = \"mirror\"\nreflectance = [0.9, 0.9, 0.9]\n\
    [[objects]]\nname = \"floor\"\nmaterial = \"floor\"\nquad = { corner = [-6.0, 0.0, -6.0], edge1 = [0.0, 0.0, 12.0], edge2 = [12.0, 0.0, 0.0] }\n\
    [[objects]]\nname = \"mirror\"\nmaterial = \"mirror\"\nquad = { corner = [-0.5, 2.0, -0.5], edge1 = [1.0, 0.0, 0.0], edge2 = [0.0, 0.0, 1.0] }\n\
    [[objects]]\nname = \"shade\"\nmaterial = \"black\"\nquad = { corner = [-0.3, 0.9, -0.3], edge1 = [0.6, 0.0, 0.0], edge2 = [0.0, 0.0, 0.6] }\n\
    [[lights]]\ntype = \"point\"\nposition = [0.0, 1.0, 0.0]\nintensity = [1.0, 1.0, 1.0]\n";

/// Runs `phases` phases of `method`, recording `fraction` of the paths into `dir` when given one.
fn render<'s>(sc: &'s Scene, method: Method, phases: usize, record: Option<(&Path, f64)>) -> Engine<'s> {
    let mut engine = Engine::new(sc, settings(sc, method, 7));
    let recorder =
        record.map(|(dir, f)| Arc::new(Recorder::create(dir, &header_for(sc, method.name(), 7, f, 0)).unwrap()));
    engine.set_recorder(recorder.clone());
    for _ in 0..phases {
        engine.run_phase();
    }
    if let Some(r) = recorder {
        let stats = r.finish().unwrap();
        assert!(stats.paths > 0 && stats.segments > 0, "{stats:?}");
    }
    engine
}

fn sum_bits(e: &Engine) -> Vec<u64> {
    e.sums().pixels.iter().flat_map(|p| p.sum.iter().flatten().chain(p.sum_sq.iter()).map(|v| v.to_bits())).collect()
}

#[test]
fn recording_every_path_leaves_a_one_thread_runs_sums_bit_identical() {
    let sc = scene(MIRROR_SCENE);
    for method in [Method::Pbpm, Method::Path] {
        let (_scratch, dir) = scratch(&format!("identical-{}", method.name()));
        let (plain, recorded) = std::thread::scope(|s| {
            let a = s.spawn(|| sum_bits(&render(&sc, method, 3, None)));
            let b = s.spawn(|| sum_bits(&render(&sc, method, 3, Some((&dir, 1.0)))));
            (a.join().unwrap(), b.join().unwrap())
        });
        assert!(plain == recorded, "{method:?}: recording changed the sums");
    }
}

/// The shipped lens at 36 × 24 pixels (the sensor keeps its size): light paths register ghost chains on its
/// sensor.
fn small_lens() -> Scene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/lens.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("width = 360\n") && text.contains("height = 240\n"));
    let text = text.replace("width = 360\n", "width = 36\n").replace("height = 240\n", "height = 24\n");
    Scene::from_toml(&text, &path, path.parent().unwrap()).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn light_paths_reaching_the_lens_sensor_are_recorded_with_their_pixel_and_leave_the_sums_bit_identical() {
    let sc = small_lens();
    for method in [Method::Pbpm, Method::Path] {
        let (_scratch, dir) = scratch(&format!("lens-{}", method.name()));
        let (plain, recorded) = std::thread::scope(|s| {
            let a = s.spawn(|| sum_bits(&render(&sc, method, 2, None)));
            let b = s.spawn(|| sum_bits(&render(&sc, method, 2, Some((&dir, 1.0)))));
            (a.join().unwrap(), b.join().unwrap())
        });
        assert!(plain == recorded, "{method:?}: recording changed the sums");
        let (_, paths, _) = read_all(&dir).unwrap();
        let on_sensor: Vec<&Vertex> = paths
            .iter()
            .filter(|p| p.kind == PathKind::Light)
            .flat_map(|p| p.vertices.iter().skip(1).filter(|v| v.events.contains(Events::SENSOR)))
            .collect();
        assert!(!on_sensor.is_empty(), "{method:?}: no recorded light path reached the sensor");
        assert!(on_sensor.iter().all(|v| v.primitive < 36 * 24), "{method:?}: a sensor vertex names no pixel");
    }
}

#[test]
fn a_fraction_records_about_that_share_of_the_paths_and_the_same_ones_every_run() {
    let sc = scene(MIRROR_SCENE);
    let ((_scratch_a, a), (_scratch_b, b)) = (scratch("fraction-a"), scratch("fraction-b"));
    render(&sc, Method::Pbpm, 4, Some((&a, 0.25)));
    render(&sc, Method::Pbpm, 4, Some((&b, 0.25)));
    let (_, pa, _) = read_all(&a).unwrap();
    let (_, pb, _) = read_all(&b).unwrap();
    assert_eq!(pa, pb, "the same seed recorded other paths");
    let camera = pa.iter().filter(|p| p.kind == PathKind::Camera).count() as f64;
    let expected = 0.25 * 4.0 * 24.0 * 24.0;
    // Binomial: 4 standard deviations of 2304 draws at p = 0.25 is about 83.
    assert!((camera - expected).abs() < 90.0, "{camera} camera paths recorded, {expected} expected");
}

/// Every light path whose first floor vertex lies in the mirrored spot reflected at the mirror, and the
/// selection "reflect(mirror)" finds exactly the light paths with a mirror reflection.
#[test]
fn in_the_mirror_scene_every_path_reaching_the_mirrored_spot_is_selected_by_a_reflection_at_the_mirror() {
    let sc = scene(MIRROR_SCENE);
    let (_scratch, dir) = scratch("mirror");
    render(&sc, Method::Pbpm, 6, Some((&dir, 1.0)));
    let (header, paths, cut) = read_all(&dir).unwrap();
    assert_eq!(cut, 0);
    let floor = header.objects.iter().position(|n| n == "floor").unwrap() as u16;
    let mirror = header.objects.iter().position(|n| n == "mirror").unwrap() as u16;
    let selected = parse("lightpath and reflect(mirror)", &header).unwrap();
    let not_selected = parse("lightpath and not reflect(mirror)", &header).unwrap();
    let in_spot = |v: &Vertex| v.object == floor && v.point[0].abs() < 1.4 && v.point[2].abs() < 1.4;
    let mut reaching = 0;
    for p in paths.iter().filter(|p| p.kind == PathKind::Light) {
        let brute = p.vertices.iter().any(|v| v.object == mirror && v.events.contains(Events::REFLECT));
        assert_eq!(selected.matches(p, header.width), brute);
        assert_ne!(selected.matches(p, header.width), not_selected.matches(p, header.width));
        if p.vertices.iter().any(in_spot) {
            reaching += 1;
            assert!(selected.matches(p, header.width), "a path reached the spot without the mirror: {p:?}");
        }
        assert_eq!(header.emitters[p.source as usize], "lights[0]");
    }
    assert!(reaching > 100, "only {reaching} light paths reached the mirrored spot");
}

/// A small map of fabricated paths over objects 0..4 and emitters 0..2, for the format tests: built as the
/// integrators build them (`begin`, then vertices), so that every field survives the map.
fn fabricated(n: usize) -> Vec<RecordedPath> {
    (0..n)
        .map(|i| {
            let kind = if i % 3 == 0 { PathKind::Light } else { PathKind::Camera };
            let source = if kind == PathKind::Light { (i % 2) as u32 } else { (i % 64) as u32 };
            let item = if kind == PathKind::Light { i as u32 } else { source };
            let mut p = RecordedPath::new(kind, (i / 7) as u32 + 1, item, source);
            p.begin(glam::Vec3::new(i as f32 * 0.1, 0.5, -1.0), glam::Vec3::new(0.0, 1.0, 0.0));
            for k in 1..1 + i % 6 {
                p.vertices.push(Vertex {
                    point: [i as f32 * 0.1, k as f32, -(k as f32) * 0.5],
                    normal: (i * 31 + k) as u32,
                    object: ((i + k) % 4) as u16,
                    primitive: (i * k) as u32,
                    events: Events(((i * 7 + k * 13) % 256) as u8),
                });
            }
            let wavelength = if i % 5 == 0 { Some(400.0 + i as f32) } else { None };
            p.finish(glam::Vec3::new(i as f32, 0.5, 1e-3), wavelength);
            p
        })
        .collect()
}

fn test_header(stream: u32) -> MapHeader {
    MapHeader {
        scene: "test.toml".into(),
        scene_hash: "0".into(),
        width: 8,
        height: 8,
        objects: ["lens", "mirror", "wall", "floor"].map(String::from).to_vec(),
        emitters: ["lamp", "lights[0]"].map(String::from).to_vec(),
        method: "pbpm".into(),
        seed: 1,
        fraction: 1.0,
        stream,
    }
}

fn write_map(dir: &Path, paths: &[RecordedPath]) -> PathBuf {
    let r = Recorder::create(dir, &test_header(0)).unwrap();
    for p in paths {
        r.record(p);
    }
    r.finish().unwrap();
    stream_file(dir, 0)
}

#[test]
fn recorded_paths_read_back_exactly_across_many_portions() {
    let (_scratch, dir) = scratch("round-trip");
    // Enough paths for several 1 MiB portions.
    let paths = fabricated(40_000);
    let file = write_map(&dir, &paths);
    let mut reader = StreamReader::open(&file).unwrap();
    let mut portions = 0;
    while reader.next_portion().unwrap().is_some() {
        portions += 1;
    }
    assert!(portions >= 2, "{portions} portions");
    let (header, back, cut) = read_all(&dir).unwrap();
    assert_eq!((header, cut), (test_header(0), 0));
    assert!(back == paths, "paths changed on the way through the map");
}

#[test]
fn a_truncated_map_reads_every_whole_portion_and_says_what_it_left() {
    let (_scratch, dir) = scratch("truncated");
    let paths = fabricated(40_000);
    let file = write_map(&dir, &paths);
    let bytes = std::fs::read(&file).unwrap();
    // Cut inside the last portion.
    std::fs::write(&file, &bytes[..bytes.len() - 100]).unwrap();
    let (_, back, cut) = read_all(&dir).unwrap();
    assert!(cut > 0 && !back.is_empty() && back.len() < paths.len(), "{cut} bytes cut, {} paths", back.len());
    assert!(back[..] == paths[..back.len()], "a whole portion changed");
}

#[test]
fn a_corrupt_portion_is_an_error_naming_its_byte_after_the_whole_portions_before_it() {
    let (_scratch, dir) = scratch("corrupt");
    let paths = fabricated(40_000);
    let file = write_map(&dir, &paths);
    let mut bytes = std::fs::read(&file).unwrap();
    let n = bytes.len();
    bytes[n - 50] ^= 0x5a;
    std::fs::write(&file, &bytes).unwrap();
    let mut reader = StreamReader::open(&file).unwrap();
    let mut whole = 0;
    let error = loop {
        match reader.next_portion().unwrap().map(|p| p.decode()) {
            Some(Ok(p)) => whole += p.len(),
            Some(Err(e)) => break e,
            None => panic!("the damage went unnoticed"),
        }
    };
    assert!(matches!(error, RayMapError::Corrupt { .. }), "{error}");
    assert!(error.to_string().contains("at byte"), "{error}");
    assert!(whole > 0);
}

/// Every portion of the stream at `path` decoded, and the bytes it cut; whether it was mapped. A pipe is opened
/// while `feed` writes `bytes` into it.
fn read_stream(path: &Path, feed: Option<Vec<u8>>) -> (bool, Vec<RecordedPath>, Option<u64>) {
    let writer = feed.map(|bytes| {
        let path = path.to_path_buf();
        std::thread::spawn(move || std::fs::write(path, bytes).unwrap())
    });
    let mut reader = StreamReader::open(path).unwrap();
    let (mut paths, mut buffer) = (Vec::new(), Vec::new());
    while let Some(p) = reader.next_portion_into(&mut buffer).unwrap() {
        paths.extend(p.decode().unwrap());
        if let Some(b) = p.into_buffer() {
            buffer = b;
        }
    }
    if let Some(w) = writer {
        w.join().unwrap();
    }
    (reader.is_mapped(), paths, reader.truncated_bytes())
}

#[test]
fn a_stream_that_cannot_be_mapped_is_read_from_a_pipe_with_the_same_paths_and_cut_as_the_mapped_file() {
    let (_scratch, dir) = scratch("pipe");
    let paths = fabricated(40_000);
    let file = write_map(&dir, &paths);
    let bytes = std::fs::read(&file).unwrap();
    for cut in [0, 100, bytes.len() - 100_000] {
        let cut_file = dir.join(format!("cut-{cut}.pfrm"));
        std::fs::write(&cut_file, &bytes[..bytes.len() - cut]).unwrap();
        let (mapped, from_file, file_cut) = read_stream(&cut_file, None);
        assert!(mapped, "a regular file was not mapped");
        assert_eq!(from_file[..], paths[..from_file.len()], "a whole portion changed");
        assert_eq!((file_cut.is_some(), from_file.len() == paths.len()), (cut > 0, cut == 0), "cut {cut}");
        let pipe = dir.join(format!("pipe-{cut}"));
        let made = std::process::Command::new("mkfifo").arg(&pipe).status().unwrap();
        assert!(made.success());
        let (mapped, from_pipe, pipe_cut) = read_stream(&pipe, Some(bytes[..bytes.len() - cut].to_vec()));
        assert!(!mapped, "a pipe was mapped");
        assert!(from_pipe == from_file && pipe_cut == file_cut, "cut {cut}: {pipe_cut:?} against {file_cut:?}");
    }
    // A pipe is a stream in its own right, as a file is.
    let pipe = dir.join("pipe-all");
    assert!(std::process::Command::new("mkfifo").arg(&pipe).status().unwrap().success());
    let writer = std::thread::spawn(move || std::fs::write(dir.join("pipe-all"), bytes).unwrap());
    let (header, back, cut) = read_all(&pipe).unwrap();
    writer.join().unwrap();
    assert!(header == test_header(0) && back == paths && cut == 0);
}

#[test]
fn another_format_version_or_a_foreign_file_is_refused_with_a_clear_error() {
    let (_scratch, dir) = scratch("version");
    let file = write_map(&dir, &fabricated(10));
    let mut bytes = std::fs::read(&file).unwrap();
    bytes[8..12].copy_from_slice(&(VERSION + 1).to_le_bytes());
    std::fs::write(&file, &bytes).unwrap();
    let e = StreamReader::open(&file).err().unwrap();
    assert!(e.to_string().contains(&format!("version {}", VERSION + 1)), "{e}");
    std::fs::write(&file, b"not a ray map at all, just text").unwrap();
    assert!(matches!(StreamReader::open(&file), Err(RayMapError::NotAMap(_))));
}

#[test]
fn bad_expressions_point_at_the_offending_token() {
    let h = test_header(0);
    for (expr, token, words) in [
        ("reflect(lense) >= 2", "lense", "no object is called 'lense'"),
        ("light(sun)", "sun", "no emitter"),
        ("hits(lens) and or hits(wall)", "or", "expected an event"),
        ("reflect(lens) >= two", "two", "expected a number"),
        ("(hits(lens)", "", "expected `)`"),
        ("hits(wall) hits(lens)", "hits", "expected `and`, `or`"),
        ("refract(lens) >= 1.5", "1.5", "whole number"),
    ] {
        let e = parse(expr, &h).unwrap_err();
        assert!(e.message.contains(words), "{expr}: {e}");
        assert_eq!(&expr[e.start..e.end.min(expr.len())], token, "{expr}: {e}");
    }
}

/// A random expression with its text, built from the same atoms the brute-force filter knows.
#[derive(Clone, Debug)]
enum Tree {
    Hits(usize),
    Count(&'static str, Option<usize>, &'static str, u32),
    Light(usize),
    Pixel(u32, u32, u32, u32),
    Camera,
    Escaped,
    Sensor,
    Not(Box<Tree>),
    And(Box<Tree>, Box<Tree>),
    Or(Box<Tree>, Box<Tree>),
}

const OBJECTS: [&str; 4] = ["lens", "mirror", "wall", "floor"];
const EVENTS: [(&str, Events); 5] = [
    ("reflect", Events::REFLECT),
    ("refract", Events::REFRACT),
    ("diffuse", Events::DIFFUSE),
    ("absorb", Events::ABSORB),
    ("tir", Events::TIR),
];
const CMPS: [&str; 5] = [">=", "<=", "=", ">", "<"];

fn tree() -> impl Strategy<Value = Tree> {
    let leaf = prop_oneof![
        (0..4usize).prop_map(Tree::Hits),
        (0..5usize, proptest::option::of(0..4usize), 0..5usize, 0..4u32).prop_map(|(e, o, c, n)| Tree::Count(
            EVENTS[e].0,
            o,
            CMPS[c],
            n
        )),
        (0..2usize).prop_map(Tree::Light),
        (0..8u32, 0..8u32, 0..9u32, 0..9u32).prop_map(|(a, b, c, d)| Tree::Pixel(a, b, c, d)),
        Just(Tree::Camera),
        Just(Tree::Escaped),
        Just(Tree::Sensor),
    ];
    leaf.prop_recursive(4, 24, 2, |inner| {
        prop_oneof![
            inner.clone().prop_map(|t| Tree::Not(Box::new(t))),
            (inner.clone(), inner.clone()).prop_map(|(a, b)| Tree::And(Box::new(a), Box::new(b))),
            (inner.clone(), inner).prop_map(|(a, b)| Tree::Or(Box::new(a), Box::new(b))),
        ]
    })
}

fn text(t: &Tree) -> String {
    match t {
        Tree::Hits(o) => format!("hits({})", OBJECTS[*o]),
        Tree::Count(e, o, c, n) => format!("{e}({}) {c} {n}", o.map_or("*", |o| OBJECTS[o])),
        Tree::Light(l) => format!("light(\"{}\")", ["lamp", "lights[0]"][*l]),
        Tree::Pixel(a, b, c, d) => format!("pixel({a}, {b}, {c}, {d})"),
        Tree::Camera => "camera".into(),
        Tree::Escaped => "escaped".into(),
        Tree::Sensor => "sensor".into(),
        Tree::Not(a) => format!("not ({})", text(a)),
        Tree::And(a, b) => format!("({}) and ({})", text(a), text(b)),
        Tree::Or(a, b) => format!("({}) OR ({})", text(a), text(b)),
    }
}

/// The expression's meaning, computed the slow, obvious way.
fn brute(t: &Tree, p: &RecordedPath) -> bool {
    match t {
        Tree::Hits(o) => p.vertices.iter().any(|v| v.object as usize == *o),
        Tree::Count(e, o, c, n) => {
            let bit = EVENTS.iter().find(|(name, _)| name == e).unwrap().1;
            let k = p
                .vertices
                .iter()
                .filter(|v| o.is_none_or(|o| v.object as usize == o) && v.events.0 & bit.0 != 0)
                .count() as u32;
            match *c {
                ">=" => k >= *n,
                "<=" => k <= *n,
                "=" => k == *n,
                ">" => k > *n,
                _ => k < *n,
            }
        }
        Tree::Light(l) => match p.kind {
            PathKind::Light => p.source as usize == *l,
            PathKind::Camera => {
                p.vertices.iter().any(|v| v.object as usize == *l && v.events.0 & Events::EMISSION.0 != 0)
            }
        },
        Tree::Pixel(a, b, c, d) => {
            let (x, y) = ((p.source % 8) as f32 + 0.5, (p.source / 8) as f32 + 0.5);
            p.kind == PathKind::Camera && x >= *a as f32 && x < *c as f32 && y >= *b as f32 && y < *d as f32
        }
        Tree::Camera => p.kind == PathKind::Camera,
        Tree::Escaped => p.vertices.last().is_some_and(|v| v.events.0 & Events::ESCAPED.0 != 0),
        Tree::Sensor => p.kind == PathKind::Light && p.vertices[1..].iter().any(|v| v.events.0 & Events::SENSOR.0 != 0),
        Tree::Not(a) => !brute(a, p),
        Tree::And(a, b) => brute(a, p) && brute(b, p),
        Tree::Or(a, b) => brute(a, p) || brute(b, p),
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]
    #[test]
    fn selection_agrees_with_a_brute_force_filter_over_random_expressions(t in tree()) {
        let paths = fabricated(300);
        let h = test_header(0);
        let e: Expr = parse(&text(&t), &h).map_err(|e| TestCaseError::fail(e.to_string()))?;
        for p in &paths {
            prop_assert_eq!(e.matches(p, h.width), brute(&t, p), "{} on {:?}", text(&t), p);
        }
        // The same paths read in place from their bytes, as a selection tests them.
        let mut raw = Vec::new();
        for p in &paths {
            encode_path(p, &mut raw);
        }
        let views: Vec<_> = path_views(&raw, paths.len()).collect::<Result<_, _>>().map_err(TestCaseError::fail)?;
        prop_assert_eq!(views.len(), paths.len());
        for (v, p) in views.iter().zip(&paths) {
            prop_assert_eq!(e.matches(v, h.width), brute(&t, p), "{} on {:?} read in place", text(&t), p);
        }
    }
}

#[test]
fn paths_read_in_place_decode_to_the_recorded_paths_and_a_cut_or_padded_portion_is_an_error() {
    let paths = fabricated(500);
    let mut raw = Vec::new();
    for p in &paths {
        encode_path(p, &mut raw);
    }
    for (v, p) in path_views(&raw, paths.len()).zip(&paths) {
        let v = v.unwrap();
        assert_eq!(v.segments(), p.segments());
        assert!(v.to_path() == *p, "{p:?} changed");
    }
    assert!(decode_paths(&raw, paths.len()).unwrap() == paths);
    let cut = decode_paths(&raw[..raw.len() - 3], paths.len()).unwrap_err();
    assert!(cut.contains("ends"), "{cut}");
    let mut padded = raw.clone();
    padded.push(0);
    let padded = decode_paths(&padded, paths.len()).unwrap_err();
    assert!(padded.contains("1 bytes follow"), "{padded}");
    // The error is the iteration's last item.
    let items: Vec<_> = path_views(&raw[..raw.len() - 3], paths.len()).collect();
    assert!(items.len() == paths.len() && items.last().unwrap().is_err());
}
