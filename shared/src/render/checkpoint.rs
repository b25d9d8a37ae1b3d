//! Checkpoints: the merged sums of a run with what is needed to continue it (`coordinator render --resume`),
//! written atomically beside the image so that a crash loses at most the phases since the last one. The file
//! ends with a CRC-32 of its content, so that a damaged one is refused rather than continued from, and each save
//! keeps the checkpoint it replaces beside it (`previous_path`), so that a damaged latest one costs at most one
//! save interval.

use super::method::Method;
use super::record::HistoryEntry;
use super::settings::RenderSettings;
use super::totals::RayTotals;
use crate::accumulation::delta::{apply_delta, encode_whole_in_pieces, max_delta_bytes, Compression};
use crate::accumulation::{Accumulator, AuxLayout};
use crate::scene::Scene;
use serde::{Deserialize, Serialize};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

/// 2: the sums' auxiliary layers (the ghost layer) are kept. 3: the settings hold the spectral-output bands.
/// 4: the totals count the light paths counted against photon maps. 5: the sums keep their replicates.
/// 6: the history says how many tiles each step rendered. 7: the sums keep the photon discs' blur layers, and
/// the history the blur's part of δ. 8: the settings say whether the run chose the camera paths' diffuse depth,
/// and the history which depth each step had. 9: the file ends with a CRC-32 of what comes before it. 10: the
/// sums follow the state as deltas of consecutive pieces of the image, each after its length in bytes.
const FORMAT: u32 = 10;

/// Pixels per piece of a checkpoint's sums: one piece's delta (about 12 MB raw) is all that saving or loading
/// holds at a time besides the sums themselves, so a large image's checkpoint costs no second image.
const PIECE_PIXELS: usize = 1 << 16;

/// Bytes of the CRC-32 that ends the file.
const CHECKSUM_BYTES: usize = 4;

/// Everything a resumed run continues from besides its sums, which follow it in the file (`save`, `load`).
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
}

/// A writer that passes its bytes on and keeps their CRC-32.
struct CrcWriter<W> {
    inner: W,
    crc: crc32fast::Hasher,
}

impl<W: Write> Write for CrcWriter<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.crc.update(&buf[..n]);
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

/// Why a checkpoint cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    #[error("cannot read the checkpoint {path}: {source}")]
    Read { path: String, source: std::io::Error },
    #[error("cannot write the checkpoint {path}: {source}")]
    Write { path: String, source: std::io::Error },
    #[error("the checkpoint {path} was not written: the run stopped meanwhile")]
    Abandoned { path: String },
    #[error("{path} is not a photonfarm checkpoint of this version: {reason}")]
    Format { path: String, reason: String },
    #[error("{path} is {size} bytes, more than a checkpoint of this scene can be ({max} bytes): it is corrupt or not a checkpoint")]
    TooLarge { path: String, size: u64, max: u64 },
    #[error("{path} does not belong to this scene: {reason}")]
    OtherScene { path: String, reason: String },
    #[error(
        "{path} is damaged: its content does not match the checksum it was saved with (a bit changed on the disk \
         or in a copy), so none of it is used{}",
        previous.as_ref().map_or(String::new(), |p| format!(
            ". The checkpoint saved before it, {p}, is at most one save interval older: resume from it with \
             --resume {p}"
        ))
    )]
    Damaged { path: String, previous: Option<String> },
}

/// Bytes a checkpoint may hold beside its sums (settings, counters and the δ history, which grows by one small
/// entry per merge): generous for runs of days.
const MAX_STATE_BYTES: u64 = 64 << 20;

/// bincode's limit on what one checkpoint may claim to hold, so that a forged length cannot make the decoder
/// allocate more than this; the file's size is checked against the scene's own bound first.
const DECODE_LIMIT: usize = u32::MAX as usize;

fn decode_config() -> impl bincode::config::Config {
    bincode::config::standard().with_limit::<DECODE_LIMIT>()
}

