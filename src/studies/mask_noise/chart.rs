//! The mask-noise study as a chart (plotters, SVG and PNG) and a Markdown table: per class, IoU
//! against the clean masks over the corruption rate, for the corrupted inputs and for the twin
//! (each mode, training and held-out views).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::damage::{DamageClass, TrainMode};
use crate::report::ChartError;
use crate::studies::mask_noise::rows::{StudyRow, StudyStage};

type DrawResult = Result<(), Box<dyn std::error::Error>>;

/// Height in pixels of the legend strip under each row of panels.
const LEGEND_HEIGHT: i32 = 34;
/// The corrupted inputs' colour.
const GREY: RGBColor = RGBColor(90, 90, 90);

fn classes(rows: &[StudyRow]) -> Vec<DamageClass> {
    DamageClass::ALL
        .into_iter()
        .filter(|c| rows.iter().any(|r| r.class == *c))
        .collect()
}

fn modes(rows: &[StudyRow]) -> Vec<TrainMode> {
    let mut modes: Vec<TrainMode> = Vec::new();
    for r in rows {
        if !modes.contains(&r.mode) {
            modes.push(r.mode);
        }
    }
    modes
}

/// A series: points (rate, value) of the rows of one class and mode, sorted by rate.
fn series(
    rows: &[StudyRow],
    class: DamageClass,
    mode: Option<TrainMode>,
    value: fn(&StudyRow) -> f64,
) -> Vec<(f64, f64)> {
    let mut points: Vec<(f64, f64)> = rows
        .iter()
        .filter(|r| r.class == class && mode.is_none_or(|m| r.mode == m))
        .map(|r| (f64::from(r.rate), value(r)))
        .filter(|p| p.1.is_finite())
        .collect();
    points.sort_by(|a, b| a.0.total_cmp(&b.0));
    points.dedup_by(|a, b| a.0 == b.0);
    points
}

fn mode_colour(mode: TrainMode) -> RGBColor {
    match mode {
        TrainMode::Label => RGBColor(30, 110, 200),
        TrainMode::Overlay => RGBColor(220, 110, 20),
        TrainMode::Rgb => RGBColor(120, 120, 120),
    }
}

/// Which views a panel scores.
#[derive(Clone, Copy, PartialEq)]
enum Views {
    /// Every training view (inputs, twin) and the held-out views (twin).
    All,
    /// Only the training views whose masks were corrupted.
    Corrupted,
}

fn panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    rows: &[StudyRow],
    class: DamageClass,
    views: Views,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let max_rate = rows
        .iter()
        .map(|r| f64::from(r.rate))
        .fold(0.0f64, f64::max)
        .max(0.1);
    let mut chart = ChartBuilder::on(area)
        .caption(
            match views {
                Views::All => format!("{class}: IoU against clean masks, all views"),
                Views::Corrupted => format!("{class}: IoU on the corrupted training views"),
            },
            ("sans-serif", 17),
        )
        .margin(10)
        .x_label_area_size(36)
        .y_label_area_size(48)
        .build_cartesian_2d(-0.02..max_rate * 1.05, 0.0..1.0)?;
    chart
        .configure_mesh()
        .x_desc("corruption rate (error / damage area per view, or share of views corrupted)")
        .y_desc("IoU")
        .draw()?;
    let rows_with_noise: Vec<StudyRow> = rows
        .iter()
        .filter(|r| views == Views::All || r.noisy_views > 0)
        .cloned()
        .collect();
    let rows = &rows_with_noise[..];
    let input = match views {
        Views::All => series(rows, class, None, |r| r.input_iou),
        Views::Corrupted => series(rows, class, None, |r| r.input_iou_noisy_views),
    };
    chart.draw_series(LineSeries::new(input.iter().copied(), GREY.stroke_width(2)))?;
    chart.draw_series(
        input
            .iter()
            .map(|&p| Cross::new(p, 5, GREY.stroke_width(2))),
    )?;
    for mode in modes(rows) {
        let colour = mode_colour(mode);
        if views == Views::Corrupted {
            let twin = series(rows, class, Some(mode), |r| r.twin_iou_noisy_views);
            chart.draw_series(LineSeries::new(
                twin.iter().copied(),
                colour.stroke_width(3),
            ))?;
            chart.draw_series(twin.iter().map(|&p| Circle::new(p, 4, colour.filled())))?;
            continue;
        }
        let heldout = series(rows, class, Some(mode), |r| r.twin_iou_heldout);
        chart.draw_series(LineSeries::new(
            heldout.iter().copied(),
            colour.stroke_width(3),
        ))?;
        chart.draw_series(heldout.iter().map(|&p| Circle::new(p, 4, colour.filled())))?;
        let train = series(rows, class, Some(mode), |r| r.twin_iou_train);
        chart.draw_series(DashedLineSeries::new(
            train.iter().copied(),
            6,
            4,
            colour.mix(0.6).stroke_width(2),
        ))?;
    }
    Ok(())
}

