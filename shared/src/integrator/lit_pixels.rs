//! Which pixels see a light, for the lit-pixel mask (`crate::accumulation::LitMask::of_scene`): stratified
//! primary rays per pixel that follow every specular branch and look for an emitter, or for an environment where
//! they leave the scene.

use crate::camera::Lens;
use crate::color::Rgb;
use crate::geometry::{ray::offset_origin, Ray};
use crate::light::Light;
use crate::scene::Scene;
use glam::{Vec2, Vec3};
use rayon::prelude::*;

/// Primary rays per pixel the mask is decided from (a 4 × 4 stratification of the pixel and of the aperture).
pub const LIT_MASK_SAMPLES: u32 = 16;

/// Segments traced per pixel at most. The branches of a pixel's primary rays are followed likeliest first: the
/// main chain of every ray costs a segment per surface (about 14 through the double Gauss lens of `lens.toml`),
/// and each uncoated surface it crosses spawns a reflection.
const PIXEL_BUDGET: u32 = 16 * LIT_MASK_SAMPLES;

/// Branches less likely than this (the product of their reflection and transmission probabilities) are not
/// followed. A light seen through glass, in a reflection off it, or after two reflections inside a glass
/// sphere (a 0.2% branch, whose rare, bright samples are what a noise-based mask would drop after the first
/// one) makes a pixel lit.
const MIN_BRANCH_PROBABILITY: f32 = 1e-4;

/// Fixed scrambling of the mask's Sobol points: the mask must not depend on the run's seed.
const MASK_SEED: u32 = 0x6c69_7431;

/// Decides which pixels of `scene` see an emitter directly or through specular surfaces only, within
/// `max_depth` segments, as one flag per pixel, row by row: `LIT_MASK_SAMPLES` primary rays per pixel, their
/// pixel positions and aperture points the first four coordinates of a scrambled Sobol sequence (stratified in
/// both), each followed into every reflection and transmission of the delta surfaces it meets, likeliest
/// branch first, up to `PIXEL_BUDGET` segments per pixel.
///
/// A pinhole camera's pixels whose four corner rays see the same surface, one that neither emits nor has a
/// delta lobe, with no emitter's image box over them, are unlit without their sixteen rays
/// (`plain_pixels`): the corner rays cost one ray per pixel, so the mask of a large image costs about a
/// sixteenth of the full test. A delta surface or an emitter smaller than a pixel that no corner ray and no
/// emitter box reveals is what this could miss; every emitter's box is marked, so only the former remains.
pub fn lit_pixels(scene: &Scene, max_depth: u32) -> Vec<bool> {
    decided(scene, max_depth, plain_pixels(scene))
}

/// The flags with the full test at every pixel that `plain` (when given) does not say is unlit.
fn decided(scene: &Scene, max_depth: u32, plain: Option<Vec<bool>>) -> Vec<bool> {
    let camera = &scene.camera;
    let w = camera.width as usize;
    (0..camera.pixel_count())
        .into_par_iter()
        .with_min_len(64)
        .map(|i| {
            if plain.as_ref().is_some_and(|p| p[i]) {
                return false;
            }
            let (x, y) = ((i % w) as u32, (i / w) as u32);
            let rays = (0..LIT_MASK_SAMPLES).filter_map(|k| {
                let u = sobol_burley::sample_4d(k, 0, MASK_SEED ^ i as u32);
                let r = camera.generate_ray(x, y, Vec2::new(u[0], u[1]), Vec2::new(u[2], u[3]));
                (r.weight > 0.0).then_some(r.ray)
            });
            sees_emitter(scene, rays, max_depth)
        })
        .collect()
}

/// What a corner ray saw: the object of a surface that neither emits nor has a delta lobe, `ESCAPED` for a ray
/// that left the scene where no infinite light shines, or `COMPLEX` for anything a pixel's full test must look
/// at (an emitter, a delta surface, an infinite light's radiance).
const ESCAPED: u32 = u32::MAX;
const COMPLEX: u32 = u32::MAX - 1;

/// Images with more pixels than this trace their corner rays at every second pixel corner first
/// (`CORNER_STRIDE`): a 4K pixel is half a 1080p one across, and the corner pass is most of a large image's mask.
const STRIDED_CORNERS_ABOVE: usize = 2048 * 1024;

