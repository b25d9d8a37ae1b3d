//! Texture files of every format decode to the right linear values (sRGB or raw), with row 0 at the top; broken
//! and hostile files are refused with a message, never a panic; scenes read them by their first bytes; and
//! anisotropic materials orient their shading frame by the surface's ∂p/∂u as Mitsuba 3 does.

use exr::prelude::{AnyChannel, AnyChannels, FlatSamples, Image, Layer, LayerAttributes, WritableImage};
use glam::{Vec2, Vec3};
use image::ImageEncoder;
use photonfarm::bsdf::microfacet::Distribution;
use photonfarm::bsdf::Transport;
use photonfarm::color::Rgb;
use photonfarm::geometry::Ray;
use photonfarm::material::{Material, Roughness, Surface};
use photonfarm::scene::Scene;
use photonfarm::texture::{Bitmap, Encoding, ImageFormat, Texture, TextureError};
use std::collections::BTreeMap;
use std::path::Path;

/// The sRGB decoding curve written out independently of the renderer's.
fn srgb(c: f64) -> f32 {
    (if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }) as f32
}

fn close(a: Rgb, b: Rgb, tolerance: f32) -> bool {
    (a - b).abs().max_element() <= tolerance
}

// ---- Writers of small files in each format ----

fn png_file(
    w: u32,
    h: u32,
    colour: png::ColorType,
    depth: png::BitDepth,
    data: &[u8],
    palette: Option<&[u8]>,
) -> Vec<u8> {
    let mut out = Vec::new();
    {
        let mut e = png::Encoder::new(&mut out, w, h);
        e.set_color(colour);
        e.set_depth(depth);
        if let Some(p) = palette {
            e.set_palette(p.to_vec());
        }
        let mut writer = e.write_header().unwrap();
        writer.write_image_data(data).unwrap();
    }
    out
}

fn jpeg_file(w: u32, h: u32, colour: image::ExtendedColorType, data: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 98).write_image(data, w, h, colour).unwrap();
    out
}

fn hdr_file(w: usize, h: usize, texels: &[[f32; 3]]) -> Vec<u8> {
    let mut out = Vec::new();
    let pixels: Vec<image::Rgb<f32>> = texels.iter().map(|&t| image::Rgb(t)).collect();
    image::codecs::hdr::HdrEncoder::new(&mut out).encode(&pixels, w, h).unwrap();
    out
}

/// An OpenEXR file with the given channels (row 0 at the top), uncompressed.
fn exr_file(w: usize, h: usize, channels: Vec<(&str, FlatSamples)>) -> Vec<u8> {
    let list = channels.into_iter().map(|(name, samples)| AnyChannel::new(name, samples)).collect();
    let layer =
        Layer::new((w, h), LayerAttributes::default(), exr::prelude::Encoding::UNCOMPRESSED, AnyChannels::sort(list));
    let mut out = std::io::Cursor::new(Vec::new());
    Image::from_layer(layer).write().non_parallel().to_buffered(&mut out).unwrap();
    out.into_inner()
}

/// A PFM file of `rows` given top row first (the file stores them bottom first), `channels` 1 or 3.
fn pfm_file(w: usize, channels: usize, scale: f32, rows: &[Vec<f32>]) -> Vec<u8> {
    let magic = if channels == 3 { "PF" } else { "Pf" };
    let mut out = format!("{magic}\n{w} {}\n{scale}\n", rows.len()).into_bytes();
    for row in rows.iter().rev() {
        assert_eq!(row.len(), w * channels);
        for v in row {
            out.extend(if scale < 0.0 { v.to_le_bytes() } else { v.to_be_bytes() });
        }
    }
    out
}

fn decode(bytes: &[u8], encoding: Encoding) -> Bitmap {
    Bitmap::decode(bytes, "", encoding).unwrap_or_else(|e| panic!("{e}"))
}

// ---- Formats ----

