//! Speed against accuracy (DESIGN.md "Measuring"): per method (or a project's step) one mark of
//! held-out IoU (per class) and PSNR against wall (or CPU) time, as PNG and SVG files or an SVG string.
//! Presentation only: the figures arrive measured (the hierarchy study's rows become points in
//! `studies::hierarchy::table`).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::report::ChartError;
use crate::report::chart_range::{padded_range, plottable};

type DrawResult = Result<(), Box<dyn std::error::Error>>;

/// Class colours of the chart (the damage palette, darkened where it is too pale on white).
fn class_colour(class: &str) -> RGBColor {
    match class {
        "crack" => RGBColor(220, 30, 30),
        "spalling" => RGBColor(200, 110, 150),
        "rebar" => RGBColor(190, 160, 0),
        _ => RGBColor(80, 80, 80),
    }
}

fn span(values: impl Iterator<Item = f64>, pad_fraction: f64) -> (f64, f64) {
    padded_range(values, |lo, hi| ((hi - lo) * pad_fraction).max(1e-3)).unwrap_or((0.0, 1.0))
}

/// One mark: what ran, its wall time, and what it reached (IoU per class where measured; PSNR
/// NaN where not).
#[derive(Clone, Debug, PartialEq)]
pub struct TradeoffPoint {
    pub label: String,
    pub seconds: f64,
    pub iou: BTreeMap<String, f64>,
    pub psnr: f64,
}

/// What a chart's seconds are: wall time, or CPU time (user + system), the cost that stays
/// honest on a shared host.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TimeAxis {
    Wall,
    Cpu,
}

impl TimeAxis {
    fn caption(self) -> &'static str {
        match self {
            TimeAxis::Wall => "wall time",
            TimeAxis::Cpu => "CPU time",
        }
    }

    fn unit(self) -> &'static str {
        match self {
            TimeAxis::Wall => "seconds",
            TimeAxis::Cpu => "CPU seconds (user + system)",
        }
    }
}

fn draw<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    rows: &[TradeoffPoint],
    axis: TimeAxis,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    // Marks a chart cannot place (a corrupted file's 1e308 seconds) are left out.
    let rows: Vec<TradeoffPoint> = rows
        .iter()
        .filter(|r| plottable(r.seconds))
        .map(|r| TradeoffPoint {
            iou: r
                .iou
                .iter()
                .filter(|&(_, &v)| plottable(v))
                .map(|(k, &v)| (k.clone(), v))
                .collect(),
            ..r.clone()
        })
        .collect();
    let (left, right) = root.split_horizontally(root.dim_in_pixel().0 / 2);
    // A fifth of the span on the right: each mark's name is written to its right, and at 0.1
    // the rightmost names were cut off.
    let (x0, x1) = span(rows.iter().map(|r| r.seconds), 0.2);
    let x = (x0.min(0.0), x1);
    let classes: Vec<String> = rows
        .iter()
        .flat_map(|r| r.iou.keys().cloned())
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect();

    // IoU per class against seconds.
    let (y0, y1) = span(rows.iter().flat_map(|r| r.iou.values().copied()), 0.15);
    // IoU lies in [0, 1]; values a file holds outside it would leave an empty axis.
    let (y0, y1) = match (y0.max(0.0), y1.min(1.0)) {
        (y0, y1) if y0 < y1 => (y0, y1),
        _ => (0.0, 1.0),
    };
    let mut chart = ChartBuilder::on(&left)
        .caption(
            format!("held-out IoU against {}", axis.caption()),
            ("sans-serif", 18),
        )
        .margin(10)
        .x_label_area_size(36)
        .y_label_area_size(48)
        .build_cartesian_2d(x.0..x.1, y0..y1)?;
    chart
        .configure_mesh()
        .x_desc(axis.unit())
        .y_desc("IoU")
        .draw()?;
    for class in &classes {
        let colour = class_colour(class);
        let points: Vec<(f64, f64)> = rows
            .iter()
            .filter_map(|r| r.iou.get(class).map(|&v| (r.seconds, v)))
            .collect();
        chart
            .draw_series(points.iter().map(|&p| Circle::new(p, 5, colour.filled())))?
            .label(class.as_str())
            .legend(move |(px, py)| Circle::new((px, py), 5, colour.filled()));
        for (row, &(sx, sy)) in rows
            .iter()
            .filter(|r| r.iou.contains_key(class))
            .zip(&points)
        {
            chart.draw_series(std::iter::once(Text::new(
                row.label.clone(),
                (sx, sy),
                ("sans-serif", 12).into_font().color(&colour),
            )))?;
        }
    }
    chart
        .configure_series_labels()
        .border_style(BLACK)
        .background_style(WHITE.mix(0.8))
        .position(SeriesLabelPosition::LowerRight)
        .draw()?;

    // PSNR against seconds.
    let (p0, p1) = span(rows.iter().map(|r| r.psnr), 0.15);
    let mut chart = ChartBuilder::on(&right)
        .caption(
            format!("held-out PSNR against {}", axis.caption()),
            ("sans-serif", 18),
        )
        .margin(10)
        .x_label_area_size(36)
        .y_label_area_size(48)
        .build_cartesian_2d(x.0..x.1, p0..p1)?;
    chart
        .configure_mesh()
        .x_desc(axis.unit())
        .y_desc("PSNR (dB)")
        .draw()?;
    let blue = RGBColor(40, 90, 200);
    for row in rows.iter().filter(|r| plottable(r.psnr)) {
        let p = (row.seconds, row.psnr);
        chart.draw_series(std::iter::once(Circle::new(p, 5, blue.filled())))?;
        chart.draw_series(std::iter::once(Text::new(
            row.label.clone(),
            p,
            ("sans-serif", 12).into_font().color(&blue),
        )))?;
    }
    root.present()?;
    Ok(())
}

/// Writes `<stem>.png` and `<stem>.svg` into `dir`, against wall time.
pub fn write_tradeoff_chart(
    dir: &Path,
    stem: &str,
    points: &[TradeoffPoint],
) -> Result<Vec<PathBuf>, ChartError> {
    write_tradeoff_chart_on(dir, stem, points, TimeAxis::Wall)
}

/// [`write_tradeoff_chart`] with the points' seconds being those `axis` says.
pub fn write_tradeoff_chart_on(
    dir: &Path,
    stem: &str,
    points: &[TradeoffPoint],
    axis: TimeAxis,
) -> Result<Vec<PathBuf>, ChartError> {
    let png = dir.join(format!("{stem}.png"));
    let svg = dir.join(format!("{stem}.svg"));
    draw(
        BitMapBackend::new(&png, (1200, 500)).into_drawing_area(),
        points,
        axis,
    )
    .map_err(|e| ChartError::new(&png, e))?;
    draw(
        SVGBackend::new(&svg, (1200, 500)).into_drawing_area(),
        points,
        axis,
    )
    .map_err(|e| ChartError::new(&svg, e))?;
    Ok(vec![png, svg])
}

/// The chart as an SVG document, for a page (`name` says which in an error).
pub fn tradeoff_svg(name: &Path, points: &[TradeoffPoint]) -> Result<String, ChartError> {
    let mut svg = String::new();
    draw(
        SVGBackend::with_string(&mut svg, (1200, 500)).into_drawing_area(),
        points,
        TimeAxis::Wall,
    )
    .map_err(|e| ChartError::new(name, e))?;
    Ok(svg)
}
