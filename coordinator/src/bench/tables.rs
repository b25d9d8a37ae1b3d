//! The bench's tables as CSV files, each written by the bench and read by the charts through one row type:
//! `results.csv` has a [`ResultsRow`] per run, `series.csv` a [`SeriesRow`] per step of every run (its error
//! against time and rays). The reader names the file, line and column of any bad input.

use anyhow::{anyhow, bail, Context, Result};
use photonfarm::render::Method;
use serde::de::{DeserializeOwned, Visitor};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// One run of the bench: its layout, what it traced, its error and its memory. The columns of `results.csv`
/// are these fields, in this order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ResultsRow {
    pub scene: String,
    pub method: Method,
    /// "this machine" for one process, the synthetic description of a distributed run's nodes.
    pub topology: String,
    pub processes: usize,
    /// Groups over all processes.
    pub groups: usize,
    pub threads_per_group: usize,
    pub threads: usize,
    pub repeat: u32,
    /// Until the last phases were merged (the run's last history entry).
    pub wall_s: f64,
    pub backward_rays: u64,
    pub forward_rays: u64,
    pub merges: u64,
    #[serde(default)]
    pub light_paths: u64,
    /// Light paths counted against the photon maps (once per map a path gathered into).
    #[serde(default)]
    pub map_light_paths: u64,
    pub phases: u64,
    pub delta_unlit: f64,
    pub delta_all: f64,
    /// Empty without a reference image.
    pub true_unlit: Option<f64>,
    pub true_all: Option<f64>,
    /// The largest peak resident memory of the run's processes (coordinator and workers).
    pub peak_memory_bytes: Option<u64>,
    pub bytes_per_pixel: f64,
    /// Fraction of thread time idle at and between synchronisation rounds (in-process parallel engines).
    #[serde(rename = "idle_fraction")]
    pub idle: Option<f64>,
    /// The reference's own δ over unlit pixels: it adds in quadrature to every true error of the run.
    #[serde(default)]
    pub reference_delta_unlit: Option<f64>,
    /// The image's mean relative to the reference's, minus one, over unlit and over all pixels: the bias.
    #[serde(default)]
    pub mean_difference_unlit: Option<f64>,
    #[serde(default)]
    pub mean_difference_all: Option<f64>,
    /// With `--target-error`: "adaptive" or "uniform" tiles, the run's target, and the wall seconds at which
    /// δ unlit first met it (empty when it did not within `--time`). Empty otherwise.
    #[serde(default)]
    pub tiles: String,
    #[serde(default)]
    pub target_error: Option<f64>,
    #[serde(default)]
    pub reached_s: Option<f64>,
    /// The photon discs' blur's part of `delta_unlit` (0 for a path tracer, and in a bench of an earlier
    /// version).
    #[serde(default)]
    pub blur_unlit: f64,
}

/// One step of a run (a phase, a round or a merged snapshot): its error against time and rays.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SeriesRow {
    pub scene: String,
    pub method: Method,
    pub threads: usize,
    pub repeat: u32,
    pub time_s: f64,
    /// Backward and forward rays traced so far.
    pub rays: u64,
    pub delta_unlit: f64,
    pub delta_all: f64,
    /// Empty without a reference image.
    pub true_unlit: Option<f64>,
    pub true_all: Option<f64>,
    /// "adaptive" or "uniform" with `--target-error`, empty otherwise.
    #[serde(default)]
    pub tiles: String,
    /// The photon discs' blur's part of `delta_unlit`.
    #[serde(default)]
    pub blur_unlit: f64,
}

/// A row type of a CSV table the bench writes.
pub trait TableRow: DeserializeOwned {
    /// Columns a file may lack, read as zero or empty: the counts a bench of an earlier version did not write.
    const OPTIONAL_COLUMNS: &'static [&'static str] = &[];
}

impl TableRow for ResultsRow {
    const OPTIONAL_COLUMNS: &'static [&'static str] = &[
        "light_paths",
        "map_light_paths",
        "reference_delta_unlit",
        "mean_difference_unlit",
        "mean_difference_all",
        "tiles",
        "target_error",
        "reached_s",
        "blur_unlit",
    ];
}

impl TableRow for SeriesRow {
    const OPTIONAL_COLUMNS: &'static [&'static str] = &["tiles", "blur_unlit"];
}

/// Writes `rows` as a CSV table with a header line.
pub fn write_table<T: Serialize>(path: &Path, rows: &[T]) -> Result<()> {
    let fail = || format!("cannot write {}", path.display());
    let mut writer = csv::Writer::from_path(path).with_context(fail)?;
    for row in rows {
        writer.serialize(row).with_context(fail)?;
    }
    writer.flush().with_context(fail)
}

/// Reads a CSV table with a header line into rows, naming the file, line and column of any bad input. Columns
/// may come in any order; every column of `T` but its optional ones must be there.
pub fn read_table<T: TableRow>(path: &Path) -> Result<Vec<T>> {
    let file = std::fs::File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
    let mut reader = csv::ReaderBuilder::new().from_reader(std::io::BufReader::new(file));
    let headers = reader.headers().map_err(|e| csv_error(path, &e))?.clone();
    // Deserialising by name would quietly read a missing column of empty-able values as empty everywhere.
    let columns = columns_of::<T>();
    let missing: Vec<&str> = columns
        .iter()
        .copied()
        .filter(|c| !T::OPTIONAL_COLUMNS.contains(c) && !headers.iter().any(|h| h == *c))
        .collect();
    if !missing.is_empty() {
        bail!(
            "{}, line 1: the header lacks {}; expected the columns {}",
            path.display(),
            missing.join(", "),
            columns.join(",")
        );
    }
    let mut rows = Vec::new();
    let mut record = csv::StringRecord::new();
    while reader.read_record(&mut record).map_err(|e| csv_error(path, &e))? {
        let line = record.position().map_or(0, |p| p.line());
        let row = record.deserialize(Some(&headers)).map_err(|e| match e.kind() {
            csv::ErrorKind::Deserialize { err, .. } => {
                let column = err.field().and_then(|i| headers.get(i as usize)).unwrap_or("?");
                anyhow!("{}, line {line}, column {column}: {}", path.display(), err.kind())
            }
            _ => anyhow!("{}, line {line}: {e}", path.display()),
        })?;
        rows.push(row);
    }
    Ok(rows)
}