#[test]
fn png_files_of_every_colour_type_and_depth_decode_from_srgb_or_raw() {
    // 16 bits: the curve is applied to v / 65535.
    let samples: [u16; 6] = [0, 1000, 32768, 65535, 300, 40000];
    let data: Vec<u8> = samples.iter().flat_map(|v| v.to_be_bytes()).collect();
    let file = png_file(2, 1, png::ColorType::Rgb, png::BitDepth::Sixteen, &data, None);
    let expected = |f: &dyn Fn(f64) -> f32, i: usize| {
        Rgb::new(f(samples[i] as f64 / 65535.0), f(samples[i + 1] as f64 / 65535.0), f(samples[i + 2] as f64 / 65535.0))
    };
    let t = decode(&file, Encoding::Srgb);
    assert!(close(t.texel(0, 0), expected(&srgb, 0), 1e-6) && close(t.texel(1, 0), expected(&srgb, 3), 1e-6));
    let raw = decode(&file, Encoding::Linear);
    let linear = |c: f64| c as f32;
    assert!(close(raw.texel(0, 0), expected(&linear, 0), 1e-6) && close(raw.texel(1, 0), expected(&linear, 3), 1e-6));
    // 8-bit grey, raw: the sample over 255, and a grey bitmap.
    let grey =
        decode(&png_file(2, 1, png::ColorType::Grayscale, png::BitDepth::Eight, &[51, 255], None), Encoding::Linear);
    assert!(grey.is_grey() && close(grey.texel(0, 0), Rgb::splat(0.2), 1e-6));
    // Grey with alpha: still grey, alpha ignored; 16-bit grey too.
    let ga =
        decode(&png_file(1, 1, png::ColorType::GrayscaleAlpha, png::BitDepth::Eight, &[188, 3], None), Encoding::Srgb);
    assert!(ga.is_grey() && close(ga.texel(0, 0), Rgb::splat(srgb(188.0 / 255.0)), 1e-6));
    let g16 = decode(
        &png_file(1, 1, png::ColorType::GrayscaleAlpha, png::BitDepth::Sixteen, &[0x80, 0, 0, 0], None),
        Encoding::Srgb,
    );
    assert!(g16.is_grey() && close(g16.texel(0, 0), Rgb::splat(srgb(32768.0 / 65535.0)), 1e-6));
    // RGBA: alpha ignored, a colour bitmap.
    let rgba =
        decode(&png_file(1, 1, png::ColorType::Rgba, png::BitDepth::Eight, &[255, 128, 0, 0], None), Encoding::Srgb);
    assert!(!rgba.is_grey() && close(rgba.texel(0, 0), Rgb::new(1.0, srgb(128.0 / 255.0), 0.0), 1e-6));
    // A palette expands to its colours.
    let palette = [10u8, 20, 30, 200, 100, 50];
    let indexed =
        decode(&png_file(2, 1, png::ColorType::Indexed, png::BitDepth::Eight, &[1, 0], Some(&palette)), Encoding::Srgb);
    let c = |r: u8, g: u8, b: u8| Rgb::new(srgb(r as f64 / 255.0), srgb(g as f64 / 255.0), srgb(b as f64 / 255.0));
    assert!(close(indexed.texel(0, 0), c(200, 100, 50), 1e-6) && close(indexed.texel(1, 0), c(10, 20, 30), 1e-6));
}

#[test]
fn jpeg_files_decode_close_to_their_colours_in_colour_and_grey() {
    // A flat colour: JPEG reproduces it within a few levels.
    let colour = [200u8, 100, 50];
    let data: Vec<u8> = (0..16 * 16).flat_map(|_| colour).collect();
    let file = jpeg_file(16, 16, image::ExtendedColorType::Rgb8, &data);
    assert_eq!(ImageFormat::from_magic(&file), Some(ImageFormat::Jpeg));
    let level = |v: u8, d: f64| v as f64 / 255.0 + d;
    for (encoding, f) in [(Encoding::Srgb, &srgb as &dyn Fn(f64) -> f32), (Encoding::Linear, &|c: f64| c as f32)] {
        let t = decode(&file, encoding);
        assert!(!t.is_grey());
        let got = t.texel(7, 9);
        for (i, &v) in colour.iter().enumerate() {
            let (lo, hi) = (f(level(v, -3.0 / 255.0)), f(level(v, 3.0 / 255.0)));
            assert!((lo..=hi).contains(&got[i]), "{encoding:?} channel {i}: {} not in [{lo}, {hi}]", got[i]);
        }
    }
    // A grey JPEG is a grey bitmap.
    let grey = jpeg_file(8, 8, image::ExtendedColorType::L8, &[128; 64]);
    let t = decode(&grey, Encoding::Srgb);
    assert!(t.is_grey() && (t.texel(3, 3).x - srgb(128.0 / 255.0)).abs() < 0.01);
}