/// How a legend entry's sample is drawn.
#[derive(Clone, Copy)]
enum Sample {
    /// Grey line with crosses (the inputs).
    Input,
    /// Solid line with dots, in the mode's colour.
    Solid(RGBColor),
    /// Light dashed line, in the mode's colour.
    Dashed(RGBColor),
}

/// The legend of one row of panels: the panels themselves carry none, so no box hides a line.
fn legend_entries(rows: &[StudyRow], views: Views) -> Vec<(Sample, String)> {
    let mut entries = vec![(Sample::Input, "corrupted input masks".to_string())];
    for mode in modes(rows) {
        let colour = mode_colour(mode);
        match views {
            Views::All => {
                entries.push((
                    Sample::Solid(colour),
                    format!("twin, {mode} mode, held-out views"),
                ));
                entries.push((
                    Sample::Dashed(colour),
                    format!("twin, {mode} mode, training views"),
                ));
            }
            Views::Corrupted => {
                entries.push((
                    Sample::Solid(colour),
                    format!("twin, {mode} mode, same views"),
                ));
            }
        }
    }
    entries
}

/// Draws the entries side by side across a strip.
fn legend_strip<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    entries: &[(Sample, String)],
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let (width, height) = area.dim_in_pixel();
    let slot = width as i32 / entries.len().max(1) as i32;
    let y = height as i32 / 2;
    for (k, (sample, label)) in entries.iter().enumerate() {
        let x = k as i32 * slot + 24;
        let line = [(x, y), (x + 34, y)];
        match *sample {
            Sample::Input => {
                area.draw(&PathElement::new(line, GREY.stroke_width(2)))?;
                area.draw(&Cross::new((x + 17, y), 5, GREY.stroke_width(2)))?;
            }
            Sample::Solid(colour) => {
                area.draw(&PathElement::new(line, colour.stroke_width(3)))?;
                area.draw(&Circle::new((x + 17, y), 4, colour.filled()))?;
            }
            Sample::Dashed(colour) => {
                for (a, b) in [(0, 10), (14, 24), (28, 34)] {
                    area.draw(&PathElement::new(
                        [(x + a, y), (x + b, y)],
                        colour.mix(0.6).stroke_width(2),
                    ))?;
                }
            }
        }
        area.draw(&Text::new(
            label.clone(),
            (x + 42, y - 8),
            ("sans-serif", 15),
        ))?;
    }
    Ok(())
}

fn draw<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, rows: &[StudyRow]) -> DrawResult
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let classes = classes(rows);
    let (_, height) = root.dim_in_pixel();
    let row_height = (height as i32 - 2 * LEGEND_HEIGHT) / 2;
    let (top, rest) = root.split_vertically(row_height);
    let (top_legend, rest) = rest.split_vertically(LEGEND_HEIGHT);
    let (bottom, bottom_legend) = rest.split_vertically(row_height);
    for (views, row, legend) in [
        (Views::All, top, top_legend),
        (Views::Corrupted, bottom, bottom_legend),
    ] {
        let areas = row.split_evenly((1, classes.len().max(1)));
        for (area, class) in areas.iter().zip(&classes) {
            panel(area, rows, *class, views)?;
        }
        legend_strip(&legend, &legend_entries(rows, views))?;
    }
    root.present()?;
    Ok(())
}

/// Writes `<stem>.png` and `<stem>.svg` into `dir`.
pub fn write_study_chart(
    dir: &Path,
    stem: &str,
    rows: &[StudyRow],
) -> Result<Vec<PathBuf>, ChartError> {
    // The chart compares modes on the coarse twins; the fine-tune rows are in the tables.
    let rows: Vec<StudyRow> = rows
        .iter()
        .filter(|r| r.stage == StudyStage::Coarse)
        .cloned()
        .collect();
    let rows = &rows[..];
    let width = 520 * classes(rows).len().max(1) as u32;
    let png = dir.join(format!("{stem}.png"));
    let svg = dir.join(format!("{stem}.svg"));
    draw(
        BitMapBackend::new(&png, (width, 1000)).into_drawing_area(),
        rows,
    )
    .map_err(|e| ChartError::new(&png, e))?;
    draw(
        SVGBackend::new(&svg, (width, 1000)).into_drawing_area(),
        rows,
    )
    .map_err(|e| ChartError::new(&svg, e))?;
    Ok(vec![png, svg])
}