/// The corner rays' spacing in pixels on images of more than `STRIDED_CORNERS_ABOVE` pixels.
const CORNER_STRIDE: usize = 2;

/// For a pinhole camera, the pixels known to be unlit from their corner rays alone: all four corners saw the
/// same plain surface (`ESCAPED` included), and no emitter's box projects onto the pixel or its neighbours.
/// None for other cameras, whose rays start across an aperture. On a large image the corners of blocks of
/// `CORNER_STRIDE` × `CORNER_STRIDE` pixels are traced first, and a block whose four corners saw the same plain
/// surface has all its pixels plain; the other blocks trace their pixels' corners, as a small image does.
fn plain_pixels(scene: &Scene) -> Option<Vec<bool>> {
    let stride = if scene.camera.pixel_count() > STRIDED_CORNERS_ABOVE { CORNER_STRIDE } else { 1 };
    plain_pixels_with_stride(scene, stride)
}

/// `plain_pixels` with the corner rays first traced `stride` pixels apart.
fn plain_pixels_with_stride(scene: &Scene, stride: usize) -> Option<Vec<bool>> {
    let camera = &scene.camera;
    if camera.lens != Lens::Pinhole {
        return None;
    }
    let (w, h) = (camera.width as usize, camera.height as usize);
    // The class of the ray through pixel corner (cx, cy), 0 ≤ cx ≤ w and 0 ≤ cy ≤ h: the corner as a position in
    // pixel (cx − 1, cy − 1) where the image ends there.
    let class = |cx: usize, cy: usize| {
        let (x, jx) = if cx == w { (cx - 1, 1.0) } else { (cx, 0.0) };
        let (y, jy) = if cy == h { (cy - 1, 1.0) } else { (cy, 0.0) };
        corner_class(scene, &camera.generate_ray(x as u32, y as u32, Vec2::new(jx, jy), Vec2::ZERO).ray)
    };
    // Blocks of stride × stride pixels (narrower at the right and bottom edges); their corners' classes.
    let (bw, bh) = (w.div_ceil(stride), h.div_ceil(stride));
    let edge = |b: usize, n: usize| (b * stride).min(n);
    let coarse: Vec<u32> = (0..(bw + 1) * (bh + 1))
        .into_par_iter()
        .with_min_len(256)
        .map(|c| class(edge(c % (bw + 1), w), edge(c / (bw + 1), h)))
        .collect();
    let boxes = emitter_boxes(scene);
    // Four corner classes of one surface that neither emits nor has a delta lobe.
    let same_plain = |k: [u32; 4]| k[0] != COMPLEX && k.iter().all(|&c| c == k[0]);
    let mut plain = vec![false; w * h];
    // One row of blocks at a time, each its pixel rows of the image.
    plain.par_chunks_mut(w * stride).enumerate().for_each(|(by, rows)| {
        let (y0, y1) = (edge(by, h), edge(by + 1, h));
        for bx in 0..bw {
            let (x0, x1) = (edge(bx, w), edge(bx + 1, w));
            let at = |cx: usize, cy: usize| coarse[cy * (bw + 1) + cx];
            let uniform = same_plain([at(bx, by), at(bx + 1, by), at(bx, by + 1), at(bx + 1, by + 1)]);
            // A block whose corners differ traces the corners of its pixels (its own four are known).
            let fine: Vec<u32> = if uniform {
                Vec::new()
            } else {
                (y0..=y1)
                    .flat_map(|cy| (x0..=x1).map(move |cx| (cx, cy)))
                    .map(|(cx, cy)| match ((cx == x0 || cx == x1), (cy == y0 || cy == y1)) {
                        (true, true) => at(if cx == x0 { bx } else { bx + 1 }, if cy == y0 { by } else { by + 1 }),
                        _ => class(cx, cy),
                    })
                    .collect()
            };
            let fw = x1 - x0 + 1;
            for y in y0..y1 {
                for x in x0..x1 {
                    let f = |dx: usize, dy: usize| fine[(y - y0 + dy) * fw + x - x0 + dx];
                    let same = uniform || same_plain([f(0, 0), f(1, 0), f(0, 1), f(1, 1)]);
                    rows[(y - y0) * w + x] = same && !boxes[y * w + x];
                }
            }
        }
    });
    Some(plain)
}