#[test]
fn openexr_files_decode_their_rgb_or_luminance_channels_linearly() {
    // f32 colour, exact; the encoding of integer samples does not apply.
    let (r, g, b) = (vec![0.5f32, 2.0, 0.0, 7.25], vec![0.25f32, 0.0, 1.0, 0.125], vec![4.0f32, 0.5, 0.5, 0.0]);
    let file = exr_file(
        2,
        2,
        vec![
            ("R", FlatSamples::F32(r)),
            ("G", FlatSamples::F32(g)),
            ("B", FlatSamples::F32(b)),
            ("A", FlatSamples::F32(vec![0.0; 4])),
        ],
    );
    for encoding in [Encoding::Srgb, Encoding::Linear] {
        let t = decode(&file, encoding);
        assert_eq!(t.texel(0, 0), Rgb::new(0.5, 0.25, 4.0));
        assert_eq!(t.texel(1, 1), Rgb::new(7.25, 0.125, 0.0));
        assert_eq!(t.max_texel(), Rgb::new(7.25, 1.0, 4.0));
    }
    // Half floats, luminance only: a grey bitmap.
    let y = [0.5f32, 1.5, 3.0].map(exr::prelude::f16::from_f32).to_vec();
    let t = decode(&exr_file(3, 1, vec![("Y", FlatSamples::F16(y))]), Encoding::Srgb);
    assert!(t.is_grey() && t.texel(2, 0) == Rgb::splat(3.0) && t.texel(1, 0) == Rgb::splat(1.5));
}

#[test]
fn float_files_read_negative_samples_as_zero_and_refuse_non_finite_ones_naming_the_pixel() {
    let file = exr_file(2, 1, vec![("Y", FlatSamples::F32(vec![-0.5, 1.0]))]);
    assert_eq!(decode(&file, Encoding::Srgb).texel(0, 0), Rgb::ZERO);
    let nan = exr_file(3, 2, vec![("Y", FlatSamples::F32(vec![0.0, 0.0, 0.0, 0.0, f32::INFINITY, 0.0]))]);
    let e = Bitmap::decode(&nan, "", Encoding::Srgb).unwrap_err();
    assert_eq!(e, TextureError::NotFinite { format: ImageFormat::OpenExr, x: 1, y: 1, value: f32::INFINITY });
    assert!(e.to_string().contains("pixel (1, 1)"), "{e}");
    let pfm = pfm_file(2, 1, -1.0, &[vec![1.0, f32::NAN]]);
    let e = Bitmap::decode(&pfm, "", Encoding::Srgb).unwrap_err();
    assert!(matches!(e, TextureError::NotFinite { format: ImageFormat::Pfm, x: 1, y: 0, .. }), "{e}");
}

#[test]
fn an_openexr_file_without_colour_or_luminance_is_refused_naming_its_channels() {
    let file = exr_file(1, 1, vec![("Z", FlatSamples::F32(vec![1.0])), ("R", FlatSamples::F32(vec![1.0]))]);
    let e = Bitmap::decode(&file, "depth.exr", Encoding::Srgb).unwrap_err().to_string();
    assert!(e.contains("OpenEXR") && e.contains("R, Z") && e.contains("Y channel"), "{e}");
}

#[test]
fn radiance_hdr_files_decode_within_the_precision_of_rgbe() {
    let texels = [[0.5f32, 0.25, 4.0], [100.0, 0.001, 0.0], [1.0, 1.0, 1.0], [0.0, 0.0, 0.0]];
    let t = decode(&hdr_file(2, 2, &texels), Encoding::Srgb);
    for (i, e) in texels.iter().enumerate() {
        let got = t.texel(i as i64 % 2, i as i64 / 2);
        // RGBE keeps 8 bits of mantissa against the largest channel.
        let tolerance = e.iter().fold(0.0f32, |m, &v| m.max(v)) / 128.0;
        assert!(close(got, Rgb::from(*e), tolerance), "{i}: {got} vs {e:?}");
    }
}

#[test]
fn pfm_files_decode_in_both_byte_orders_bottom_row_first_with_their_scale() {
    // Little-endian (negative scale) colour, scale 2: every sample doubled.
    let rows = vec![vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0], vec![0.5, 0.25, 0.125, 0.0, 0.0, 0.0]];
    let t = decode(&pfm_file(2, 3, -2.0, &rows), Encoding::Srgb);
    assert_eq!((t.width(), t.height()), (2, 2));
    assert_eq!(t.texel(0, 0), Rgb::new(2.0, 4.0, 6.0));
    assert_eq!(t.texel(1, 0), Rgb::new(8.0, 10.0, 12.0));
    assert_eq!(t.texel(0, 1), Rgb::new(1.0, 0.5, 0.25));
    // Big-endian grey.
    let t = decode(&pfm_file(3, 1, 1.0, &[vec![0.5, 0.75, 1.0], vec![0.0, 0.0, 2.0]]), Encoding::Linear);
    assert!(t.is_grey() && t.texel(2, 0) == Rgb::splat(1.0) && t.texel(2, 1) == Rgb::splat(2.0));
    // A header without its scale, or with a width that is no number, says so.
    let e = Bitmap::decode(b"PF\n2 2\n", "", Encoding::Srgb).unwrap_err().to_string();
    assert!(e.contains("PFM") && e.contains("scale"), "{e}");
    let e = Bitmap::decode(b"Pf\nabc 2\n-1\n\0\0\0\0", "", Encoding::Srgb).unwrap_err().to_string();
    assert!(e.contains("width 'abc'"), "{e}");
    let e = Bitmap::decode(b"Pf\n2 2\n-1\n\0\0\0\0", "", Encoding::Srgb).unwrap_err().to_string();
    assert!(e.contains("truncated") && e.contains("16 bytes"), "{e}");
}

