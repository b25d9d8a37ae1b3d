//! The output folder of a run: the multi-layer EXR, the PNG preview and the JSON record.

use anyhow::{Context, Result};
use photonfarm::accumulation::{relative_mean_difference, relative_rmse, Accumulator, LitMask};
use photonfarm::color::luminance_f64;
use photonfarm::image_io::exr_file::{find_layer, read_exr, write_computed_exr, Compressing, ComputedLayer};
use photonfarm::image_io::preview::{auto_exposure, write_preview_png};
use photonfarm::image_io::OutputError;
use photonfarm::render::images::luminance_of;
use photonfarm::render::images::{
    computed_layers, computed_lit_layer, computed_phases_layer, total_image, total_layer,
};
use photonfarm::render::record::{RunRecord, TrueError};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

/// A reference image loaded once and compared against after every save.
pub struct Reference {
    pub path: PathBuf,
    pub total: Vec<[f64; 3]>,
    /// Luminance of the reference's standard error per pixel (its `sem` layer, when it has one).
    pub sem: Option<Vec<f64>>,
}

impl Reference {
    /// Loads a reference EXR and checks its size.
    pub fn load(path: &Path, width: u32, height: u32) -> Result<Reference> {
        let layers = read_exr(path)?;
        let total = find_layer(&layers, path, "total")?;
        if (total.width, total.height) != (width as usize, height as usize) {
            anyhow::bail!(
                "reference {} is {}×{} but the scene renders {}×{}",
                path.display(),
                total.width,
                total.height,
                width,
                height
            );
        }
        let sem = find_layer(&layers, path, "sem").ok().map(|s| s.rgb.iter().map(|&p| luminance_of(p)).collect());
        Ok(Reference {
            path: path.to_path_buf(),
            total: total.rgb.iter().map(|p| [p[0] as f64, p[1] as f64, p[2] as f64]).collect(),
            sem,
        })
    }

    /// Relative RMSE of the sums' mean image against this reference, over every pixel and over the pixels
    /// that `lit`, the run's mask, leaves unlit (the pixels of δ unlit).
    pub fn compare(&self, sums: &Accumulator, lit: &LitMask) -> TrueError {
        let image = total_image(sums);
        let lit = |i: usize| lit.is_lit(i);
        // δ of the reference itself: its SEMs against its own values (paper eq. 6).
        let reference_delta = |include: &dyn Fn(usize) -> bool| {
            let sem = self.sem.as_ref()?;
            let (mut num, mut den) = (0.0, 0.0);
            for (_, (s, r)) in sem.iter().zip(&self.total).enumerate().filter(|&(i, _)| include(i)) {
                num += s * s;
                den += luminance_f64(*r).powi(2);
            }
            (den > 0.0).then(|| (num / den).sqrt())
        };
        TrueError {
            reference: self.path.display().to_string(),
            rmse_all: relative_rmse(&image, &self.total, |_| true),
            rmse_unlit: relative_rmse(&image, &self.total, |i| !lit(i)),
            reference_delta_all: reference_delta(&|_| true),
            reference_delta_unlit: reference_delta(&|i| !lit(i)),
            mean_difference_all: Some(relative_mean_difference(&image, &self.total, |_| true)),
            mean_difference_unlit: Some(relative_mean_difference(&image, &self.total, |i| !lit(i))),
        }
    }
}

/// Writes preview.png, then runs `between` (the preview is the cheapest file, and the one a user waits for; a
/// large image's EXR takes seconds), then image.exr (with the lit mask as its `lit` layer and the phases per
/// pixel as its `phases` layer) and run.json; each file is replaced atomically. Besides the sums it holds the
/// preview's total layer, then what `between` holds, then a row of each of the EXR's layers, never two of them
/// at once. Nothing renders meanwhile (it is called between an in-process engine's steps, and at the end), so
/// the EXR is compressed on every core.
pub fn save(
    dir: &Path,
    sums: &Accumulator,
    lit: &LitMask,
    record: &RunRecord,
    between: impl FnOnce() -> Result<()>,
) -> Result<()> {
    write_preview(dir, sums)?;
    between()?;
    write_image_and_record(dir, sums, lit, record, Compressing::OnEveryCore, None)?;
    Ok(())
}

/// Writes preview.png from the total layer alone.
pub fn write_preview(dir: &Path, sums: &Accumulator) -> Result<()> {
    let total = total_layer(sums);
    write_preview_png(&dir.join("preview.png"), &total, auto_exposure(&total))?;
    Ok(())
}

/// The layers of image.exr, made from the sums as the file is written: the sums' layers
/// (`photonfarm::render::images::layer_images`), the lit mask as `lit` and the phases per pixel as `phases`.
fn exr_layers<'a>(sums: &'a Accumulator, lit: &'a LitMask) -> Vec<ComputedLayer<'a>> {
    let mut layers = computed_layers(sums);
    layers.push(computed_lit_layer(lit));
    layers.push(computed_phases_layer(sums));
    layers
}

/// What became of a write of the image and the record that could be abandoned.
#[derive(Debug, PartialEq)]
pub enum Written {
    Done,
    /// `abandon` was set while the EXR was written: neither file changed.
    Abandoned,
}

/// Writes image.exr from the sums (`exr_layers`), then run.json. A large image's EXR takes seconds to compress,
/// all the while reading the sums; with `abandon`, a write under way when it is set stops at its next block.
pub fn write_image_and_record(
    dir: &Path,
    sums: &Accumulator,
    lit: &LitMask,
    record: &RunRecord,
    compressing: Compressing,
    abandon: Option<&AtomicBool>,
) -> Result<Written> {
    let size = (sums.width as usize, sums.height as usize);
    match write_computed_exr(&dir.join("image.exr"), size, &exr_layers(sums, lit), compressing, abandon) {
        Err(OutputError::Abandoned { .. }) => return Ok(Written::Abandoned),
        written => written?,
    }
    let json = serde_json::to_vec_pretty(record)?;
    let tmp = dir.join(".run.json.tmp");
    std::fs::write(&tmp, json).with_context(|| format!("cannot write {}", tmp.display()))?;
    std::fs::rename(&tmp, dir.join("run.json"))
        .with_context(|| format!("cannot write {}", dir.join("run.json").display()))?;
    Ok(Written::Done)
}

/// A fresh folder under out/ named after the scene and the UTC time.
pub fn default_dir(scene: &Path) -> PathBuf {
    let stem = scene.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "render".into());
    let stamp = humantime::format_rfc3339_seconds(std::time::SystemTime::now())
        .to_string()
        .replace([':', 'T'], "-")
        .trim_end_matches('Z')
        .to_string();
    let mut dir = PathBuf::from("out").join(format!("{stem}-{stamp}"));
    let mut n = 1;
    while dir.exists() {
        n += 1;
        dir = PathBuf::from("out").join(format!("{stem}-{stamp}-{n}"));
    }
    dir
}