fn corner_class(scene: &Scene, ray: &Ray) -> u32 {
    let Some(hit) = scene.geometry.intersect(ray) else {
        return if scene.lights.escaped(ray.direction, None) == Rgb::ZERO { ESCAPED } else { COMPLEX };
    };
    let wo = -ray.direction;
    if scene.lights.emitted(&hit, ray.direction) != Rgb::ZERO || !scene.bsdf(&hit, wo).delta_branches(wo).is_empty() {
        return COMPLEX;
    }
    hit.object
}

/// The pixels onto which some emitter's bounding box projects, grown by a pixel, as one flag per pixel: an
/// emitter smaller than a pixel falls between the corner rays. An emitter whose box reaches behind the camera
/// marks the whole image.
fn emitter_boxes(scene: &Scene) -> Vec<bool> {
    let camera = &scene.camera;
    let (w, h) = (camera.width as i64, camera.height as i64);
    // A two-dimensional difference array: each box adds one rectangle in constant time.
    let mut marks = vec![0i32; ((w + 1) * (h + 1)) as usize];
    let mut mark = |x0: i64, y0: i64, x1: i64, y1: i64| {
        let (x0, y0, x1, y1) = (x0.clamp(0, w), y0.clamp(0, h), x1.clamp(0, w), y1.clamp(0, h));
        if x0 >= x1 || y0 >= y1 {
            return;
        }
        let at = |x: i64, y: i64| (y * (w + 1) + x) as usize;
        marks[at(x0, y0)] += 1;
        marks[at(x1, y0)] -= 1;
        marks[at(x0, y1)] -= 1;
        marks[at(x1, y1)] += 1;
    };
    for light in scene.lights.all() {
        let (lo, hi) = match light {
            Light::Area { triangle, .. } => {
                let v = scene.geometry.triangle(*triangle).v;
                (v[0].min(v[1]).min(v[2]), v[0].max(v[1]).max(v[2]))
            }
            Light::Sphere { center, radius, .. } | Light::Disc { center, radius, .. } => {
                (*center - Vec3::splat(*radius), *center + Vec3::splat(*radius))
            }
            Light::Point { .. } | Light::Spot { .. } | Light::Infinite(_) => continue,
        };
        let mut min = Vec2::splat(f32::INFINITY);
        let mut max = Vec2::splat(f32::NEG_INFINITY);
        let mut behind = false;
        for k in 0..8 {
            let p = Vec3::new(
                if k & 1 == 0 { lo.x } else { hi.x },
                if k & 2 == 0 { lo.y } else { hi.y },
                if k & 4 == 0 { lo.z } else { hi.z },
            );
            match camera.project(p) {
                Some(q) if q.is_finite() => (min, max) = (min.min(q), max.max(q)),
                _ => behind = true,
            }
        }
        if behind {
            mark(0, 0, w, h);
        } else {
            mark(min.x.floor() as i64 - 1, min.y.floor() as i64 - 1, max.x.ceil() as i64 + 1, max.y.ceil() as i64 + 1);
        }
    }
    // Prefix sums over rows then columns turn the differences into counts.
    for y in 0..=h {
        for x in 1..=w {
            marks[(y * (w + 1) + x) as usize] += marks[(y * (w + 1) + x - 1) as usize];
        }
    }
    for y in 1..=h {
        for x in 0..=w {
            marks[(y * (w + 1) + x) as usize] += marks[((y - 1) * (w + 1) + x) as usize];
        }
    }
    (0..h).flat_map(|y| (0..w).map(move |x| (x, y))).map(|(x, y)| marks[(y * (w + 1) + x) as usize] > 0).collect()
}

/// A ray of the specular tree still to trace: its segment number and the probability of its branch.
struct Branch {
    ray: Ray,
    segment: u32,
    probability: f32,
}