/// A 16 × 16 grey image, its top 8 rows white and the rest black, in every format.
fn top_white_files() -> Vec<(ImageFormat, Vec<u8>)> {
    let grey: Vec<u8> = (0..256).map(|i| if i < 128 { 255 } else { 0 }).collect();
    let rgb: Vec<u8> = grey.iter().flat_map(|&v| [v, v, v]).collect();
    let floats: Vec<f32> = grey.iter().map(|&v| v as f32 / 255.0).collect();
    let rgbf: Vec<[f32; 3]> = floats.iter().map(|&v| [v; 3]).collect();
    let rows: Vec<Vec<f32>> = floats.chunks(16).map(|r| r.to_vec()).collect();
    vec![
        (ImageFormat::Png, png_file(16, 16, png::ColorType::Rgb, png::BitDepth::Eight, &rgb, None)),
        (ImageFormat::Jpeg, jpeg_file(16, 16, image::ExtendedColorType::L8, &grey)),
        (ImageFormat::OpenExr, exr_file(16, 16, vec![("Y", FlatSamples::F32(floats.clone()))])),
        (ImageFormat::RadianceHdr, hdr_file(16, 16, &rgbf)),
        (ImageFormat::Pfm, pfm_file(16, 1, -1.0, &rows)),
    ]
}

#[test]
fn row_zero_is_the_top_of_the_image_and_v_runs_upward_in_every_format() {
    for (format, file) in top_white_files() {
        assert_eq!(ImageFormat::from_magic(&file), Some(format));
        let t = decode(&file, Encoding::Srgb);
        assert!(t.texel(5, 2).x > 0.97 && t.texel(5, 13).x < 0.03, "{format}: {} {}", t.texel(5, 2), t.texel(5, 13));
        assert!(t.lookup(Vec2::new(0.5, 0.8)).x > 0.97 && t.lookup(Vec2::new(0.5, 0.2)).x < 0.03, "{format}");
    }
}

#[test]
fn the_format_comes_from_the_content_not_the_name() {
    let (_, png) = &top_white_files()[0];
    assert!(Bitmap::decode(png, "misnamed.exr", Encoding::Srgb).is_ok());
    let e = Bitmap::decode(b"solid cube\nendsolid\n", "cube.png", Encoding::Srgb).unwrap_err().to_string();
    assert!(e.contains("does not begin as PNG files do"), "{e}");
}

/// A small deterministic generator for the corruptions below.
fn next(state: &mut u64) -> u64 {
    *state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
    *state >> 33
}

#[test]
fn truncated_and_corrupted_files_of_every_format_are_refused_with_a_message_never_a_panic() {
    let mut state = 7u64;
    for (format, file) in top_white_files() {
        // Cut in half: refused, and the message names the format.
        let e = Bitmap::decode(&file[..file.len() / 2], "", Encoding::Srgb).unwrap_err().to_string();
        assert!(e.contains(&format.to_string()), "{format}: {e}");
        // Every cut and a thousand random corruptions: an answer either way, never a panic.
        for len in 0..file.len() {
            let _ = Bitmap::decode(&file[..len], "", Encoding::Srgb);
        }
        for _ in 0..1000 {
            let mut bad = file.clone();
            for _ in 0..1 + next(&mut state) % 4 {
                let i = next(&mut state) as usize % bad.len();
                bad[i] = next(&mut state) as u8;
            }
            if let Err(e) = Bitmap::decode(&bad, "", Encoding::Srgb) {
                assert!(!e.to_string().is_empty());
            }
        }
    }
}

