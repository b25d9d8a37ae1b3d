//! Lossless multi-layer OpenEXR files: every [`LayerImage`] becomes the channels
//! `<name>.R`, `<name>.G`, `<name>.B` of one single-part scan-line image, the classic
//! layer convention that exrheader, Blender, Nuke, tev and friends all understand
//! (multi-part files are still unsupported by several viewers).

use std::fs::File;
use std::io::{BufReader, BufWriter, Seek, SeekFrom, Write};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;

use exr::block::lines::LineRefMut;
use exr::image::write::samples::{SamplesWriter, WritableSamples};
use exr::math::RoundingMode;
use exr::meta::attribute::{LevelMode, SampleType};
use exr::meta::header::Header;
use exr::prelude::{
    AnyChannel, AnyChannels, Encoding, Image, Layer, LayerAttributes, ReadChannels, ReadLayers, Text, Vec2,
    WritableImage,
};

use super::{write_atomically, OutputError};

/// Layer name given to the plain `R`, `G`, `B` channels of an ordinary single-layer EXR,
/// because that is what a render's full image is called everywhere else.
const DEFAULT_LAYER_NAME: &str = "total";

/// One named RGB layer of an image, row-major with row 0 at the top of the image.
#[derive(Clone, Debug, PartialEq)]
pub struct LayerImage {
    /// Layer name as shown by image viewers, e.g. "total" or "direct".
    pub name: String,
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Linear RGB pixels, `width * height` of them, pixel (x, y) at `y * width + x`.
    pub rgb: Vec<[f32; 3]>,
}

impl LayerImage {
    /// A black layer, ready to be filled in, so callers never get the buffer length wrong.
    pub fn new(name: impl Into<String>, width: usize, height: usize) -> Self {
        Self { name: name.into(), width, height, rgb: vec![[0.0; 3]; width * height] }
    }

    /// The pixel at column `x` and row `y` (row 0 is the top), hiding the row-major layout.
    ///
    /// Panics if `(x, y)` is outside the image, like slice indexing.
    pub fn get(&self, x: usize, y: usize) -> [f32; 3] {
        assert!(
            x < self.width && y < self.height,
            "pixel ({x}, {y}) is outside the {}x{} layer \"{}\"",
            self.width,
            self.height,
            self.name
        );
        self.rgb[y * self.width + x]
    }
}

/// One named RGB layer whose pixels are made as the file is written, from whatever holds them (a render's running
/// sums), so that writing an image never holds all its layers as f32 at once.
pub struct ComputedLayer<'a> {
    /// Layer name, as for [`LayerImage`].
    pub name: String,
    /// The linear RGB pixel at index `y * width + x` (row 0 at the top).
    pub pixel: Box<dyn Fn(usize) -> [f32; 3] + Sync + 'a>,
}

impl<'a> ComputedLayer<'a> {
    /// A layer named `name` whose pixel `i` is `pixel(i)`.
    pub fn new(name: impl Into<String>, pixel: impl Fn(usize) -> [f32; 3] + Sync + 'a) -> Self {
        Self { name: name.into(), pixel: Box::new(pixel) }
    }

    /// The layer made whole, `width` × `height` pixels.
    pub fn to_image(&self, width: usize, height: usize) -> LayerImage {
        LayerImage { name: self.name.clone(), width, height, rgb: (0..width * height).map(&self.pixel).collect() }
    }
}

/// Writes all layers into one multi-layer OpenEXR file (channels `<name>.R/G/B` as f32,
/// lossless ZIP compression) so every pass of a render travels in a single file that
/// viewers show as layers "total", "direct", ...
///
/// The file is written to a temporary file next to `path` and renamed into place, so a
/// crash never leaves a half-written image. Layer names must be unique, non-empty,
/// printable ASCII, and all layers must have the same, non-zero size.
pub fn write_exr(path: &Path, layers: Vec<LayerImage>) -> Result<(), OutputError> {
    let (width, height) = check_layers(path, &layers)?;
    let computed: Vec<ComputedLayer> =
        layers.iter().map(|layer| ComputedLayer::new(layer.name.clone(), |i| layer.rgb[i])).collect();
    write_computed_exr(path, (width, height), &computed, Compressing::OnThisThread, None)
}

