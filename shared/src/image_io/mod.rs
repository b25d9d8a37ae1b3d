//! Image files written by a render: lossless multi-layer OpenEXR for analysis and
//! resuming, plus an 8-bit sRGB PNG preview for humans. Every file is replaced
//! atomically so that a crash during a periodic refresh never leaves a broken image.

pub mod exr_file;
pub mod preview;

use std::fs::{self, File, OpenOptions};
use std::io;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Everything that can go wrong while writing or reading an image file; every variant
/// names the file so that a message from a long batch render is actionable on its own.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// The file system refused an operation (missing directory, permissions, full disk...).
    #[error("cannot {operation} {}: {source}", path.display())]
    Io {
        /// The image file the operation was for.
        path: PathBuf,
        /// What was attempted, e.g. "write" or "read".
        operation: &'static str,
        /// The underlying operating-system error.
        #[source]
        source: io::Error,
    },

    /// The exr crate rejected the image or the file is not a valid OpenEXR file.
    #[error("cannot {operation} OpenEXR file {}: {message}", path.display())]
    Exr {
        /// The image file the operation was for.
        path: PathBuf,
        /// What was attempted, "write" or "read".
        operation: &'static str,
        /// The exr crate's error text, or why the image cannot be stored as EXR.
        message: String,
    },

    /// The png crate could not encode the preview.
    #[error("cannot write PNG file {}: {message}", path.display())]
    Png {
        /// The preview file being written.
        path: PathBuf,
        /// The png crate's error text, or why the preview cannot be encoded.
        message: String,
    },

    /// A requested layer (for example "total") is not in the file.
    #[error("{} has no layer named \"{name}\"", path.display())]
    MissingLayer {
        /// The image file that was searched.
        path: PathBuf,
        /// The layer name that was looked for.
        name: String,
    },

    /// A write was abandoned while under way (the run it saved had stopped); the file is as it was.
    #[error("the write of {} was abandoned", path.display())]
    Abandoned {
        /// The file that was being written.
        path: PathBuf,
    },

    /// A layer's size disagrees with the other layers or with its own pixel buffer.
    #[error("cannot write {}: layer \"{layer}\" {detail}", path.display())]
    SizeMismatch {
        /// The image file being written.
        path: PathBuf,
        /// Name of the offending layer.
        layer: String,
        /// What exactly does not match, with both sizes.
        detail: String,
    },
}

impl OutputError {
    /// Builds an [`OutputError::Io`]; a helper because almost every file operation needs it.
    pub(crate) fn io(path: &Path, operation: &'static str, source: io::Error) -> Self {
        Self::Io { path: path.to_path_buf(), operation, source }
    }
}

/// Distinguishes temporary files of concurrent writers within one process.
static TEMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// Writes `path` by letting `write` fill a fresh temporary file in the same directory,
/// syncing it and renaming it over `path`, so readers only ever see a complete old or
/// complete new image. The temporary file is removed again if anything fails.
pub(crate) fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut File) -> Result<(), OutputError>,
) -> Result<(), OutputError> {
    let file_name = path.file_name().ok_or_else(|| {
        OutputError::io(path, "write", io::Error::new(io::ErrorKind::InvalidInput, "the path has no file name"))
    })?;
    let mut temp_name = std::ffi::OsString::from(".");
    temp_name.push(file_name);
    temp_name.push(format!(".{}.{}.tmp", std::process::id(), TEMP_COUNTER.fetch_add(1, Ordering::Relaxed)));
    let temp_path = path.with_file_name(temp_name);

    let mut file = OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&temp_path)
        .map_err(|error| OutputError::io(path, "write", error))?;

    let result = write(&mut file).and_then(|()| file.sync_all().map_err(|error| OutputError::io(path, "write", error)));
    drop(file);
    let result =
        result.and_then(|()| fs::rename(&temp_path, path).map_err(|error| OutputError::io(path, "replace", error)));
    if result.is_err() {
        // Best effort: the original error is more useful than a failure to clean up.
        let _ = fs::remove_file(&temp_path);
    }
    result
}