#[test]
fn files_declaring_more_pixels_than_a_texture_may_have_are_refused_before_decoding() {
    let huge = 30_000u32;
    let too_large = |format: ImageFormat, bytes: &[u8]| {
        let e = Bitmap::decode(bytes, "", Encoding::Srgb).unwrap_err();
        assert!(matches!(e, TextureError::TooLarge { format: f, .. } if f == format), "{format}: {e}");
        assert!(e.to_string().contains("30000×30000"), "{e}");
    };
    let files = top_white_files();
    // PNG: the IHDR's width and height (its CRC no longer matches, which the size check comes before).
    let mut png = files[0].1.clone();
    png[16..20].copy_from_slice(&huge.to_be_bytes());
    png[20..24].copy_from_slice(&huge.to_be_bytes());
    let crc = crc32(&png[12..29]);
    png[29..33].copy_from_slice(&crc.to_be_bytes());
    too_large(ImageFormat::Png, &png);
    // JPEG: the frame header's height and width.
    let mut jpeg = files[1].1.clone();
    let sof = jpeg.windows(2).position(|w| w == [0xff, 0xc0]).expect("a baseline frame header");
    jpeg[sof + 5..sof + 7].copy_from_slice(&(huge as u16).to_be_bytes());
    jpeg[sof + 7..sof + 9].copy_from_slice(&(huge as u16).to_be_bytes());
    too_large(ImageFormat::Jpeg, &jpeg);
    // OpenEXR: the data window's corners.
    let mut exr = files[2].1.clone();
    let at = exr.windows(17).position(|w| w == b"dataWindow\0box2i\0").expect("a data window") + 17 + 4;
    exr[at + 8..at + 12].copy_from_slice(&(huge as i32 - 1).to_le_bytes());
    exr[at + 12..at + 16].copy_from_slice(&(huge as i32 - 1).to_le_bytes());
    too_large(ImageFormat::OpenExr, &exr);
    too_large(
        ImageFormat::RadianceHdr,
        format!("#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y {huge} +X {huge}\n").as_bytes(),
    );
    too_large(ImageFormat::Pfm, format!("PF\n{huge} {huge}\n-1\n").as_bytes());
}

/// CRC-32 as PNG chunks use it.
fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = 0xffff_ffffu32;
    for &b in bytes {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = if crc & 1 != 0 { (crc >> 1) ^ 0xedb8_8320 } else { crc >> 1 };
        }
    }
    !crc
}

// ---- Scenes ----

const SCENE: &str = r#"
[camera]
position = [0.0, 0.0, -1.0]
look_at = [0.0, 0.0, 0.0]
fov_y_deg = 40
width = 8
height = 8

[materials.white]
type = "diffuse"
albedo_texture = "TEXTURE"

[[objects]]
name = "floor"
material = "white"
quad = { corner = [-1.0, -1.0, 0.0], edge1 = [2.0, 0.0, 0.0], edge2 = [0.0, 2.0, 0.0] }

[[lights]]
type = "point"
position = [0.0, 0.0, -0.5]
intensity = [1.0, 1.0, 1.0]
"#;

fn scene_with_texture(name: &str, bytes: Vec<u8>) -> Result<Scene, photonfarm::scene::SceneError> {
    let text = SCENE.replace("TEXTURE", name);
    let files = BTreeMap::from([(name.to_string(), bytes)]);
    Scene::from_toml_with_meshes(&text, Path::new("scene.toml"), &files)
}

#[test]
fn scenes_read_albedo_textures_of_every_format() {
    for (format, file) in top_white_files() {
        let name = format!("floor.{}", format.to_string().to_lowercase().replace(' ', ""));
        let scene = scene_with_texture(&name, file).unwrap_or_else(|e| panic!("{format}: {e}"));
        let Surface::Diffuse { reflectance } = &scene.materials[0].front else { panic!("a diffuse floor") };
        assert!(reflectance.eval(Vec2::new(0.5, 0.9)).x > 0.97, "{format}");
        assert!(reflectance.eval(Vec2::new(0.5, 0.1)).x < 0.03, "{format}");
        assert!(scene.mesh_files.iter().any(|(p, _)| *p == name), "the texture travels with the scene");
    }
}

#[test]
fn a_broken_texture_is_refused_naming_the_file_the_line_the_field_and_the_format() {
    let (_, exr) = &top_white_files()[2];
    let e = scene_with_texture("floor.exr", exr[..exr.len() / 2].to_vec()).err().expect("refused").to_string();
    let line = SCENE.lines().position(|l| l.contains("[materials.white]")).unwrap() + 1;
    for needle in
        [format!("scene.toml:{line}"), "materials.white.albedo_texture".into(), "floor.exr".into(), "OpenEXR".into()]
    {
        assert!(e.contains(&needle), "{e:?} does not mention {needle:?}");
    }
}

#[test]
fn a_float_albedo_texture_above_one_is_refused() {
    let exr = exr_file(1, 1, vec![("Y", FlatSamples::F32(vec![2.5]))]);
    let e = scene_with_texture("bright.exr", exr).err().expect("refused").to_string();
    assert!(e.contains("albedo_texture") && e.contains("2.5") && e.contains("cannot reflect more"), "{e}");
}

// ---- The shading frame's tangent ----

