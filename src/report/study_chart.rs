//! The mask-noise study as a chart (plotters, SVG and PNG) and a Markdown table: per class, IoU
//! against the clean masks over the corruption rate, for the corrupted inputs and for the twin
//! (each mode, training and held-out views).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::damage::study::StudyRow;
use crate::damage::{DamageClass, TrainMode};

type DrawResult = Result<(), Box<dyn std::error::Error>>;

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
        .x_desc("fraction of training views with corrupted masks")
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
    let grey = RGBColor(90, 90, 90);
    chart
        .draw_series(LineSeries::new(input.iter().copied(), grey.stroke_width(2)))?
        .label("corrupted input masks")
        .legend(move |(x, y)| PathElement::new([(x, y), (x + 18, y)], grey.stroke_width(2)));
    chart.draw_series(
        input
            .iter()
            .map(|&p| Cross::new(p, 5, grey.stroke_width(2))),
    )?;
    for mode in modes(rows) {
        let colour = mode_colour(mode);
        if views == Views::Corrupted {
            let twin = series(rows, class, Some(mode), |r| r.twin_iou_noisy_views);
            chart
                .draw_series(LineSeries::new(
                    twin.iter().copied(),
                    colour.stroke_width(3),
                ))?
                .label(format!("twin, {mode} mode, same views"))
                .legend(move |(x, y)| {
                    PathElement::new([(x, y), (x + 18, y)], colour.stroke_width(3))
                });
            chart.draw_series(twin.iter().map(|&p| Circle::new(p, 4, colour.filled())))?;
            continue;
        }
        let heldout = series(rows, class, Some(mode), |r| r.twin_iou_heldout);
        chart
            .draw_series(LineSeries::new(
                heldout.iter().copied(),
                colour.stroke_width(3),
            ))?
            .label(format!("twin, {mode} mode, held-out views"))
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 18, y)], colour.stroke_width(3)));
        chart.draw_series(heldout.iter().map(|&p| Circle::new(p, 4, colour.filled())))?;
        let train = series(rows, class, Some(mode), |r| r.twin_iou_train);
        let light = colour.mix(0.6);
        chart
            .draw_series(DashedLineSeries::new(
                train.iter().copied(),
                6,
                4,
                light.stroke_width(2),
            ))?
            .label(format!("twin, {mode} mode, training views"))
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 18, y)], light.stroke_width(2)));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerLeft)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.3))
        .draw()?;
    Ok(())
}

fn draw<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, rows: &[StudyRow]) -> DrawResult
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let classes = classes(rows);
    let areas = root.split_evenly((2, classes.len().max(1)));
    for (k, class) in classes.iter().enumerate() {
        panel(&areas[k], rows, *class, Views::All)?;
        panel(&areas[classes.len() + k], rows, *class, Views::Corrupted)?;
    }
    root.present()?;
    Ok(())
}

/// Writes `<stem>.png` and `<stem>.svg` into `dir`.
pub fn write_study_chart(
    dir: &Path,
    stem: &str,
    rows: &[StudyRow],
) -> Result<Vec<PathBuf>, String> {
    let width = 520 * classes(rows).len().max(1) as u32;
    let png = dir.join(format!("{stem}.png"));
    let svg = dir.join(format!("{stem}.svg"));
    draw(
        BitMapBackend::new(&png, (width, 1000)).into_drawing_area(),
        rows,
    )
    .map_err(|e| format!("drawing {}: {e}", png.display()))?;
    draw(
        SVGBackend::new(&svg, (width, 1000)).into_drawing_area(),
        rows,
    )
    .map_err(|e| format!("drawing {}: {e}", svg.display()))?;
    Ok(vec![png, svg])
}

/// The rows as a Markdown table (for docs/).
pub fn study_table(rows: &[StudyRow]) -> String {
    let mut text = String::from(
        "| mode | rate | class | input IoU | twin IoU (train views) | twin IoU (held-out) | twin F1 (held-out) | input IoU (corrupted views) | twin IoU (corrupted views) | corrupted pixels corrected |\n\
         |---|---|---|---|---|---|---|---|---|---|\n",
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
                100.0 * r.corrupted_pixels_corrected,
                r.corrupted_pixels
            )
        } else {
            "–".to_string()
        };
        let _ = writeln!(
            text,
            "| {} | {:.2} | {} | {} | {} | {} | {} | {} | {} | {} |",
            r.mode,
            r.rate,
            r.class,
            value(r.input_iou),
            value(r.twin_iou_train),
            value(r.twin_iou_heldout),
            value(r.twin_f1_heldout),
            value(r.input_iou_noisy_views),
            value(r.twin_iou_noisy_views),
            corrected
        );
    }
    text
}

/// The rows as CSV.
pub fn study_csv(rows: &[StudyRow]) -> String {
    let mut text = String::from(
        "mode,rate,class,input_iou,twin_iou_train,twin_iou_heldout,twin_f1_heldout,\
         twin_precision_heldout,twin_recall_heldout,input_iou_noisy_views,twin_iou_noisy_views,\
         corrupted_pixels,corrupted_pixels_corrected,noisy_views,train_seconds,gaussians,heldout_psnr\n",
    );
    for r in rows {
        let _ = writeln!(
            text,
            "{},{},{},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{},{:.5},{},{:.2},{},{}",
            r.mode,
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
            r.corrupted_pixels_corrected,
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
