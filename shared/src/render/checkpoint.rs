//! Checkpoints: the merged sums of a run with what is needed to continue it (`coordinator render --resume`),
//! written atomically beside the image so that a crash loses at most the phases since the last one.

use super::method::Method;
use super::record::HistoryEntry;
use super::settings::RenderSettings;
use super::totals::RayTotals;
use crate::accumulation::delta::{apply_delta, encode_delta, Compression};
use crate::accumulation::{Accumulator, AuxLayout};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// 2: the sums' auxiliary layers (the ghost layer) are kept. 3: the settings hold the spectral-output bands.
/// 4: the totals count the light paths counted against photon maps. 5: the sums keep their replicates.
const FORMAT: u32 = 5;

/// Everything a resumed run continues from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Checkpoint {
    pub format: u32,
    pub scene_hash: String,
    pub width: u32,
    pub height: u32,
    pub method: Method,
    pub settings: RenderSettings,
    /// Sessions of this run so far (the first run is session 1); a resumed run draws from new streams.
    pub session: u32,
    /// Rendering time of every session so far, seconds.
    pub elapsed_s: f64,
    pub totals: RayTotals,
    pub history: Vec<HistoryEntry>,
    /// The auxiliary layers of the sums.
    pub aux: AuxLayout,
    /// The sums, as an exact delta from zero (see `accumulation::delta`).
    sums: Vec<u8>,
}

/// Why a checkpoint cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    #[error("cannot read the checkpoint {path}: {source}")]
    Read { path: String, source: std::io::Error },
    #[error("cannot write the checkpoint {path}: {source}")]
    Write { path: String, source: std::io::Error },
    #[error("{path} is not a photonfarm checkpoint of this version: {reason}")]
    Format { path: String, reason: String },
}

impl Checkpoint {
    /// A checkpoint of `sums` with the run's state.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        sums: &Accumulator,
        scene_hash: &str,
        method: Method,
        settings: RenderSettings,
        session: u32,
        elapsed_s: f64,
        totals: RayTotals,
        history: &[HistoryEntry],
    ) -> Self {
        let zero = Accumulator::with_aux(sums.width, sums.height, sums.aux.layout().clone());
        Checkpoint {
            format: FORMAT,
            scene_hash: scene_hash.into(),
            width: sums.width,
            height: sums.height,
            method,
            settings,
            session,
            elapsed_s,
            totals,
            history: history.to_vec(),
            aux: sums.aux.layout().clone(),
            sums: encode_delta(sums, &zero, Compression::Small),
        }
    }

    /// The sums it holds.
    pub fn sums(&self) -> Result<Accumulator, String> {
        let mut a = Accumulator::with_aux(self.width, self.height, self.aux.clone());
        apply_delta(&self.sums, &mut a).map_err(|e| e.to_string())?;
        Ok(a)
    }

    /// Writes the checkpoint atomically (a temporary file renamed over the old one).
    pub fn save(&self, path: &Path) -> Result<(), CheckpointError> {
        let err = |source| CheckpointError::Write { path: path.display().to_string(), source };
        let bytes = bincode::serde::encode_to_vec(self, bincode::config::standard())
            .map_err(|e| err(std::io::Error::other(e.to_string())))?;
        let tmp = path.with_extension("tmp");
        std::fs::write(&tmp, bytes).map_err(err)?;
        std::fs::rename(&tmp, path).map_err(err)
    }

    /// Reads and checks a checkpoint.
    pub fn load(path: &Path) -> Result<Self, CheckpointError> {
        let p = path.display().to_string();
        let bytes = std::fs::read(path).map_err(|source| CheckpointError::Read { path: p.clone(), source })?;
        let (c, _): (Checkpoint, usize) = bincode::serde::decode_from_slice(&bytes, bincode::config::standard())
            .map_err(|e| CheckpointError::Format { path: p.clone(), reason: e.to_string() })?;
        if c.format != FORMAT {
            return Err(CheckpointError::Format {
                path: p,
                reason: format!("format {} (expected {FORMAT})", c.format),
            });
        }
        c.sums().map_err(|reason| CheckpointError::Format { path: p, reason })?;
        Ok(c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::color::Rgb;
    use crate::render::Estimator;

    #[test]
    fn a_checkpoint_gives_back_its_sums_and_auxiliary_layers_exactly() {
        let ghost = AuxLayout::new(vec![crate::accumulation::AuxLayer { name: "ghost".into(), channels: 3 }]);
        let mut a = Accumulator::with_aux(8, 4, ghost);
        for i in 0..32 {
            a.add_phase(i, &[Rgb::splat(i as f32 * 0.1), Rgb::ONE, Rgb::ZERO, Rgb::splat(0.3)], 1, i % 4);
            a.aux.add_phase(i, &[0.01 * i as f32, 0.5, 0.25]);
        }
        let settings = RenderSettings {
            estimator: Estimator::Pbpm,
            seed: 1,
            max_depth: 8,
            backward_diffuse_depth: 2,
            radius_scale: 3.0,
            radius_alpha: 2.0 / 3.0,
            light_paths_per_pixel: 1.0,
            spectral_bands: 0,
        };
        // History with and without a true error: bincode cannot skip a field, so every one must round-trip.
        let history = [
            HistoryEntry { phase: 1, time_s: 0.5, delta_all: 0.2, ..HistoryEntry::default() },
            HistoryEntry {
                phase: 2,
                time_s: 1.0,
                true_all: Some(0.1),
                true_unlit: Some(0.3),
                ..HistoryEntry::default()
            },
        ];
        let c = Checkpoint::new(&a, "abc", Method::ThreeLevel, settings, 1, 2.5, RayTotals::default(), &history);
        let dir = std::env::temp_dir().join(format!("pf-checkpoint-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("checkpoint.bin");
        c.save(&path).unwrap();
        let back = Checkpoint::load(&path).unwrap();
        assert_eq!(back, c);
        assert_eq!(back.sums().unwrap(), a, "the sums and their ghost layer");
        std::fs::write(&path, b"garbage").unwrap();
        assert!(matches!(Checkpoint::load(&path), Err(CheckpointError::Format { .. })));
    }
}