/// A scene of two quads side by side in the plane z = 0, facing −z: the left one with u along +x, the right one
/// with u along +y; materials are set by the tests.
fn two_quads() -> Scene {
    let text = r#"
[camera]
position = [0.0, 0.0, -3.0]
look_at = [0.0, 0.0, 0.0]
fov_y_deg = 40
width = 8
height = 8

[materials.m]
type = "diffuse"
albedo = [0.5, 0.5, 0.5]

[[objects]]
name = "u along x"
material = "m"
quad = { corner = [-2.0, -1.0, 0.0], edge1 = [2.0, 0.0, 0.0], edge2 = [0.0, 2.0, 0.0] }

[[objects]]
name = "u along y"
material = "m"
quad = { corner = [2.0, -1.0, 0.0], edge1 = [0.0, 2.0, 0.0], edge2 = [-2.0, 0.0, 0.0] }

[[objects]]
name = "a box without texture coordinates"
material = "m"
box = { min = [-1.0, 2.0, 0.0], max = [1.0, 3.0, 1.0] }

[[lights]]
type = "point"
position = [0.0, 0.0, -2.0]
intensity = [1.0, 1.0, 1.0]
"#;
    Scene::from_toml_with_meshes(text, Path::new("quads.toml"), &BTreeMap::new()).unwrap()
}

fn hit_at(scene: &Scene, x: f32, y: f32) -> photonfarm::geometry::SurfaceHit {
    scene.geometry.intersect(&Ray::new(Vec3::new(x, y, -1.0), Vec3::Z)).expect("a hit")
}

#[test]
fn the_tangent_is_du_along_texture_coordinates_or_the_first_edge_without_them() {
    let scene = two_quads();
    let along = |t: Option<Vec3>| t.expect("a tangent").normalize();
    assert!((along(scene.tangent_at(&hit_at(&scene, -1.0, 0.3))) - Vec3::X).length() < 1e-6);
    assert!((along(scene.tangent_at(&hit_at(&scene, 1.0, 0.3))) - Vec3::Y).length() < 1e-6);
    // The box's front face (z = 0) has no texture coordinates: its triangle's first edge, as Mitsuba's
    // barycentric parametrisation has it.
    let hit = hit_at(&scene, 0.2, 2.5);
    let v = scene.geometry.triangle(hit.triangle).v;
    assert!(scene.triangle_uvs.get(hit.triangle).is_none());
    assert_eq!(scene.tangent_at(&hit), Some(v[1] - v[0]));
}

#[test]
fn anisotropic_materials_turn_their_roughness_with_the_uv_tangent() {
    let mut scene = two_quads();
    let roughness =
        Roughness { distribution: Distribution::Ggx, alpha_u: Texture::grey(0.05), alpha_v: Texture::grey(0.5) };
    let metal = Material::two_sided(Surface::Conductor {
        fresnel: photonfarm::bsdf::conductor::ConductorFresnel::Perfect,
        specular: Texture::grey(1.0),
        roughness: Some(roughness),
    });
    assert!(metal.needs_tangent() && !scene.materials[0].needs_tangent());
    scene.materials[0] = metal;
    // Seen head-on, light leaving 40° off the mirror direction: sharp (α = 0.05) when tilted along u, broad
    // (α = 0.5) when tilted across it.
    let wo = -Vec3::Z;
    let tilt = |axis: Vec3| (-Vec3::Z * 40f32.to_radians().cos() + axis * 40f32.to_radians().sin()).normalize();
    let f = |x: f32, axis: Vec3| {
        let hit = hit_at(&scene, x, 0.3);
        scene.bsdf(&hit, wo).eval(wo, tilt(axis), Transport::Radiance).x
    };
    let (left_x, left_y) = (f(-1.0, Vec3::X), f(-1.0, Vec3::Y));
    let (right_x, right_y) = (f(1.0, Vec3::X), f(1.0, Vec3::Y));
    assert!(left_x < 0.01 * left_y, "u along x: {left_x} along u, {left_y} across");
    assert!(right_y < 0.01 * right_x, "u along y: {right_y} along u, {right_x} across");
    assert!((left_y - right_x).abs() < 1e-4 * left_y, "the same lobe turned: {left_y} vs {right_x}");
}

// ---- The TOML syntax of textures ----

/// SCENE with the floor's material given `albedo = VALUE` (and no albedo_texture), its files in memory.
fn scene_with_albedo(value: &str, files: &[(&str, Vec<u8>)]) -> Result<Scene, photonfarm::scene::SceneError> {
    let text = SCENE.replace("albedo_texture = \"TEXTURE\"", &format!("albedo = {value}"));
    let files = files.iter().map(|(n, b)| (n.to_string(), b.clone())).collect();
    Scene::from_toml_with_meshes(&text, Path::new("scene.toml"), &files)
}

