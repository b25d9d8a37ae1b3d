//! `coordinator charts DIR`: charts of a bench folder's `results.csv` and `series.csv`, written to `DIR/charts/`
//! as SVG and PNG. The main curves use the error over pixels that do not see a light directly (the `_unlit`
//! columns), where δ is meaningful. Every method has one colour in every chart and every thread count (or, in
//! the charts over cores, every scene) one marker shape; δ is drawn solid and the true error dashed. Every
//! repeat of a series is its own line, so the spread between runs stays visible; only the speedup and memory
//! lines are means over repeats. A scene with more (method, threads) keys than can be told apart gets one chart
//! per thread count.

mod calibration;
mod draw;
mod error_vs_rays;
mod error_vs_time;
mod memory;
mod over_cores;
mod plot;
mod scale;
mod series;
mod speedup;
mod style;

use crate::bench::tables::{read_table, ResultsRow, SeriesRow};
use crate::cli::ChartsArgs;
use anyhow::{Context, Result};
use calibration::calibration;
use draw::save;
pub(crate) use draw::{register_embedded_font, FONT};
use error_vs_rays::error_vs_rays;
use error_vs_time::error_vs_time;
use memory::memory_vs_cores;
use series::chart_groups;
use speedup::speedup_vs_cores;
use std::path::{Path, PathBuf};
use style::ThreadMarkers;

/// `coordinator charts DIR`: draws the charts and prints the files written.
pub fn run(args: ChartsArgs) -> Result<()> {
    for path in write_charts(&args.dir)? {
        say!("wrote {}", path.display());
    }
    Ok(())
}

/// Reads `dir/results.csv` and `dir/series.csv` (the bench's output) and writes every chart into `dir/charts/`
/// as SVG and PNG, returning the files written. Per scene of series.csv: error-vs-time, error-vs-rays and
/// calibration; from results.csv: speedup-vs-cores and memory-vs-cores.
pub fn write_charts(dir: &Path) -> Result<Vec<PathBuf>> {
    register_embedded_font()?;
    let results: Vec<ResultsRow> = read_table(&dir.join("results.csv"))?;
    let series: Vec<SeriesRow> = read_table(&dir.join("series.csv"))?;
    let out = dir.join("charts");
    std::fs::create_dir_all(&out).with_context(|| format!("cannot create {}", out.display()))?;

    let markers = ThreadMarkers::of(series.iter().map(|r| r.threads));
    let mut plots = Vec::new();
    for scene in first_appearances(series.iter().map(|r| r.scene.as_str())) {
        let rows: Vec<&SeriesRow> = series.iter().filter(|r| r.scene == scene).collect();
        let part = file_name_part(scene);
        for (suffix, title, rows) in chart_groups(&rows) {
            let title = format!("{scene}{title}");
            plots.push((format!("error-vs-time-{part}{suffix}"), error_vs_time(&title, &rows, &markers)));
            plots.push((format!("error-vs-rays-{part}{suffix}"), error_vs_rays(&title, &rows, &markers)));
            plots.push((format!("calibration-{part}{suffix}"), calibration(&title, &rows, &markers)));
        }
    }
    let scenes = first_appearances(results.iter().map(|r| r.scene.as_str()));
    plots.push(("speedup-vs-cores".to_string(), speedup_vs_cores(&results, &scenes)));
    plots.push(("memory-vs-cores".to_string(), memory_vs_cores(&results, &scenes)));

    let mut written = Vec::new();
    for (name, plot) in &plots {
        written.extend(save(plot, &out, name).with_context(|| format!("cannot draw the chart {name}"))?);
    }
    Ok(written)
}

/// Distinct values in the order they first appear: the bench writes methods and thread counts in the order the
/// user asked for them, which reads better than sorted.
fn first_appearances<T: PartialEq>(items: impl Iterator<Item = T>) -> Vec<T> {
    let mut seen = Vec::new();
    for item in items {
        if !seen.contains(&item) {
            seen.push(item);
        }
    }
    seen
}