/// Where a write compresses the file's blocks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Compressing {
    /// On the calling thread alone: a write beside a render must not compete with its threads.
    OnThisThread,
    /// On every core, the blocks made one after another on the calling thread: for a write while nothing
    /// renders (between an in-process engine's steps, or at the end of a run).
    OnEveryCore,
}

/// Writes `layers` of an image of `size` (width, height) as [`write_exr`] does, making each row of each layer only
/// as its block is compressed: besides what the layers read, the write holds one row per layer (and the blocks
/// being compressed). With `abandon`, a write still under way when it is set stops at its next block and leaves
/// the file as it was ([`OutputError::Abandoned`]).
pub fn write_computed_exr(
    path: &Path,
    size: (usize, usize),
    layers: &[ComputedLayer],
    compressing: Compressing,
    abandon: Option<&AtomicBool>,
) -> Result<(), OutputError> {
    let (width, height) = size;
    check_names(path, layers.iter().map(|l| l.name.as_str()))?;
    if width == 0 || height == 0 {
        return Err(OutputError::Exr {
            path: path.to_path_buf(),
            operation: "write",
            message: format!("the image is empty ({width}x{height})"),
        });
    }
    let rows: Vec<RowCache> = layers.iter().map(|_| Mutex::new((usize::MAX, Vec::new()))).collect();
    let mut channels = Vec::with_capacity(layers.len() * 3);
    for (layer, row) in layers.iter().zip(&rows) {
        for (component, suffix) in ["R", "G", "B"].into_iter().enumerate() {
            let channel_name = format!("{}.{suffix}", layer.name);
            let text = Text::new_or_none(&channel_name).ok_or_else(|| OutputError::Exr {
                path: path.to_path_buf(),
                operation: "write",
                message: format!("channel name \"{channel_name}\" is not representable"),
            })?;
            channels.push(AnyChannel::new(text, ComputedChannel { layer, row, component, width }));
        }
    }

    // SMALL_LOSSLESS = ZIP (16 scan lines per block) in increasing line order: lossless
    // for f32, supported by every OpenEXR reader, and the first row stored is the top row.
    let layer = Layer::new(
        Vec2(width, height),
        LayerAttributes::default(),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(channels.into()),
    );
    let image = Image::from_layer(layer);

    let abandoned = || abandon.is_some_and(|a| a.load(Ordering::Relaxed));
    let written = write_atomically(path, |file| {
        let out = Abandonable { inner: BufWriter::new(file), abandon };
        // In parallel the exr crate starts a thread pool of one thread per core for the write.
        let written = match compressing {
            Compressing::OnThisThread => image.write().non_parallel().to_buffered(out),
            Compressing::OnEveryCore => image.write().to_buffered(out),
        };
        written.map_err(|error| exr_error(path, "write", error))
    });
    match written {
        Err(_) if abandoned() => Err(OutputError::Abandoned { path: path.to_path_buf() }),
        other => other,
    }
}

/// The row a computed layer made last: the index of its first pixel and its pixels. The exr crate asks for a
/// block's lines one channel after another, so a layer's three channels of a row share one making of it.
type RowCache = Mutex<(usize, Vec<[f32; 3]>)>;

/// One channel of a [`ComputedLayer`], as the exr crate writes it.
#[derive(Clone, Copy)]
struct ComputedChannel<'l, 'a> {
    layer: &'l ComputedLayer<'a>,
    row: &'l RowCache,
    component: usize,
    width: usize,
}