/// The rows as a Markdown table (for docs/).
pub fn study_table(rows: &[StudyRow]) -> String {
    let mut text = String::from(
        "| mode | stage | rate | class | input IoU | twin IoU (train views) | twin IoU (held-out) | twin F1 (held-out) | input IoU (corrupted views) | twin IoU (corrupted views) | errors corrected | clean twin on those pixels | errors introduced |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    // No corrupted views at rate 0: those columns have nothing to show.
    let value = |v: f64| {
        if v.is_finite() {
            format!("{v:.3}")
        } else {
            "–".to_string()
        }
    };
    for r in rows {
        let corrected = if r.corrupted_pixels > 0 {
            format!(
                "{:.1} % of {}",
                100.0 * r.errors_corrected,
                r.corrupted_pixels
            )
        } else {
            "–".to_string()
        };
        let clean_twin = if r.corrupted_pixels > 0 && r.clean_twin_corrected.is_finite() {
            format!("{:.1} %", 100.0 * r.clean_twin_corrected)
        } else {
            "–".to_string()
        };
        let introduced = if r.errors_introduced.is_finite() {
            format!("{:.2} %", 100.0 * r.errors_introduced)
        } else {
            "–".to_string()
        };
        let _ = writeln!(
            text,
            "| {} | {} | {:.2} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            r.mode,
            r.stage,
            r.rate,
            r.class,
            value(r.input_iou),
            value(r.twin_iou_train),
            value(r.twin_iou_heldout),
            value(r.twin_f1_heldout),
            value(r.input_iou_noisy_views),
            value(r.twin_iou_noisy_views),
            corrected,
            clean_twin,
            introduced
        );
    }
    text
}

/// The rows as CSV.
pub fn study_csv(rows: &[StudyRow]) -> String {
    let mut text = String::from(
        "mode,stage,rate,class,input_iou,twin_iou_train,twin_iou_heldout,twin_f1_heldout,\
         twin_precision_heldout,twin_recall_heldout,input_iou_noisy_views,twin_iou_noisy_views,\
         corrupted_pixels,errors_corrected,missed_corrected,added_corrected,clean_twin_corrected,errors_introduced,noisy_views,train_seconds,gaussians,heldout_psnr\n",
    );
    for r in rows {
        let _ = writeln!(
            text,
            "{},{},{},{},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{},{:.5},{:.5},{:.5},{:.5},{:.5},{},{:.2},{},{}",
            r.mode,
            r.stage,
            r.rate,
            r.class,
            r.input_iou,
            r.twin_iou_train,
            r.twin_iou_heldout,
            r.twin_f1_heldout,
            r.twin_precision_heldout,
            r.twin_recall_heldout,
            r.input_iou_noisy_views,
            r.twin_iou_noisy_views,
            r.corrupted_pixels,
            r.errors_corrected,
            r.missed_corrected,
            r.added_corrected,
            r.clean_twin_corrected,
            r.errors_introduced,
            r.noisy_views,
            r.train_seconds,
            r.gaussians,
            r.heldout_psnr
                .map(|v| format!("{v:.3}"))
                .unwrap_or_default()
        );
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(serde::Deserialize)]
    struct Study {
        rows: Vec<StudyRow>,
    }

    #[test]
    fn the_chart_has_one_legend_per_row_of_panels_and_none_inside_them() {
        let json = include_str!("../../../docs/figures/mask-noise-study.json");
        let study: Study = serde_json::from_str(json).expect("the study in docs/ parses");
        let dir = tempfile::tempdir().expect("temp dir");
        let files = write_study_chart(dir.path(), "study", &study.rows).expect("chart drawn");
        assert_eq!(files.len(), 2);
        for f in &files {
            let bytes = std::fs::metadata(f).expect("chart written").len();
            assert!(bytes > 10_000, "{} is only {bytes} bytes", f.display());
        }
        let svg = std::fs::read_to_string(&files[1]).expect("svg");
        // Three panels per row, one legend strip per row: each label twice in all (inputs) or
        // once (the row-specific twin entries), never once per panel.
        assert_eq!(svg.matches("corrupted input masks").count(), 2);
        assert_eq!(svg.matches("twin, label mode, held-out views").count(), 1);
        assert_eq!(svg.matches("twin, overlay mode, same views").count(), 1);
        assert_eq!(
            svg.matches("IoU on the corrupted training views").count(),
            3
        );
    }
}
