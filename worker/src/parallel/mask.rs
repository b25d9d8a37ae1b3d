//! Random, balanced masks of square tiles (paper §4.1): every pixel in exactly one mask per deal, group sizes
//! within one tile of each other, a new random deal every round.

use photonfarm::render::ActiveTiles;
use photonfarm::sampling::{Pass, Sampler};

/// Units (tiles or their quarters) a deal of active tiles aims for per group, so that the groups' pixel counts
/// stay within a small fraction of each other when few tiles are left.
const UNITS_PER_GROUP: usize = 4;

/// Puts `items` in a random order drawn from `sampler` (Fisher–Yates), the job's stream for a deal.
fn shuffle<T>(items: &mut [T], sampler: &mut Sampler) {
    for i in (1..items.len()).rev() {
        let j = ((sampler.next_f32() * (i + 1) as f32) as usize).min(i);
        items.swap(i, j);
    }
}

/// Deals the tiles of a `width` × `height` image into `groups` masks at random. Each mask lists its pixels
/// (row-major image indices) tile by tile, so a group's threads walk memory tile-coherently.
pub fn deal(width: u32, height: u32, tile: u32, groups: usize, seed: u64, deal_index: u64) -> Vec<Vec<u32>> {
    assert!(groups > 0 && tile > 0);
    let (tx, ty) = (width.div_ceil(tile), height.div_ceil(tile));
    let mut tiles: Vec<u32> = (0..tx * ty).collect();
    shuffle(&mut tiles, &mut Sampler::new(seed, Pass::Camera, deal_index, u64::MAX));
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
    shuffle(&mut units, &mut Sampler::new(seed, Pass::Camera, deal_index, u64::MAX));
    let mut masks = vec![Vec::new(); groups];
    for (x0, y0, w, h) in units {
        let mask = masks.iter_mut().min_by_key(|m| m.len()).expect("at least one group");
        for y in y0..y0 + h {
            mask.extend((x0..x0 + w).map(|x| y * tiles.width + x));
        }
    }
    masks
}

/// The active tiles of `tiles` that a capped round renders: those with the fewest phases (a tile's phases being
/// its pixels' fewest, `phases` of an image pixel), ties in a random order, as many as fit in `max_pixels` and at
/// least one. None when every active tile fits, so that the round renders them all as without a cap.
pub fn fewest_phases_first(
    tiles: &ActiveTiles,
    phases: impl Fn(u32) -> u32,
    max_pixels: usize,
    seed: u64,
    deal_index: u64,
) -> Option<ActiveTiles> {
    let area = |t: usize| {
        let (_, _, w, h) = tiles.rect(t);
        (w * h) as usize
    };
    let mut order: Vec<usize> = (0..tiles.len()).filter(|&t| tiles.is_active(t)).collect();
    if order.iter().map(|&t| area(t)).sum::<usize>() <= max_pixels {
        return None;
    }
    // Shuffled, then sorted stably by phases: ties fall in a random order, so that no tile is always left for
    // the next round. A stream of its own leaves `deal_tiles`'s draws as they are without a cap.
    shuffle(&mut order, &mut Sampler::new(seed, Pass::Camera, deal_index, u64::MAX - 1));
    let mut keyed: Vec<(u32, usize)> =
        order.into_iter().map(|t| (tiles.pixels_of(t).map(&phases).min().unwrap_or(0), t)).collect();
    keyed.sort_by_key(|&(n, _)| n);
    let mut flags = vec![false; tiles.len()];
    let mut taken = 0;
    for (_, t) in keyed {
        if taken > 0 && taken + area(t) > max_pixels {
            break;
        }
        flags[t] = true;
        taken += area(t);
    }
    Some(ActiveTiles::from_flags(tiles.width, tiles.height, tiles.tile, flags).expect("the same image's tiles"))
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
    fn a_capped_round_takes_the_tiles_with_the_fewest_phases_and_breaks_ties_at_random() {
        // 100 × 70 in 32-pixel tiles: 4 × 3 tiles, the right column 4 and the bottom row 6 pixels short.
        let all = ActiveTiles::all(100, 70, 32).unwrap();
        assert_eq!(fewest_phases_first(&all, |_| 0, 7000, 1, 1), None, "every tile fits");
        // Tile t = column + 4 × row has t mod 3 phases: 0, 3, 6 and 9 have none, and hold 1024 + 128 + 1024 +
        // 192 = 2368 pixels, which fit in 2400 where no other tile fits beside them.
        let phases = |p: u32| ((p % 100) / 32 + 4 * ((p / 100) / 32)) % 3;
        let capped = fewest_phases_first(&all, phases, 2400, 1, 1).unwrap();
        let chosen: Vec<usize> = (0..all.len()).filter(|&t| capped.is_active(t)).collect();
        assert_eq!(chosen, vec![0, 3, 6, 9]);
        // Ties go another way in another deal, the same way for the same seed and deal.
        let sets: std::collections::BTreeSet<Vec<bool>> =
            (0..20).map(|d| fewest_phases_first(&all, phases, 1024, 1, d).unwrap().flags().to_vec()).collect();
        assert!(sets.len() > 1);
        assert_eq!(fewest_phases_first(&all, phases, 1024, 1, 3), fewest_phases_first(&all, phases, 1024, 1, 3));
        // Retired tiles are never taken, and a cap below one tile still renders one.
        let some = ActiveTiles::from_flags(100, 70, 32, (0..12).map(|t| t >= 6).collect()).unwrap();
        let one = fewest_phases_first(&some, |_| 0, 10, 2, 2).unwrap();
        assert_eq!(one.active_count(), 1);
        assert!((6..12).any(|t| one.is_active(t)));
    }

    #[test]
    fn successive_deals_differ() {
        assert_ne!(deal(256, 256, 32, 4, 1, 1), deal(256, 256, 32, 4, 1, 2));
        assert_eq!(deal(256, 256, 32, 4, 1, 1), deal(256, 256, 32, 4, 1, 1));
    }
}