impl Checkpoint {
    /// The state of a run whose sums are `sums` (their size and layers), to be saved with them.
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
        }
    }

    /// Writes the state and `sums` (of the size and layers `new` was given) atomically (a temporary file,
    /// flushed to the disk, renamed over the old one), with its CRC-32 at the end; the checkpoint it replaces
    /// becomes `previous_path(path)`. A checkpoint exists at `path` at every moment, the old one or the new one.
    pub fn save(&self, path: &Path, sums: &Accumulator) -> Result<(), CheckpointError> {
        self.write(path, sums, Compression::Small, &AtomicBool::new(false))
    }

    /// `save` for a periodic save: abandoned (`CheckpointError::Abandoned`, leaving the checkpoint at `path` as
    /// it was) once `stop` is set, as the run's final save follows at once, and compressed in zstd's fast mode,
    /// so that it holds the sums, which merges wait for, a shorter time for a somewhat larger file.
    pub fn save_unless(&self, path: &Path, sums: &Accumulator, stop: &AtomicBool) -> Result<(), CheckpointError> {
        self.write(path, sums, Compression::Fast, stop)
    }

    fn write(
        &self,
        path: &Path,
        sums: &Accumulator,
        compression: Compression,
        stop: &AtomicBool,
    ) -> Result<(), CheckpointError> {
        assert!(
            (sums.width, sums.height) == (self.width, self.height) && *sums.aux.layout() == self.aux,
            "a checkpoint saved with sums of another image"
        );
        let err = |source| CheckpointError::Write { path: path.display().to_string(), source };
        let tmp = path.with_extension("tmp");
        // Encoded piece by piece straight into the file, its CRC-32 taken on the way: a large image's checkpoint
        // never holds a second image in memory.
        let file = std::fs::File::create(&tmp).map_err(err)?;
        let mut out =
            CrcWriter { inner: std::io::BufWriter::with_capacity(1 << 20, file), crc: crc32fast::Hasher::new() };
        bincode::serde::encode_into_std_write(self, &mut out, bincode::config::standard())
            .map_err(|e| err(std::io::Error::other(e.to_string())))?;
        let pieces = encode_whole_in_pieces(sums, PIECE_PIXELS, compression, |piece| {
            if stop.load(Ordering::Relaxed) {
                return Err(None);
            }
            out.write_all(&(piece.len() as u32).to_le_bytes()).and_then(|()| out.write_all(piece)).map_err(Some)
        });
        match pieces {
            Ok(()) => {}
            Err(Some(e)) => return Err(err(e)),
            Err(None) => {
                drop(out);
                let _ = std::fs::remove_file(&tmp);
                return Err(CheckpointError::Abandoned { path: path.display().to_string() });
            }
        }
        let CrcWriter { mut inner, crc } = out;
        inner.write_all(&crc.finalize().to_le_bytes()).map_err(err)?;
        let file = inner.into_inner().map_err(|e| err(e.into_error()))?;
        file.sync_all().map_err(err)?;
        if path.exists() {
            // Linked (or copied where links are not allowed), then renamed, so that the previous checkpoint is
            // also always whole.
            let previous = previous_path(path);
            let previous_tmp = previous.with_extension("tmp");
            let _ = std::fs::remove_file(&previous_tmp);
            std::fs::hard_link(path, &previous_tmp)
                .or_else(|_| std::fs::copy(path, &previous_tmp).map(|_| ()))
                .and_then(|()| std::fs::rename(&previous_tmp, &previous))
                .map_err(|source| CheckpointError::Write { path: previous.display().to_string(), source })?;
        }
        std::fs::rename(&tmp, path).map_err(err)
    }

    /// The most memory a save holds besides the sums, for sums with the auxiliary layers `layout`: one piece's
    /// delta, raw and compressed, and the file's buffer.
    pub fn max_save_bytes(layout: &AuxLayout) -> u64 {
        2 * max_delta_bytes(PIECE_PIXELS as u64, layout) + (1 << 20)
    }

    /// The largest checkpoint file `scene` can have: its sums with every auxiliary layer a run of it may keep,
    /// in incompressible pieces, and the rest of the run's state.
    pub fn max_file_bytes(scene: &Scene) -> u64 {
        let widest = AuxLayout::for_scene(scene, crate::spectrum::MAX_BANDS);
        let pixels = scene.camera.width as u64 * scene.camera.height as u64;
        let pieces = pixels.div_ceil(PIECE_PIXELS as u64);
        pieces * (4 + max_delta_bytes(PIECE_PIXELS as u64, &widest)) + MAX_STATE_BYTES
    }

    /// Reads a checkpoint of `scene` and its sums, and checks it: its size against what the scene can have
    /// before reading it, then its format, the scene's hash, the image size and the auxiliary layers before its
    /// sums are decoded, so a corrupt or foreign file costs no more memory than the scene's own image.
    pub fn load(path: &Path, scene: &Scene) -> Result<(Self, Accumulator), CheckpointError> {
        let p = path.display().to_string();
        let read_err = |source| CheckpointError::Read { path: p.clone(), source };
        let file = std::fs::File::open(path).map_err(read_err)?;
        let size = file.metadata().map_err(read_err)?.len();
        let max = Self::max_file_bytes(scene);
        if size > max {
            return Err(CheckpointError::TooLarge { path: p, size, max });
        }
        let mut bytes = Vec::with_capacity(size as usize);
        // `take` keeps a file that grows while it is read within the bound.
        file.take(max + 1).read_to_end(&mut bytes).map_err(read_err)?;
        Self::from_bytes(&bytes, scene, &p).map_err(|e| match e {
            CheckpointError::Damaged { path: damaged, .. } => {
                let previous = previous_path(path);
                let previous = (previous != path && previous.is_file()).then(|| previous.display().to_string());
                CheckpointError::Damaged { path: damaged, previous }
            }
            e => e,
        })
    }

    /// Checks and decodes the bytes of a checkpoint of `scene` and its sums (`path` names it in errors), in the
    /// order `load` gives.
    pub fn from_bytes(bytes: &[u8], scene: &Scene, path: &str) -> Result<(Self, Accumulator), CheckpointError> {
        let max = Self::max_file_bytes(scene);
        if bytes.len() as u64 > max {
            return Err(CheckpointError::TooLarge { path: path.into(), size: bytes.len() as u64, max });
        }
        let body = checked_body(bytes).map_err(|damage| match damage {
            Damage::Checksum => CheckpointError::Damaged { path: path.into(), previous: None },
            Damage::Format(reason) => CheckpointError::Format { path: path.into(), reason },
        })?;
        let format = |reason| CheckpointError::Format { path: path.into(), reason };
        let (c, used) = Self::decode_state(body).map_err(format)?;
        c.check_scene(scene).map_err(|reason| CheckpointError::OtherScene { path: path.into(), reason })?;
        let sums = c.decode_sums(&body[used..]).map_err(format)?;
        Ok((c, sums))
    }

    /// The state at the start of a checkpoint's content (after its checksum was checked), with its format
    /// number checked, and the bytes it took.
    fn decode_state(body: &[u8]) -> Result<(Self, usize), String> {
        let (c, used): (Checkpoint, usize) =
            bincode::serde::decode_from_slice(body, decode_config()).map_err(|e| e.to_string())?;
        if c.format != FORMAT {
            return Err(format!("format {} (expected {FORMAT})", c.format));
        }
        Ok((c, used))
    }

    /// The sums from the pieces that follow the state: each piece holds the next pixels of the image, and the
    /// last ends at its last pixel.
    fn decode_sums(&self, mut pieces: &[u8]) -> Result<Accumulator, String> {
        let mut sums = Accumulator::with_aux(self.width, self.height, self.aux.clone());
        let n = sums.pixels.len();
        let mut next = 0;
        while !pieces.is_empty() {
            let (len, rest) = pieces.split_first_chunk::<4>().ok_or("the sums end inside the length of a piece")?;
            let len = u32::from_le_bytes(*len) as usize;
            let piece = rest.get(..len).ok_or_else(|| format!("the piece at pixel {next} runs past the file's end"))?;
            let added = apply_delta(piece, &mut sums).map_err(|e| format!("the sums' piece at pixel {next}: {e}"))?;
            match added.pixels.runs() {
                &[(first, count)] if first as usize == next => next += count as usize,
                _ => return Err(format!("a piece of the sums does not hold the pixels from {next} on")),
            }
            pieces = &rest[len..];
        }
        if next != n {
            return Err(format!("the sums hold {next} of the image's {n} pixels"));
        }
        Ok(sums)
    }

    /// Checks that the checkpoint continues a render of `scene`: the same scene and meshes (their hash), the
    /// same image size, and the auxiliary layers the scene gives with the checkpoint's settings.
    pub fn check_scene(&self, scene: &Scene) -> Result<(), String> {
        if self.scene_hash != scene.hash {
            return Err("it was made from another scene, or the scene or its meshes changed since".into());
        }
        let (w, h) = (scene.camera.width, scene.camera.height);
        if (self.width, self.height) != (w, h) {
            return Err(format!("it holds a {}×{} image, the scene renders {w}×{h}", self.width, self.height));
        }
        if self.settings.spectral_bands > crate::spectrum::MAX_BANDS {
            return Err(format!("it claims {} spectral bands", self.settings.spectral_bands));
        }
        if self.aux != AuxLayout::for_scene(scene, self.settings.spectral_bands) {
            return Err("its auxiliary layers are not the ones this version gives the scene".into());
        }
        Ok(())
    }
}