/// A scene name as part of a file name: it comes from a CSV file and must not escape the charts folder.
fn file_name_part(name: &str) -> String {
    name.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '_' { c } else { '_' }).collect()
}

#[cfg(test)]
mod tests {
    use super::draw::{CHART_SIZE, LEGEND_WIDTH};
    use super::plot::Stroke;
    use super::series::UNLIT;
    use super::style::method_colour;
    use super::*;
    use photonfarm::render::Method;
    use plotters::style::RGBColor;

    const RESULTS_HEADER: &str = "scene,method,topology,processes,groups,threads_per_group,threads,repeat,wall_s,\
        backward_rays,forward_rays,merges,phases,delta_unlit,delta_all,true_unlit,true_all,peak_memory_bytes,\
        bytes_per_pixel,idle_fraction";
    const SERIES_HEADER: &str = "scene,method,threads,repeat,time_s,rays,delta_unlit,delta_all,true_unlit,true_all";
    const SCENES: [&str; 2] = ["cornell", "caustic"];

    /// A fresh, empty folder for one test, so tests can run in parallel.
    fn test_dir(test: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("photonfarm-charts-{test}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// A bench folder of 2 scenes × 3 methods × threads 1 and 2 × 2 repeats, where caustic's async runs have no
    /// true error, and with values the log axes cannot show.
    fn write_bench_folder(dir: &Path) {
        let mut results = format!("{RESULTS_HEADER}\n");
        let mut series = format!("{SERIES_HEADER}\n");
        for (s, scene) in SCENES.iter().enumerate() {
            for (m, method) in ["sync", "async", "two-level"].iter().enumerate() {
                for threads in [1u32, 2] {
                    for repeat in 0..2u32 {
                        let rate =
                            1e6 * f64::from(threads).powf(0.9) * (1.0 + 0.1 * m as f64 + 0.02 * f64::from(repeat));
                        let error = |rays: f64| 3.0 * (1.0 + 0.2 * s as f64) / rays.powf(1.0 / 3.0);
                        let no_truth = *scene == "caustic" && *method == "async";
                        let truth = |delta: f64| {
                            if no_truth {
                                String::new()
                            } else {
                                (delta * (0.6 + 0.3 * m as f64)).to_string()
                            }
                        };
                        let wall = 10.0;
                        let delta = error(rate * wall);
                        let memory = 40e6 + 5e6 * f64::from(threads) + 1e6 * f64::from(repeat);
                        results.push_str(&format!(
                            "{scene},{method},in-process,1,{threads},1,{threads},{repeat},{wall},{},{},0,100,{delta},\
                             {delta},{},{},{memory},120.5,0.05\n",
                            (rate * wall * 0.7).round(),
                            (rate * wall * 0.3).round(),
                            truth(delta),
                            truth(delta),
                        ));
                        for k in 0..8 {
                            let time = 0.25 * 2f64.powi(k);
                            let rays = (rate * time).round();
                            let delta = error(rays);
                            series.push_str(&format!(
                                "{scene},{method},{threads},{repeat},{time},{rays},{delta},{delta},{},{}\n",
                                truth(delta),
                                truth(delta)
                            ));
                        }
                    }
                }
            }
        }
        series.push_str("cornell,sync,1,0,0,0,0,0,0,0\n");
        series.push_str("cornell,sync,1,0,-1,0,NaN,inf,-0.5,\n");
        std::fs::write(dir.join("results.csv"), results).unwrap();
        std::fs::write(dir.join("series.csv"), series).unwrap();
    }

    /// Decodes an 8-bit RGB PNG into (width, height, bytes).
    fn decode(path: &Path) -> (u32, u32, Vec<u8>) {
        let file = std::fs::File::open(path).unwrap();
        let mut reader = png::Decoder::new(std::io::BufReader::new(file)).read_info().unwrap();
        let mut buffer = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buffer).unwrap();
        assert_eq!((info.color_type, info.bit_depth), (png::ColorType::Rgb, png::BitDepth::Eight), "{path:?}");
        buffer.truncate(info.buffer_size());
        (info.width, info.height, buffer)
    }

    #[test]
    fn every_chart_is_written_as_svg_and_a_png_with_lines_and_text() {
        let dir = test_dir("all");
        write_bench_folder(&dir);
        let written = write_charts(&dir).unwrap();

        let mut names: Vec<String> = vec!["speedup-vs-cores".into(), "memory-vs-cores".into()];
        for scene in SCENES {
            names.extend(["error-vs-time", "error-vs-rays", "calibration"].map(|chart| format!("{chart}-{scene}")));
        }
        let mut expected: Vec<PathBuf> = names
            .iter()
            .flat_map(|name| ["svg", "png"].map(|ext| dir.join("charts").join(format!("{name}.{ext}"))))
            .collect();
        let mut written_sorted = written.clone();
        written_sorted.sort();
        expected.sort();
        assert_eq!(written_sorted, expected);

        for path in &written {
            if path.extension().unwrap() == "svg" {
                let svg = std::fs::read_to_string(path).unwrap();
                assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"), "{path:?}");
                let per_scene = SCENES.iter().any(|s| path.to_string_lossy().ends_with(&format!("-{s}.svg")));
                assert!(!per_scene || svg.contains(UNLIT), "{path:?} does not say which pixels");
                continue;
            }
            let (width, height, rgb) = decode(path);
            assert_eq!((width, height), CHART_SIZE, "{path:?}");
            let pixels: Vec<(usize, &[u8])> =
                rgb.chunks_exact(3).enumerate().map(|(i, p)| (i % width as usize, p)).collect();
            let not_white = pixels.iter().filter(|(_, p)| p.iter().any(|&c| c < 250)).count();
            assert!(not_white > pixels.len() / 100, "{path:?} is nearly blank: {not_white} drawn pixels");
            // The data lines are the only saturated colours.
            let coloured =
                pixels.iter().filter(|(_, p)| p.iter().max().unwrap() - p.iter().min().unwrap() > 80).count();
            assert!(coloured > 200, "{path:?} has no data lines: {coloured} coloured pixels");
            // Legend text, drawn with the embedded font: black pixels right of the legend's line samples.
            let text_from = (width - LEGEND_WIDTH) as usize + 46;
            let text = pixels.iter().filter(|(x, p)| *x >= text_from && p.iter().all(|&c| c < 90)).count();
            assert!(text > 100, "{path:?} has no legend text: {text} dark pixels");
        }
        let calibration = std::fs::read_to_string(dir.join("charts/calibration-caustic.svg")).unwrap();
        // plotters writes each text on a line of its own.
        assert!(!calibration.contains("\nasync\n"), "caustic's async runs have no true error to calibrate");
        assert!(calibration.contains("\nsync\n") && calibration.contains("\n2 threads\n"), "the legend names the keys");
        std::fs::remove_dir_all(&dir).ok();
    }

    fn series_row(method: Method, threads: usize, repeat: u32) -> SeriesRow {
        SeriesRow {
            scene: "caustic".into(),
            method,
            threads,
            repeat,
            time_s: 1.0,
            rays: 1000,
            delta_unlit: 0.1,
            delta_all: 0.1,
            true_unlit: Some(0.12),
            true_all: Some(0.12),
            tiles: String::new(),
            blur_unlit: 0.0,
        }
    }

    #[test]
    fn a_method_keeps_its_colour_a_thread_count_its_marker_and_true_error_is_dashed() {
        let rows = [
            series_row(Method::Path, 1, 0),
            series_row(Method::Combination, 2, 0),
            series_row(Method::Pbpm, 1, 0),
            series_row(Method::ThreeLevel, 1, 0),
            series_row(Method::ThreeLevel, 2, 0),
        ];
        let refs: Vec<&SeriesRow> = rows.iter().collect();
        let markers = ThreadMarkers::of(rows.iter().map(|r| r.threads));
        let plot = error_vs_time("caustic", &refs, &markers);
        assert_eq!(plot.lines.len(), 10, "δ and true error for each key");
        let colours: Vec<RGBColor> = Method::ALL.iter().map(|&m| method_colour(m)).collect();
        assert!(colours.iter().enumerate().all(|(i, c)| !colours[..i].contains(c)), "every method its own colour");
        for (row, pair) in rows.iter().zip(plot.lines.chunks(2)) {
            assert!(pair
                .iter()
                .all(|l| l.colour == method_colour(row.method) && l.marker == Some(markers.get(row.threads))));
            assert_eq!((pair[0].stroke, pair[1].stroke), (Stroke::Solid, Stroke::Dashed));
        }
        assert_ne!(markers.get(1), markers.get(2));
        let texts: Vec<&str> = plot.legend.iter().map(|e| e.text.as_str()).collect();
        assert_eq!(
            texts,
            ["path", "combination", "pbpm", "three-level", "1 thread", "2 threads", "δ (estimated)", "true error"]
        );
    }

    #[test]
    fn a_scene_with_more_keys_than_can_be_told_apart_gets_a_chart_per_thread_count() {
        // The bench's default on two cores: pbpm and path at one thread, the five parallel methods at one and two.
        let few: Vec<SeriesRow> = Method::ALL
            .iter()
            .flat_map(|&m| if m.layout().runs_on(2) { vec![1, 2] } else { vec![1] }.into_iter().map(move |t| (m, t)))
            .map(|(m, t)| series_row(m, t, 0))
            .collect();
        let refs: Vec<&SeriesRow> = few.iter().collect();
        assert_eq!((refs.len(), chart_groups(&refs).len()), (12, 1));
        let many: Vec<SeriesRow> = [1, 2, 4].iter().flat_map(|&t| Method::ALL.map(|m| series_row(m, t, 0))).collect();
        let refs: Vec<&SeriesRow> = many.iter().collect();
        let groups = chart_groups(&refs);
        let suffixes: Vec<&str> = groups.iter().map(|g| g.0.as_str()).collect();
        assert_eq!(suffixes, ["-1t", "-2t", "-4t"]);
        assert!(groups.iter().all(|g| g.2.len() == Method::ALL.len()));
    }

    fn error_with(test: &str, file: &str, edit: impl Fn(&str) -> String) -> String {
        let dir = test_dir(test);
        write_bench_folder(&dir);
        let path = dir.join(file);
        std::fs::write(&path, edit(&std::fs::read_to_string(&path).unwrap())).unwrap();
        let message = format!("{:#}", write_charts(&dir).expect_err("bad input accepted"));
        std::fs::remove_dir_all(&dir).ok();
        message
    }

    /// Replaces field `column` of line `line` (1-based, the header is line 1).
    fn set_field(text: &str, line: usize, column: usize, value: &str) -> String {
        let mut lines: Vec<String> = text.lines().map(String::from).collect();
        let mut fields: Vec<&str> = lines[line - 1].split(',').collect();
        fields[column] = value;
        lines[line - 1] = fields.join(",");
        lines.join("\n") + "\n"
    }

    #[test]
    fn malformed_csv_is_refused_with_file_line_and_column() {
        let m = error_with("number", "results.csv", |t| set_field(t, 3, 8, "fast"));
        assert!(m.contains("results.csv, line 3, column wall_s"), "{m}");

        let m = error_with("threads", "series.csv", |t| set_field(t, 5, 2, "1.5"));
        assert!(m.contains("series.csv, line 5, column threads"), "{m}");

        let m = error_with("fields", "series.csv", |t| {
            let mut lines: Vec<&str> = t.lines().collect();
            lines[3] = "cornell,sync,1,0,0.5";
            lines.join("\n")
        });
        assert!(m.contains("series.csv, line 4") && m.contains("5 fields where the header has 10"), "{m}");

        let m = error_with("header", "results.csv", |t| t.replacen("peak_memory_bytes", "peak_rss", 1));
        assert!(m.contains("results.csv, line 1") && m.contains("peak_memory_bytes"), "{m}");

        let dir = test_dir("missing");
        let m = format!("{:#}", write_charts(&dir).expect_err("no results.csv accepted"));
        assert!(m.contains("results.csv"), "{m}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