/// True when some branch of the specular trees from `rays` reaches an emitter, or leaves the scene toward an
/// infinite light's radiance, before a diffuse surface.
fn sees_emitter(scene: &Scene, rays: impl Iterator<Item = Ray>, max_depth: u32) -> bool {
    let mut frontier: Vec<Branch> = rays.map(|ray| Branch { ray, segment: 1, probability: 1.0 }).collect();
    for _ in 0..PIXEL_BUDGET {
        // The frontier holds a few branches per primary ray: a scan for the likeliest is cheap.
        let Some(next) =
            (0..frontier.len()).max_by(|&a, &b| frontier[a].probability.total_cmp(&frontier[b].probability))
        else {
            return false;
        };
        let Branch { ray, segment, probability } = frontier.swap_remove(next);
        let Some(hit) = scene.geometry.intersect(&ray) else {
            // A ray that leaves the scene sees the infinite lights.
            if scene.lights.escaped(ray.direction, None) != Rgb::ZERO {
                return true;
            }
            continue;
        };
        if scene.lights.emitted(&hit, ray.direction) != Rgb::ZERO {
            return true;
        }
        // Most surfaces have no delta lobe: a cached flag skips resolving their BSDF, which would find no branch.
        if segment >= max_depth || !scene.material_at(&hit).has_delta() {
            continue;
        }
        let wo = -ray.direction;
        for (s, p) in scene.bsdf(&hit, wo).delta_branches(wo) {
            if s.weight != Rgb::ZERO && probability * p >= MIN_BRANCH_PROBABILITY {
                let ray = Ray::new(offset_origin(hit.p, hit.ng, s.wi), s.wi);
                frontier.push(Branch { ray, segment: segment + 1, probability: probability * p });
            }
        }
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accumulation::LitMask;

    #[test]
    fn the_corner_rays_leave_every_shipped_pinhole_scene_s_mask_as_the_full_test_decides_it() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
        for name in ["cornell.toml", "caustic.toml", "glossy-room.toml", "materials.toml", "outdoor.toml"] {
            let scene = Scene::load(&dir.join(name)).unwrap();
            let plain = plain_pixels(&scene).expect("a pinhole camera");
            let skipped = plain.iter().filter(|&&p| p).count();
            let mask =
                |flags| LitMask::from_flags(scene.camera.width, scene.camera.height, flags, 0).with_neighbours_lit();
            let fast = mask(lit_pixels(&scene, 12));
            let full = mask(decided(&scene, 12, None));
            assert_eq!(fast, full, "{name}");
            // Corner rays first traced every second pixel corner, as on a large image: the same mask, and the
            // same plain pixels but where a block's corners missed what its pixels' corners see.
            let strided = plain_pixels_with_stride(&scene, CORNER_STRIDE).unwrap();
            assert_eq!(mask(decided(&scene, 12, Some(strided.clone()))), full, "{name}, strided");
            let same = strided.iter().zip(&plain).filter(|(a, b)| a == b).count();
            assert!(same > plain.len() * 99 / 100, "{name}: {same} of {} pixels classed alike", plain.len());
            // The shortcut must actually skip pixels, or this test checks nothing.
            assert!(skipped > scene.camera.pixel_count() / 4, "{name}: {skipped} pixels skipped");
        }
    }

    #[test]
    fn delta_branches_of_glass_are_a_reflection_and_a_refraction_whose_probabilities_add_to_one() {
        use crate::geometry::SurfaceHit;
        use crate::material::{Material, Surface};
        use crate::spectrum::RefractiveIndex;
        use crate::texture::Texture;
        use glam::{Vec2, Vec3};
        let glass = Material::two_sided(Surface::Dielectric {
            ior: RefractiveIndex::constant(1.5),
            ext_ior: RefractiveIndex::constant(1.0),
            anti_reflection: false,
        });
        let hit = SurfaceHit { t: 1.0, p: Vec3::ZERO, ng: Vec3::Z, ns: Vec3::Z, object: 0, triangle: u32::MAX };
        let wo = Vec3::new(0.3, 0.0, 1.0).normalize();
        let b = glass.bsdf(&hit, Vec2::ZERO, wo).delta_branches(wo);
        assert_eq!(b.len(), 2);
        assert!((b[0].1 + b[1].1 - 1.0).abs() < 1e-6);
        assert!(b[0].0.wi.z > 0.0 && b[1].0.wi.z < 0.0, "reflected up, refracted down");
        let diffuse = Material::two_sided(Surface::Diffuse { reflectance: Texture::Constant(Rgb::ONE) });
        assert!(diffuse.bsdf(&hit, Vec2::ZERO, wo).delta_branches(wo).is_empty());
    }
}