fn floor_albedo(scene: &Scene) -> &Texture {
    let Surface::Diffuse { reflectance } = &scene.materials[0].front else { panic!("a diffuse floor") };
    reflectance
}

#[test]
fn an_albedo_table_reads_a_bitmap_of_any_format_with_its_lookup_options() {
    for (format, file) in top_white_files() {
        let value = "{ bitmap = \"floor.img\", filter = \"nearest\", wrap = \"clamp\", factor = [0.5, 0.5, 0.5], \
                     to_uv = [[1, 0, 0], [0, 0.5, 0.5]] }";
        let scene = scene_with_albedo(value, &[("floor.img", file)]).unwrap_or_else(|e| panic!("{format}: {e}"));
        let albedo = floor_albedo(&scene);
        // to_uv maps v ∈ [0, 1] onto [0.5, 1]: the top (white) half of the image everywhere.
        for v in [0.05, 0.5, 0.95] {
            assert!((albedo.eval(Vec2::new(0.5, v)).x - 0.5).abs() < 0.02, "{format} v = {v}");
        }
        // Clamped: far outside reads the edge texels, white at the top.
        assert!((albedo.eval(Vec2::new(3.0, 9.0)).x - 0.5).abs() < 0.02, "{format}");
        assert!(scene.materials[0].uses_uv());
        assert!(scene.mesh_files.iter().any(|(p, _)| p == "floor.img"), "the texture travels with the scene");
    }
}

#[test]
fn an_albedo_checkerboard_loads_on_a_quad_and_is_refused_where_there_are_no_texture_coordinates() {
    let value = "{ checkerboard = true, color0 = [0.9, 0.1, 0.1], color1 = 0.3, to_uv = [[2, 0, 0], [0, 2, 0]] }";
    let scene = scene_with_albedo(value, &[]).unwrap();
    let albedo = floor_albedo(&scene);
    assert_eq!(albedo.eval(Vec2::new(0.125, 0.375)), Rgb::new(0.9, 0.1, 0.1));
    assert_eq!(albedo.eval(Vec2::new(0.375, 0.375)), Rgb::splat(0.3));
    let quad = "quad = { corner = [-1.0, -1.0, 0.0], edge1 = [2.0, 0.0, 0.0], edge2 = [0.0, 2.0, 0.0] }";
    let text = SCENE
        .replace("albedo_texture = \"TEXTURE\"", &format!("albedo = {value}"))
        .replace(quad, "box = { min = [-1.0, -1.0, 0.0], max = [1.0, 1.0, 0.1] }");
    let e = Scene::from_toml(&text, Path::new("scene.toml"), Path::new(".")).err().expect("refused").to_string();
    assert!(e.contains("objects[0].material") && e.contains("texture coordinates") && e.contains("box"), "{e}");
}

#[test]
fn albedo_texture_keeps_working_beside_a_constant_albedo_and_is_refused_beside_a_table() {
    let (_, png) = top_white_files().remove(0);
    let text = SCENE.replace("albedo_texture", "albedo = 0.5\nalbedo_texture");
    let files = BTreeMap::from([("floor.png".to_string(), png.clone())]);
    let scene =
        Scene::from_toml_with_meshes(&text.replace("TEXTURE", "floor.png"), Path::new("s.toml"), &files).unwrap();
    assert!((floor_albedo(&scene).eval(Vec2::new(0.5, 0.9)).x - 0.5).abs() < 1e-3);
    let text = SCENE.replace("albedo_texture", "albedo = { checkerboard = true }\nalbedo_texture");
    let e = Scene::from_toml_with_meshes(&text.replace("TEXTURE", "floor.png"), Path::new("s.toml"), &files)
        .err()
        .expect("refused")
        .to_string();
    assert!(e.contains("materials.white.albedo_texture") && e.contains("constant albedo"), "{e}");
}

#[test]
fn a_float_bitmap_in_an_albedo_table_above_one_is_refused_naming_the_field() {
    let exr = exr_file(1, 1, vec![("Y", FlatSamples::F32(vec![2.5]))]);
    let e = scene_with_albedo("{ bitmap = \"bright.exr\" }", &[("bright.exr", exr.clone())]).err().expect("refused");
    let e = e.to_string();
    assert!(e.contains("materials.white.albedo") && e.contains("2.5") && e.contains("cannot reflect more"), "{e}");
    // Scaled down by its factor it is a valid albedo.
    assert!(scene_with_albedo("{ bitmap = \"bright.exr\", factor = 0.4 }", &[("bright.exr", exr)]).is_ok());
}