impl<'s> WritableSamples<'s> for ComputedChannel<'_, '_> {
    fn sample_type(&self) -> SampleType {
        SampleType::F32
    }

    fn infer_level_modes(&self) -> (LevelMode, RoundingMode) {
        (LevelMode::Singular, RoundingMode::Down)
    }

    type Writer = Self;

    fn create_samples_writer(&'s self, _header: &Header) -> Self::Writer {
        *self
    }
}

impl SamplesWriter for ComputedChannel<'_, '_> {
    fn extract_line(&self, line: LineRefMut<'_>) {
        let start = line.location.position.y() * self.width + line.location.position.x();
        let count = line.location.sample_count;
        let mut row = self.row.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        if row.0 != start || row.1.len() != count {
            row.1.clear();
            row.1.extend((start..start + count).map(&self.layer.pixel));
            row.0 = start;
        }
        // The line's bytes are the exr crate's own buffer of exactly `count` f32 samples.
        line.write_samples(|i| row.1[i][self.component]).expect("a line holds its samples");
    }
}

/// A file writer that fails once `abandon` is set, so that an EXR being compressed stops at its next block.
struct Abandonable<'f, W> {
    inner: W,
    abandon: Option<&'f AtomicBool>,
}

impl<W: Write> Write for Abandonable<'_, W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if self.abandon.is_some_and(|a| a.load(Ordering::Relaxed)) {
            return Err(std::io::Error::other("the write was abandoned"));
        }
        self.inner.write(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

impl<W: Seek> Seek for Abandonable<'_, W> {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        self.inner.seek(pos)
    }
}

/// Reads every RGB layer of a multi-layer EXR written by [`write_exr`] (and also a plain
/// single-layer RGB EXR, whose layer is then named "total" when it has no name), so
/// renders can be resumed, compared and merged from their own output files.
///
/// Layers come back in file order; as OpenEXR stores channels sorted by name, layers
/// written by [`write_exr`] come back sorted by name, so look them up with
/// [`find_layer`]. Channels that do not form a complete R, G, B triple (alpha, depth,
/// ...) are ignored; a file without any RGB layer is an error.
pub fn read_exr(path: &Path) -> Result<Vec<LayerImage>, OutputError> {
    let file = File::open(path).map_err(|error| OutputError::io(path, "read", error))?;
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .all_layers()
        .all_attributes()
        .non_parallel()
        .from_buffered(BufReader::new(file))
        .map_err(|error| exr_error(path, "read", error))?;

    let mut layers = Vec::new();
    for part in &image.layer_data {
        let part_name = part.attributes.layer_name.as_ref().map(Text::to_string);
        let (width, height) = (part.size.width(), part.size.height());

        // (layer name, channel index of R, G, B) in order of first appearance.
        let mut groups: Vec<(String, [Option<usize>; 3])> = Vec::new();
        for (index, channel) in part.channel_data.list.iter().enumerate() {
            if channel.sampling != Vec2(1, 1) {
                continue; // sub-sampled channels cannot be part of a full-resolution layer
            }
            let channel_name = channel.name.to_string();
            let (prefix, suffix) = channel_name.rsplit_once('.').unwrap_or(("", &channel_name));
            let Some(component) = rgb_component(suffix) else {
                continue;
            };
            let layer_name = if prefix.is_empty() {
                part_name.clone().unwrap_or_else(|| DEFAULT_LAYER_NAME.to_string())
            } else {
                prefix.to_string()
            };
            match groups.iter_mut().find(|(name, _)| *name == layer_name) {
                Some((_, indices)) => indices[component] = Some(index),
                None => {
                    let mut indices = [None; 3];
                    indices[component] = Some(index);
                    groups.push((layer_name, indices));
                }
            }
        }

        for (name, indices) in groups {
            let [Some(r), Some(g), Some(b)] = indices else {
                continue;
            };
            let list = &part.channel_data.list;
            let pixel_count = width * height;
            if [r, g, b].iter().any(|&index| list[index].sample_data.len() != pixel_count) {
                return Err(OutputError::Exr {
                    path: path.to_path_buf(),
                    operation: "read",
                    message: format!("layer \"{name}\" does not have {width}x{height} samples"),
                });
            }
            let rgb = list[r]
                .sample_data
                .values_as_f32()
                .zip(list[g].sample_data.values_as_f32())
                .zip(list[b].sample_data.values_as_f32())
                .map(|((r, g), b)| [r, g, b])
                .collect();
            layers.push(LayerImage { name, width, height, rgb });
        }
    }

    if layers.is_empty() {
        return Err(OutputError::Exr {
            path: path.to_path_buf(),
            operation: "read",
            message: "the file contains no layer with R, G and B channels".to_string(),
        });
    }
    Ok(layers)
}

