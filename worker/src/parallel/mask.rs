//! Random, balanced masks of square tiles (paper §4.1): every pixel in exactly one mask per deal, group sizes
//! within one tile of each other, a new random deal every round.

use photonfarm::sampling::{Pass, Sampler};

/// Deals the tiles of a `width` × `height` image into `groups` masks at random. Each mask lists its pixels
/// (row-major image indices) tile by tile, so a group's threads walk memory tile-coherently.
pub fn deal(width: u32, height: u32, tile: u32, groups: usize, seed: u64, deal_index: u64) -> Vec<Vec<u32>> {
    assert!(groups > 0 && tile > 0);
    let (tx, ty) = (width.div_ceil(tile), height.div_ceil(tile));
    let mut tiles: Vec<u32> = (0..tx * ty).collect();
    // Fisher–Yates with the job's random stream for this deal.
    let mut s = Sampler::new(seed, Pass::Camera, deal_index, u64::MAX);
    for i in (1..tiles.len()).rev() {
        let j = ((s.next_f32() * (i + 1) as f32) as usize).min(i);
        tiles.swap(i, j);
    }
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
    fn successive_deals_differ() {
        assert_ne!(deal(256, 256, 32, 4, 1, 1), deal(256, 256, 32, 4, 1, 2));
        assert_eq!(deal(256, 256, 32, 4, 1, 1), deal(256, 256, 32, 4, 1, 1));
    }
}
