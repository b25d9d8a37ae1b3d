//! Compares two multi-layer EXRs written by `coordinator render`: per layer, the mean luminance of each and
//! the relative RMSE of their 8×8-pixel block averages (block averages suppress the noise of short runs).
//!
//! `cargo run --release -p photonfarm --example compare_images -- A.exr B.exr`

use photonfarm::image_io::exr_file::{find_layer, read_exr};
use photonfarm::render::images::luminance_of;
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<PathBuf> = std::env::args_os().skip(1).map(PathBuf::from).collect();
    if args.len() != 2 {
        return Err("usage: compare_images A.exr B.exr".into());
    }
    let a = read_exr(&args[0])?;
    let b = read_exr(&args[1])?;
    for name in ["visible_lights", "direct", "indirect", "caustic", "total"] {
        let (la, lb) = (find_layer(&a, &args[0], name)?, find_layer(&b, &args[1], name)?);
        let block = 8;
        let (bw, bh) = (la.width / block, la.height / block);
        let (mut num, mut den, mut sa, mut sb) = (0.0, 0.0, 0.0, 0.0);
        for by in 0..bh {
            for bx in 0..bw {
                let (mut ma, mut mb) = (0.0, 0.0);
                for y in by * block..(by + 1) * block {
                    for x in bx * block..(bx + 1) * block {
                        ma += luminance_of(la.get(x, y));
                        mb += luminance_of(lb.get(x, y));
                    }
                }
                num += (ma - mb) * (ma - mb);
                den += mb * mb;
                sa += ma;
                sb += mb;
            }
        }
        let n = (la.width * la.height) as f64;
        println!(
            "{name:>15}: mean A {:.5}  mean B {:.5}  ratio {:.4}  block rel. RMSE {:.4}",
            sa / n,
            sb / n,
            sa / sb.max(1e-30),
            (num / den.max(1e-30)).sqrt()
        );
    }
    Ok(())
}