/// Finds a layer by name or returns [`OutputError::MissingLayer`], so that callers get an
/// error naming both the file and the layer instead of an `Option` to explain themselves.
pub fn find_layer<'a>(layers: &'a [LayerImage], path: &Path, name: &str) -> Result<&'a LayerImage, OutputError> {
    layers
        .iter()
        .find(|layer| layer.name == name)
        .ok_or_else(|| OutputError::MissingLayer { path: path.to_path_buf(), name: name.to_string() })
}

/// Which of R, G, B a channel name suffix denotes, accepting the common spellings.
fn rgb_component(suffix: &str) -> Option<usize> {
    match suffix.to_ascii_lowercase().as_str() {
        "r" | "red" => Some(0),
        "g" | "green" => Some(1),
        "b" | "blue" => Some(2),
        _ => None,
    }
}

/// Checks that `layers` can be one EXR image and returns its (width, height): the names as
/// [`check_names`] asks, one non-zero size for all, and each layer's pixels filling it.
fn check_layers(path: &Path, layers: &[LayerImage]) -> Result<(usize, usize), OutputError> {
    check_names(path, layers.iter().map(|l| l.name.as_str()))?;
    let first = &layers[0];
    let (width, height) = (first.width, first.height);
    if width == 0 || height == 0 {
        let message = format!("the image is empty ({width}x{height})");
        return Err(OutputError::Exr { path: path.to_path_buf(), operation: "write", message });
    }
    for layer in layers {
        let name = &layer.name;
        if (layer.width, layer.height) != (width, height) {
            return Err(OutputError::SizeMismatch {
                path: path.to_path_buf(),
                layer: name.clone(),
                detail: format!("is {}x{} but layer \"{}\" is {width}x{height}", layer.width, layer.height, first.name),
            });
        }
        if layer.rgb.len() != width * height {
            return Err(OutputError::SizeMismatch {
                path: path.to_path_buf(),
                layer: name.clone(),
                detail: format!("has {} pixels but {width}x{height} needs {}", layer.rgb.len(), width * height),
            });
        }
    }
    Ok((width, height))
}

/// Checks the layer names of one EXR image: at least one, each non-empty printable ASCII, none twice.
fn check_names<'n>(path: &Path, names: impl Iterator<Item = &'n str>) -> Result<(), OutputError> {
    let invalid = |message: String| OutputError::Exr { path: path.to_path_buf(), operation: "write", message };
    let mut seen: Vec<&str> = Vec::new();
    for name in names {
        if name.is_empty() || !name.bytes().all(|byte| (b' '..=b'~').contains(&byte)) {
            return Err(invalid(format!("layer name \"{name}\" must be non-empty printable ASCII")));
        }
        if seen.contains(&name) {
            return Err(invalid(format!("layer name \"{name}\" is used twice")));
        }
        seen.push(name);
    }
    if seen.is_empty() {
        return Err(invalid("there are no layers to write".to_string()));
    }
    Ok(())
}

