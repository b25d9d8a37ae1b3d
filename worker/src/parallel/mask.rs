//! Random, balanced masks of square tiles (paper §4.1): every pixel in exactly one mask per deal, group sizes
//! within one tile of each other, a new random deal every round.

use photonfarm::render::ActiveTiles;
use photonfarm::sampling::{Pass, Sampler};

/// Units (tiles or their quarters) a deal of active tiles aims for per group, so that the groups' pixel counts
/// stay within a small fraction of each other when few tiles are left.
const UNITS_PER_GROUP: usize = 4;

/// Deals the tiles of a `width` × `height` image into `groups` masks at random. Each mask lists its pixels
/// (row-major image indices) tile by tile, so a group's threads walk memory tile-coherently.
pub fn deal(width: u32, height: u32, tile: u32, groups: usize, seed: u64, deal_index: u64) -> Vec<Vec<u32>> {
    assert!(groups > 0 && tile > 0);
    let (tx, ty) = (width.div_ceil(tile), height.div_ceil(tile));
    let mut tiles: Vec<u32> = (0..tx * ty).collect();
    Sampler::new(seed, Pass::Camera, deal_index, u64::MAX).shuffle(&mut tiles);
    let mut masks = vec![Vec::new(); groups];
    for (k, t) in tiles.iter().enumerate() {
        let (x0, y0) = ((t % tx) * tile, (t / tx) * tile);
        let mask = &mut masks[k % groups];
        for y in y0..(y0 + tile).min(height) {
            for x in x0..(x0 + tile).min(width) {
                mask.push(y * width + x);
            }
        }
    }
    masks
}

/// Deals the active tiles of `tiles` into `groups` masks: the tiles (quartered until there are
/// `UNITS_PER_GROUP` units per group, or single pixels) in a random order, each to the group with the fewest
/// pixels so far, so the groups' work stays balanced to within one unit however few tiles are active.
pub fn deal_tiles(tiles: &ActiveTiles, groups: usize, seed: u64, deal_index: u64) -> Vec<Vec<u32>> {
    assert!(groups > 0);
    // Rectangles: first column, first row, width, height.
    let mut units: Vec<(u32, u32, u32, u32)> =
        (0..tiles.len()).filter(|&t| tiles.is_active(t)).map(|t| tiles.rect(t)).collect();
    while units.len() < UNITS_PER_GROUP * groups && units.iter().any(|&(_, _, w, h)| w > 1 || h > 1) {
        units = units
            .into_iter()
            .flat_map(|(x, y, w, h)| {
                let (w0, h0) = (w.div_ceil(2), h.div_ceil(2));
                [(x, y, w0, h0), (x + w0, y, w - w0, h0), (x, y + h0, w0, h - h0), (x + w0, y + h0, w - w0, h - h0)]
            })
            .filter(|&(_, _, w, h)| w > 0 && h > 0)
            .collect();
    }
    Sampler::new(seed, Pass::Camera, deal_index, u64::MAX).shuffle(&mut units);
    let mut masks = vec![Vec::new(); groups];
    for (x0, y0, w, h) in units {
        let mask = masks.iter_mut().min_by_key(|m| m.len()).expect("at least one group");
        for y in y0..y0 + h {
            mask.extend((x0..x0 + w).map(|x| y * tiles.width + x));
        }
    }
    masks
}

/// Every pixel of the image, for methods without masks.
pub fn whole_image(width: u32, height: u32) -> Vec<u32> {
    (0..width * height).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_pixel_is_in_exactly_one_mask_per_deal() {
        for (w, h, tile, groups) in [(64, 48, 32, 2), (100, 37, 8, 5), (256, 256, 32, 8), (7, 7, 32, 3)] {
            let masks = deal(w, h, tile, groups, 9, 4);
            let mut seen = vec![0u8; (w * h) as usize];
            for m in &masks {
                for &p in m {
                    seen[p as usize] += 1;
                }
            }
            assert!(seen.iter().all(|&c| c == 1), "{w}x{h} tile {tile} groups {groups}");
        }
    }

    #[test]
    fn deals_are_balanced_to_within_one_tile() {
        let masks = deal(256, 256, 32, 3, 1, 1);
        let tiles: Vec<usize> = masks.iter().map(|m| m.len() / (32 * 32)).collect();
        assert!(tiles.iter().max().unwrap() - tiles.iter().min().unwrap() <= 1, "{tiles:?}");
    }

    #[test]
    fn deals_of_active_tiles_cover_each_active_pixel_once_and_stay_balanced() {
        let flags: Vec<bool> = (0..12).map(|t| t % 5 == 1).collect();
        let tiles = ActiveTiles::from_flags(100, 70, 32, flags).unwrap();
        let active: std::collections::BTreeSet<u32> = tiles.active_pixels().into_iter().collect();
        for groups in [1, 2, 3, 5] {
            let masks = deal_tiles(&tiles, groups, 3, 7);
            let mut all: Vec<u32> = masks.iter().flatten().copied().collect();
            all.sort_unstable();
            assert_eq!(all, active.iter().copied().collect::<Vec<_>>(), "{groups} groups");
            let sizes: Vec<usize> = masks.iter().map(Vec::len).collect();
            let (lo, hi) = (*sizes.iter().min().unwrap(), *sizes.iter().max().unwrap());
            // Three active tiles quartered to at least four units per group: within one quarter tile (256 px).
            assert!(hi - lo <= 256 && lo > 0, "{groups} groups: {sizes:?}");
        }
        // One active tile of one pixel and more groups than pixels: the others get nothing, none a pixel twice.
        let one = ActiveTiles::from_flags(3, 1, 1, vec![false, true, false]).unwrap();
        assert_eq!(deal_tiles(&one, 2, 1, 1).concat(), vec![1]);
    }

    #[test]
    fn successive_deals_differ() {
        assert_ne!(deal(256, 256, 32, 4, 1, 1), deal(256, 256, 32, 4, 1, 2));
        assert_eq!(deal(256, 256, 32, 4, 1, 1), deal(256, 256, 32, 4, 1, 1));
    }
}