// ---- Against Mitsuba 3 ----

/// The texture a case of shared/tests/data/textures/mitsuba.json describes (written by scripts/mitsuba/textures).
fn mitsuba_case_texture(t: &serde_json::Value, dir: &Path) -> Texture {
    use photonfarm::texture::{BitmapTexture, Checkerboard, Filter, UvTransform, Wrap};
    let to_uv = match t.get("to_uv_mitsuba") {
        Some(rows) => {
            let row = |i: usize| [0, 1, 2].map(|j| rows[i][j].as_f64().unwrap() as f32);
            UvTransform::from_mitsuba([row(0), row(1)]).unwrap()
        }
        None => UvTransform::IDENTITY,
    };
    if let Some(file) = t.get("bitmap").and_then(|f| f.as_str()) {
        let encoding = if t["raw"].as_bool().unwrap() { Encoding::Linear } else { Encoding::Srgb };
        let image = Bitmap::decode(&std::fs::read(dir.join(file)).unwrap(), file, encoding).unwrap();
        let filter = if t["filter"] == "nearest" { Filter::Nearest } else { Filter::Bilinear };
        let wrap = match t["wrap"].as_str().unwrap() {
            "mirror" => Wrap::Mirror,
            "clamp" => Wrap::Clamp,
            _ => Wrap::Repeat,
        };
        return Texture::Bitmap(BitmapTexture {
            image: std::sync::Arc::new(image),
            factor: Rgb::ONE,
            filter,
            wrap,
            to_uv,
        });
    }
    let colour = |c: Option<&serde_json::Value>, default: Texture| match c {
        Some(serde_json::Value::Array(a)) => Texture::Constant(Rgb::new(
            a[0].as_f64().unwrap() as f32,
            a[1].as_f64().unwrap() as f32,
            a[2].as_f64().unwrap() as f32,
        )),
        Some(v) => Texture::grey(v.as_f64().unwrap() as f32),
        None => default,
    };
    let d = Checkerboard::default();
    Texture::Checkerboard(Box::new(Checkerboard {
        color0: colour(t.get("color0"), d.color0),
        color1: colour(t.get("color1"), d.color1),
        to_uv,
    }))
}

#[test]
fn textures_match_mitsuba_3() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/textures");
    let data: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("mitsuba.json")).unwrap()).unwrap();
    let (mut worst_colour, mut worst_scalar, mut swapped) = (0.0f32, 0.0f32, 0);
    for case in data["cases"].as_array().unwrap() {
        let name = case["name"].as_str().unwrap();
        let texture = mitsuba_case_texture(&case["texture"], &dir);
        let checkerboard = matches!(texture, Texture::Checkerboard(_));
        for p in case["points"].as_array().unwrap() {
            let x: Vec<f32> = p.as_array().unwrap().iter().map(|x| x.as_f64().unwrap() as f32).collect();
            // Mitsuba's v runs down the image: photonfarm's is 1 − v.
            let uv = Vec2::new(x[0], 1.0 - x[1]);
            let theirs = Rgb::new(x[2], x[3], x[4]);
            let ours = texture.eval(uv);
            let colour_error = ((ours - theirs).abs() / theirs.abs().max(Rgb::ONE)).max_element();
            assert!(colour_error < 1e-5, "{name} at Mitsuba's uv ({}, {}): {ours} vs {theirs}", x[0], x[1]);
            worst_colour = worst_colour.max(colour_error);
            // Numbers: a bitmap's luminance, whose weights Mitsuba writes with more digits (0.212671, 0.715160,
            // 0.072169 against Rec. 709's 0.2126, 0.7152, 0.0722); a checkerboard's number is its colour's (the
            // channel mean), where Mitsuba's eval_1 reads the other colour. The weights differ by at most 3.4e-4
            // of themselves (red's), which bounds the relative difference of the luminances.
            let scalar = texture.eval_scalar(uv);
            let expected = if checkerboard { (theirs.x + theirs.y + theirs.z) / 3.0 } else { x[5] };
            let scalar_error = (scalar - expected).abs() / expected.abs().max(1.0);
            assert!(scalar_error < 3.5e-4, "{name} at ({}, {}): number {scalar} vs {expected}", x[0], x[1]);
            worst_scalar = worst_scalar.max(scalar_error);
            if checkerboard && (x[5] - expected).abs() > 1e-6 {
                swapped += 1;
            }
        }
    }
    println!(
        "largest relative difference to Mitsuba {}: colour {worst_colour:e}, number {worst_scalar:e}; Mitsuba's \
              checkerboard eval_1 differs from its eval at {swapped} points",
        data["mitsuba"]
    );
}