/// Converts an exr crate error, keeping genuine file-system failures as [`OutputError::Io`].
fn exr_error(path: &Path, operation: &'static str, error: exr::error::Error) -> OutputError {
    match error {
        exr::error::Error::Io(source) => OutputError::io(path, operation, source),
        other => OutputError::Exr { path: path.to_path_buf(), operation, message: other.to_string() },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    /// A fresh, empty directory for one test, so tests can run in parallel.
    fn test_dir(test: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("photonfarm-output-exr-{test}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    fn bits(layer: &LayerImage) -> Vec<[u32; 3]> {
        layer.rgb.iter().map(|p| [p[0].to_bits(), p[1].to_bits(), p[2].to_bits()]).collect()
    }

    fn sample_layers() -> Vec<LayerImage> {
        let specials = [
            f32::from_bits(1), // smallest subnormal
            f32::MIN_POSITIVE,
            1.0e-30,
            -0.0,
            f32::MAX,
            -3.0e38,
            1.0e30,
            f32::INFINITY,
            f32::NAN,
            0.1,
        ];
        ["total", "direct", "indirect"]
            .iter()
            .enumerate()
            .map(|(l, name)| {
                let mut layer = LayerImage::new(*name, 7, 5);
                for (i, pixel) in layer.rgb.iter_mut().enumerate() {
                    for (c, value) in pixel.iter_mut().enumerate() {
                        let n = (l * 1000 + i * 3 + c) as f32;
                        *value = if (i + c) % 4 == 0 {
                            specials[(i + c + l) % specials.len()]
                        } else {
                            n * 0.37 + 1.0 / (n + 1.0)
                        };
                    }
                }
                layer
            })
            .collect()
    }

    #[test]
    fn exr_round_trip_keeps_every_layer_bit_exact() {
        let dir = test_dir("round-trip");
        let path = dir.join("image.exr");
        let layers = sample_layers();
        write_exr(&path, layers.clone()).unwrap();
        let read = read_exr(&path).unwrap();

        assert_eq!(read.len(), layers.len());
        for layer in &layers {
            let back = find_layer(&read, &path, &layer.name).unwrap();
            assert_eq!((back.width, back.height), (7, 5));
            assert_eq!(bits(back), bits(layer), "layer {}", layer.name);
        }
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn exr_rows_start_at_the_top() {
        let dir = test_dir("rows");
        let path = dir.join("image.exr");
        let mut layer = LayerImage::new("total", 3, 2);
        layer.rgb[1] = [1.0, 2.0, 3.0]; // (x=1, y=0)
        write_exr(&path, vec![layer.clone()]).unwrap();
        let read = read_exr(&path).unwrap();
        assert_eq!(read[0].get(1, 0), [1.0, 2.0, 3.0]);
        assert_eq!(read[0].get(1, 1), [0.0, 0.0, 0.0]);

        // Also check with an independent reader that row 0 is the first row in the file.
        let meta = exr::meta::MetaData::read_from_file(&path, false).unwrap();
        let header = &meta.headers[0];
        assert_eq!(header.line_order, exr::meta::attribute::LineOrder::Increasing);
        assert_eq!(header.own_attributes.layer_position, Vec2(0, 0));
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn exr_file_is_one_zip_part_with_prefixed_rgb_channels() {
        let dir = test_dir("channels");
        let path = dir.join("image.exr");
        write_exr(&path, sample_layers()).unwrap();
        let meta = exr::meta::MetaData::read_from_file(&path, false).unwrap();
        assert_eq!(meta.headers.len(), 1);
        let header = &meta.headers[0];
        assert_eq!(header.compression, exr::compression::Compression::ZIP16);
        let names: Vec<String> = header.channels.list.iter().map(|c| c.name.to_string()).collect();
        assert_eq!(
            names,
            [
                "direct.B",
                "direct.G",
                "direct.R",
                "indirect.B",
                "indirect.G",
                "indirect.R",
                "total.B",
                "total.G",
                "total.R"
            ]
        );
        assert!(header.channels.list.iter().all(|c| c.sample_type == exr::meta::attribute::SampleType::F32));
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn plain_single_layer_rgb_exr_reads_as_total() {
        let dir = test_dir("plain");
        let path = dir.join("plain.exr");
        let image = Image::from_channels(
            (4, 3),
            exr::prelude::SpecificChannels::rgb(|pos: Vec2<usize>| (pos.x() as f32, pos.y() as f32, 0.5_f32)),
        );
        image.write().to_file(&path).unwrap();
        let read = read_exr(&path).unwrap();
        assert_eq!(read.len(), 1);
        let total = find_layer(&read, &path, "total").unwrap();
        assert_eq!((total.width, total.height), (4, 3));
        assert_eq!(total.get(3, 2), [3.0, 2.0, 0.5]);
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn exr_rewrite_replaces_the_file_and_leaves_no_temporary_files() {
        let dir = test_dir("rewrite");
        let path = dir.join("image.exr");
        let mut layer = LayerImage::new("total", 2, 2);
        write_exr(&path, vec![layer.clone()]).unwrap();
        layer.rgb[3] = [4.0, 5.0, 6.0];
        write_exr(&path, vec![layer.clone()]).unwrap();
        assert_eq!(read_exr(&path).unwrap(), vec![layer]);
        let files: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(files, ["image.exr"]);
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn computed_layers_write_the_same_bytes_as_the_layers_they_compute_on_one_thread_or_all() {
        // 40 rows: blocks of 16 lines, the last one short, each row made once for its three channels.
        let (w, h) = (9, 40);
        let value = |l: usize, i: usize, c: usize| ((l * 7919 + i * 31 + c) % 1013) as f32 * 0.173 - 20.0;
        let computed: Vec<ComputedLayer> = ["total", "direct", "ghost"]
            .iter()
            .enumerate()
            .map(|(l, name)| ComputedLayer::new(*name, move |i| [value(l, i, 0), value(l, i, 1), value(l, i, 2)]))
            .collect();
        let images: Vec<LayerImage> = computed.iter().map(|l| l.to_image(w, h)).collect();
        let dir = test_dir("computed");
        let (a, b) = (dir.join("a.exr"), dir.join("b.exr"));
        write_exr(&a, images.clone()).unwrap();
        write_computed_exr(&b, (w, h), &computed, Compressing::OnThisThread, None).unwrap();
        assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
        write_computed_exr(&b, (w, h), &computed, Compressing::OnEveryCore, None).unwrap();
        assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
        let mut read = read_exr(&b).unwrap();
        read.sort_by(|x, y| x.name.cmp(&y.name));
        let mut expected = images;
        expected.sort_by(|x, y| x.name.cmp(&y.name));
        assert_eq!(read.iter().map(bits).collect::<Vec<_>>(), expected.iter().map(bits).collect::<Vec<_>>());
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn an_abandoned_write_leaves_the_old_file_and_no_temporary_file() {
        let dir = test_dir("abandoned");
        let path = dir.join("image.exr");
        let old = LayerImage::new("total", 3, 2);
        write_exr(&path, vec![old.clone()]).unwrap();
        let new = [ComputedLayer::new("total", |_| [1.0, 2.0, 3.0])];
        let abandon = AtomicBool::new(true);
        let error = write_computed_exr(&path, (3, 2), &new, Compressing::OnThisThread, Some(&abandon)).unwrap_err();
        assert!(matches!(error, OutputError::Abandoned { .. }), "{error}");
        assert_eq!(read_exr(&path).unwrap(), vec![old]);
        let files: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(files, ["image.exr"]);
        // Not set, the same write goes through.
        abandon.store(false, Ordering::Relaxed);
        write_computed_exr(&path, (3, 2), &new, Compressing::OnThisThread, Some(&abandon)).unwrap();
        assert_eq!(read_exr(&path).unwrap()[0].rgb, vec![[1.0, 2.0, 3.0]; 6]);
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn exr_write_into_missing_directory_names_the_path() {
        let dir = test_dir("missing-dir");
        let path = dir.join("no/such/dir/image.exr");
        let error = write_exr(&path, vec![LayerImage::new("total", 2, 2)]).unwrap_err();
        assert!(matches!(error, OutputError::Io { .. }), "{error:?}");
        let message = error.to_string();
        assert!(message.contains(&path.display().to_string()), "{message}");
        assert!(message.starts_with("cannot write "), "{message}");
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn exr_layers_of_different_sizes_are_rejected() {
        let dir = test_dir("sizes");
        let path = dir.join("image.exr");
        let layers = [LayerImage::new("total", 4, 4), LayerImage::new("direct", 4, 3)];
        let error = write_exr(&path, layers.to_vec()).unwrap_err();
        assert!(matches!(&error, OutputError::SizeMismatch { layer, .. } if layer == "direct"), "{error:?}");
        assert!(error.to_string().contains("4x3"), "{error}");

        let mut short = LayerImage::new("total", 4, 4);
        short.rgb.pop();
        let error = write_exr(&path, vec![short]).unwrap_err();
        assert!(matches!(error, OutputError::SizeMismatch { .. }), "{error:?}");
        assert!(!path.exists());
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn exr_rejects_empty_duplicate_and_non_ascii_layer_names() {
        let dir = test_dir("names");
        let path = dir.join("image.exr");
        for layers in [
            vec![],
            vec![LayerImage::new("", 2, 2)],
            vec![LayerImage::new("tötal", 2, 2)],
            vec![LayerImage::new("a", 2, 2), LayerImage::new("a", 2, 2)],
            vec![LayerImage::new("empty", 0, 2)],
        ] {
            let error = write_exr(&path, layers.clone()).unwrap_err();
            assert!(matches!(error, OutputError::Exr { .. }), "{error:?}");
            assert!(error.to_string().contains("image.exr"), "{error}");
        }
        assert!(!path.exists());
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn reading_a_file_that_is_not_exr_is_an_error_not_a_panic() {
        let dir = test_dir("not-exr");
        let path = dir.join("notes.exr");
        std::fs::write(&path, "this is not an image\n").unwrap();
        let error = read_exr(&path).unwrap_err();
        assert!(matches!(error, OutputError::Exr { .. }), "{error:?}");
        assert!(error.to_string().contains("notes.exr"), "{error}");
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn reading_a_truncated_exr_is_an_error_not_a_panic() {
        let dir = test_dir("truncated");
        let path = dir.join("image.exr");
        write_exr(&path, sample_layers()).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        for keep in [bytes.len() / 2, bytes.len() - 1, 20] {
            std::fs::write(&path, &bytes[..keep]).unwrap();
            assert!(read_exr(&path).is_err(), "kept {keep} bytes");
        }
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn reading_a_missing_file_is_an_io_error_naming_the_path() {
        let dir = test_dir("missing-file");
        let path = dir.join("absent.exr");
        let error = read_exr(&path).unwrap_err();
        assert!(matches!(error, OutputError::Io { .. }), "{error:?}");
        assert!(error.to_string().starts_with(&format!("cannot read {}", path.display())), "{error}");
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn find_layer_reports_missing_layer_with_file_and_name() {
        let layers = [LayerImage::new("total", 1, 1)];
        let path = Path::new("out/x/image.exr");
        assert_eq!(find_layer(&layers, path, "total").unwrap().name, "total");
        let error = find_layer(&layers, path, "direct").unwrap_err();
        assert!(matches!(&error, OutputError::MissingLayer { name, .. } if name == "direct"), "{error:?}");
        assert_eq!(error.to_string(), "out/x/image.exr has no layer named \"direct\"");
    }
}