/// Where a save keeps the checkpoint at `path` that it replaces: `checkpoint-previous.bin` beside
/// `checkpoint.bin`.
pub fn previous_path(path: &Path) -> PathBuf {
    let stem = path.file_stem().map_or_else(|| "checkpoint".into(), |s| s.to_string_lossy().into_owned());
    let name = match path.extension() {
        Some(e) => format!("{stem}-previous.{}", e.to_string_lossy()),
        None => format!("{stem}-previous"),
    };
    path.with_file_name(name)
}

/// Why the bytes of a checkpoint file are not a checkpoint's.
enum Damage {
    /// The content does not match the CRC-32 at the end.
    Checksum,
    /// Not this version's file at all.
    Format(String),
}

/// The content of a checkpoint file, once its CRC-32 matches. A file whose first byte (bincode's encoding of
/// the format number, below 251) names another format is reported as such, not as damaged: versions before 9
/// wrote no checksum.
fn checked_body(bytes: &[u8]) -> Result<&[u8], Damage> {
    let other_format = bytes.first().map(|&b| b as u32).filter(|&f| f < 251 && f != FORMAT);
    if let Some(f) = other_format {
        return Err(Damage::Format(format!("format {f} (expected {FORMAT})")));
    }
    if bytes.len() < CHECKSUM_BYTES {
        return Err(Damage::Format(format!("{} bytes are too few for a checkpoint", bytes.len())));
    }
    let (body, sum) = bytes.split_at(bytes.len() - CHECKSUM_BYTES);
    let sum = u32::from_le_bytes(sum.try_into().expect("four bytes"));
    if crc32fast::hash(body) != sum {
        return Err(Damage::Checksum);
    }
    Ok(body)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::color::Rgb;
    use crate::render::Estimator;

    /// A checkpoint file's state and sums, trusting the image size it names (the tests' own files).
    fn decode(bytes: &[u8]) -> Result<(Checkpoint, Accumulator), String> {
        let body = checked_body(bytes).map_err(|d| match d {
            Damage::Checksum => "its content does not match its checksum".to_string(),
            Damage::Format(reason) => reason,
        })?;
        let (c, used) = Checkpoint::decode_state(body)?;
        Ok((c.clone(), c.decode_sums(&body[used..])?))
    }

    /// The bytes of a checkpoint file of `state` whose sums are `pieces` as they follow the state, with the
    /// checksum that makes them pass as undamaged.
    fn file_of(state: &Checkpoint, pieces: &[u8]) -> Vec<u8> {
        let mut bytes = bincode::serde::encode_to_vec(state, bincode::config::standard()).unwrap();
        bytes.extend_from_slice(pieces);
        let crc = crc32fast::hash(&bytes);
        bytes.extend_from_slice(&crc.to_le_bytes());
        bytes
    }

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
            adaptive_light: true,
            adaptive_depth: true,
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
        let dir = tempfile::Builder::new().prefix("pf-checkpoint-").tempdir().unwrap();
        let path = dir.path().join("checkpoint.bin");
        c.save(&path, &a).unwrap();
        let (back, sums) = decode(&std::fs::read(&path).unwrap()).unwrap();
        assert_eq!(back, c);
        assert_eq!(sums, a, "the sums and their ghost layer");
        assert!(decode(b"garbage").is_err());
    }

    #[test]
    fn an_image_of_several_pieces_comes_back_exactly_and_a_missing_or_misplaced_piece_is_refused() {
        // 300 × 300 pixels: a whole piece and part of another.
        let (scene, _, mut a) = empty_scene_and_checkpoint(300, 300);
        for i in (0..90_000).step_by(7) {
            a.add_phase(i, &[Rgb::splat(i as f32 * 1e-4), Rgb::ONE, Rgb::ZERO, Rgb::splat(0.3)], 1, i % 4);
        }
        let c = Checkpoint::new(
            &a,
            &scene.hash,
            Method::ThreeLevel,
            RenderSettings::for_scene(&scene, Method::ThreeLevel, 1),
            1,
            1.0,
            RayTotals::default(),
            &[],
        );
        let dir = tempfile::Builder::new().prefix("pf-checkpoint-pieces-").tempdir().unwrap();
        let path = dir.path().join("checkpoint.bin");
        c.save(&path, &a).unwrap();
        let (back, sums) = Checkpoint::load(&path, &scene).unwrap();
        assert_eq!((back, sums), (c.clone(), a.clone()));
        let mut pieces = Vec::new();
        encode_whole_in_pieces(&a, PIECE_PIXELS, Compression::Fast, |p| {
            pieces.push(p.to_vec());
            Ok::<_, ()>(())
        })
        .unwrap();
        assert_eq!(pieces.len(), 2);
        let framed = |order: &[usize]| -> Vec<u8> {
            order
                .iter()
                .flat_map(|&k| (pieces[k].len() as u32).to_le_bytes().into_iter().chain(pieces[k].clone()))
                .collect()
        };
        assert_eq!(Checkpoint::from_bytes(&file_of(&c, &framed(&[0, 1])), &scene, "whole").unwrap().1, a);
        for (order, says) in [
            (&[0][..], "hold 65536 of the image's 90000 pixels"),
            (&[1, 0][..], "from 0 on"),
            (&[0, 0][..], "from 65536 on"),
            (&[][..], "hold 0 of"),
        ] {
            let e = Checkpoint::from_bytes(&file_of(&c, &framed(order)), &scene, "cut").unwrap_err();
            assert!(matches!(e, CheckpointError::Format { .. }) && e.to_string().contains(says), "{order:?}: {e}");
        }
        let mut cut = framed(&[0, 1]);
        cut.truncate(cut.len() - 10);
        let e = Checkpoint::from_bytes(&file_of(&c, &cut), &scene, "cut").unwrap_err().to_string();
        assert!(e.contains("runs past the file's end"), "{e}");
    }

    /// A scene of `width` × `height` pixels with nothing in it but a light, and its checkpoint with no phase and
    /// those sums.
    fn empty_scene_and_checkpoint(width: u32, height: u32) -> (Scene, Checkpoint, Accumulator) {
        let text = format!(
            r#"
[camera]
type = "pinhole"
position = [0.0, 0.0, 5.0]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
fov_y_deg = 40.0
width = {width}
height = {height}

[materials.white]
type = "diffuse"
albedo = [0.5, 0.5, 0.5]

[[objects]]
material = "white"
emission = [1.0, 1.0, 1.0]
quad = {{ corner = [-1.0, -1.0, 0.0], edge1 = [2.0, 0.0, 0.0], edge2 = [0.0, 2.0, 0.0] }}
"#
        );
        let scene = Scene::from_toml(&text, Path::new("test.toml"), Path::new(".")).unwrap();
        let settings = RenderSettings::for_scene(&scene, Method::ThreeLevel, 1);
        let sums = Accumulator::with_aux(width, height, AuxLayout::for_scene(&scene, 0));
        let c = Checkpoint::new(&sums, &scene.hash, Method::ThreeLevel, settings, 1, 1.0, RayTotals::default(), &[]);
        (scene, c, sums)
    }

    #[test]
    fn a_checkpoint_of_another_scene_or_size_is_refused_before_its_sums_are_decoded() {
        let dir = tempfile::Builder::new().prefix("pf-checkpoint-scene-").tempdir().unwrap();
        let path = dir.path().join("checkpoint.bin");
        let (scene, c, sums) = empty_scene_and_checkpoint(8, 4);
        c.save(&path, &sums).unwrap();
        assert_eq!(Checkpoint::load(&path, &scene).unwrap().0, c);
        let (other, _, _) = empty_scene_and_checkpoint(8, 5);
        let e = Checkpoint::load(&path, &other).unwrap_err();
        assert!(matches!(e, CheckpointError::OtherScene { .. }), "{e}");
        // The image size as read is checked against the scene before anything of that size is allocated.
        let mut huge = c.clone();
        (huge.width, huge.height) = (1 << 30, 1 << 30);
        std::fs::write(&path, file_of(&huge, &[])).unwrap();
        let e = Checkpoint::load(&path, &scene).unwrap_err().to_string();
        assert!(e.contains("1073741824×1073741824 image"), "{e}");
        let mut foreign = c.clone();
        foreign.scene_hash = "0".repeat(64);
        foreign.save(&path, &sums).unwrap();
        assert!(matches!(Checkpoint::load(&path, &scene), Err(CheckpointError::OtherScene { .. })));
        std::fs::write(&path, b"garbage").unwrap();
        assert!(matches!(Checkpoint::load(&path, &scene), Err(CheckpointError::Format { .. })));
    }

    #[test]
    fn a_save_abandoned_at_the_stop_leaves_the_checkpoint_as_it_was() {
        let dir = tempfile::Builder::new().prefix("pf-checkpoint-abandoned-").tempdir().unwrap();
        let path = dir.path().join("checkpoint.bin");
        let (scene, c, sums) = empty_scene_and_checkpoint(8, 4);
        c.save(&path, &sums).unwrap();
        let before = std::fs::read(&path).unwrap();
        let mut later = c.clone();
        later.session = 2;
        let e = later.save_unless(&path, &sums, &AtomicBool::new(true)).unwrap_err();
        assert!(matches!(e, CheckpointError::Abandoned { .. }), "{e}");
        assert_eq!(std::fs::read(&path).unwrap(), before);
        assert!(!previous_path(&path).exists() && !path.with_extension("tmp").exists(), "nothing left beside it");
        assert_eq!(Checkpoint::load(&path, &scene).unwrap().0, c);
    }

    #[test]
    fn a_bit_flipped_anywhere_is_refused_as_damaged_and_names_the_previous_checkpoint() {
        let dir = tempfile::Builder::new().prefix("pf-checkpoint-damage-").tempdir().unwrap();
        let path = dir.path().join("checkpoint.bin");
        let (scene, c, sums) = empty_scene_and_checkpoint(8, 4);
        c.save(&path, &sums).unwrap();
        assert!(!previous_path(&path).exists(), "a first save has nothing to keep");
        c.save(&path, &sums).unwrap();
        assert_eq!(previous_path(&path), dir.path().join("checkpoint-previous.bin"));
        assert_eq!(Checkpoint::load(&previous_path(&path), &scene).unwrap().0, c);
        let whole = std::fs::read(&path).unwrap();
        // Every bit of the file but the format number's byte, which names another version instead.
        for bit in 8..whole.len() * 8 {
            let mut bytes = whole.clone();
            bytes[bit / 8] ^= 1 << (bit % 8);
            std::fs::write(&path, &bytes).unwrap();
            match Checkpoint::load(&path, &scene) {
                Err(e @ CheckpointError::Damaged { .. }) => {
                    let text = e.to_string();
                    assert!(
                        text.contains("damaged") && text.contains("--resume") && text.contains("previous"),
                        "{text}"
                    );
                }
                other => panic!("bit {bit} of {}: {other:?}", whole.len() * 8),
            }
        }
        // A file of an older version says so, rather than that it is damaged.
        let mut old = whole.clone();
        old[0] = 8;
        let e = Checkpoint::from_bytes(&old, &scene, "old").unwrap_err().to_string();
        assert!(e.contains("format 8 (expected 10)"), "{e}");
    }

    #[test]
    fn a_file_larger_than_any_checkpoint_of_the_scene_is_refused_unread() {
        let dir = tempfile::Builder::new().prefix("pf-checkpoint-large-").tempdir().unwrap();
        let path = dir.path().join("checkpoint.bin");
        let (scene, _, _) = empty_scene_and_checkpoint(2, 2);
        let max = Checkpoint::max_file_bytes(&scene);
        // A sparse file: its size, not its content, is what is refused.
        std::fs::File::create(&path).unwrap().set_len(max + 1).unwrap();
        let e = Checkpoint::load(&path, &scene).unwrap_err();
        assert!(matches!(e, CheckpointError::TooLarge { size, .. } if size == max + 1), "{e}");
    }
}
