//! Same seed, same settings, one thread: bit-identical sums; another seed: different noise.

use crate::common::{settings, shipped};
use photonfarm::render::{Engine, Method};

#[test]
fn two_single_thread_runs_with_the_same_seed_give_bit_identical_sums() {
    let sc = shipped("caustic.toml");
    for method in [Method::Pbpm, Method::Path] {
        let run = |seed: u64| {
            let mut e = Engine::new(&sc, settings(&sc, method, seed));
            for _ in 0..3 {
                e.run_phase();
            }
            (e.sums().clone(), e.totals())
        };
        // Independent single-threaded engines, run side by side: this file's one test would otherwise leave a
        // core idle.
        let [(a, ta), (b, tb), (c, _)] =
            std::thread::scope(|s| [42, 42, 43].map(|seed| s.spawn(move || run(seed))).map(|h| h.join().unwrap()));
        assert_eq!(ta, tb);
        let bits = |s: &photonfarm::accumulation::Accumulator| -> Vec<u64> {
            s.pixels
                .iter()
                .flat_map(|p| p.sum.iter().flatten().chain(p.sum_sq.iter()).map(|v| v.to_bits()).collect::<Vec<_>>())
                .collect()
        };
        assert!(bits(&a) == bits(&b), "{method:?}: same seed, different sums");
        assert!(bits(&a) != bits(&c), "{method:?}: the seed does not reach the random streams");
    }
}