fn csv_error(path: &Path, e: &csv::Error) -> anyhow::Error {
    let detail = match e.kind() {
        csv::ErrorKind::UnequalLengths { expected_len, len, .. } => {
            format!("{len} fields where the header has {expected_len}")
        }
        csv::ErrorKind::Utf8 { err, .. } => format!("not UTF-8 ({err})"),
        _ => e.to_string(),
    };
    match e.position() {
        Some(p) => anyhow!("{}, line {}: {detail}", path.display(), p.line()),
        None => anyhow!("{}: {detail}", path.display()),
    }
}

/// The columns of a row type, in order: the field names serde's derive hands to `deserialize_struct`, so the
/// struct is the one place they are spelled.
pub fn columns_of<'de, T: Deserialize<'de>>() -> &'static [&'static str] {
    /// A deserializer that only notes the fields a struct asks for.
    struct FieldNames<'a>(&'a mut &'static [&'static str]);

    impl<'de> serde::Deserializer<'de> for FieldNames<'_> {
        type Error = serde::de::value::Error;

        fn deserialize_any<V: Visitor<'de>>(self, _: V) -> Result<V::Value, Self::Error> {
            Err(serde::de::Error::custom("a table row is a struct"))
        }

        fn deserialize_struct<V: Visitor<'de>>(
            self,
            _name: &'static str,
            fields: &'static [&'static str],
            _visitor: V,
        ) -> Result<V::Value, Self::Error> {
            *self.0 = fields;
            Err(serde::de::Error::custom("only the field names are read"))
        }

        serde::forward_to_deserialize_any! {
            bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string bytes byte_buf option unit
            unit_struct newtype_struct seq tuple tuple_struct map enum identifier ignored_any
        }
    }

    let mut fields: &'static [&'static str] = &[];
    let _ = T::deserialize(FieldNames(&mut fields));
    fields
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row() -> ResultsRow {
        ResultsRow {
            scene: "cornell".into(),
            method: Method::ThreeLevel,
            topology: "synthetic pack:1 numa:2 core:1 pu:1".into(),
            processes: 2,
            groups: 2,
            threads_per_group: 1,
            threads: 2,
            repeat: 0,
            wall_s: 8.0625,
            backward_rays: 1_000_000,
            forward_rays: 2_000_000,
            merges: 30,
            light_paths: 400,
            map_light_paths: 600,
            phases: 12,
            delta_unlit: 0.05,
            delta_all: f64::NAN,
            true_unlit: Some(0.04),
            true_all: None,
            peak_memory_bytes: Some(123_456_789),
            bytes_per_pixel: 520.5,
            idle: None,
            reference_delta_unlit: Some(0.002),
            mean_difference_unlit: Some(-0.0004),
            mean_difference_all: None,
            tiles: "adaptive".into(),
            target_error: Some(0.03),
            reached_s: Some(7.5),
            blur_unlit: 0.01,
        }
    }

    #[test]
    fn results_keep_their_columns_in_order_and_read_back() {
        let dir = std::env::temp_dir().join(format!("photonfarm-bench-tables-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("results.csv");
        write_table(&path, &[row()]).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(
            text.lines().next().unwrap(),
            "scene,method,topology,processes,groups,threads_per_group,threads,repeat,wall_s,backward_rays,\
             forward_rays,merges,light_paths,map_light_paths,phases,delta_unlit,delta_all,true_unlit,true_all,\
             peak_memory_bytes,bytes_per_pixel,idle_fraction,reference_delta_unlit,mean_difference_unlit,\
             mean_difference_all,tiles,target_error,reached_s,blur_unlit"
        );
        assert!(text.lines().nth(1).unwrap().starts_with("cornell,three-level,synthetic pack:1 numa:2"), "{text}");
        let back: Vec<ResultsRow> = read_table(&path).unwrap();
        assert_eq!(back.len(), 1);
        let (mut a, mut b) = (back[0].clone(), row());
        assert!(a.delta_all.is_nan());
        (a.delta_all, b.delta_all) = (0.0, 0.0);
        assert_eq!(a, b);

        let step = SeriesRow {
            scene: "caustic".into(),
            method: Method::TwoLevel,
            threads: 4,
            repeat: 1,
            time_s: 0.5,
            rays: 12_345,
            delta_unlit: 0.25,
            delta_all: 0.125,
            true_unlit: None,
            true_all: Some(0.5),
            tiles: String::new(),
            blur_unlit: 0.0625,
        };
        let path = dir.join("series.csv");
        write_table(&path, std::slice::from_ref(&step)).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(
            text,
            "scene,method,threads,repeat,time_s,rays,delta_unlit,delta_all,true_unlit,true_all,tiles,blur_unlit\n\
             caustic,two-level,4,1,0.5,12345,0.25,0.125,,0.5,,0.0625\n"
        );
        assert_eq!(read_table::<SeriesRow>(&path).unwrap(), [step]);
        std::fs::remove_dir_all(&dir).ok();
    }
}
