//! Training curves (plotters): loss, held-out PSNR and Gaussian count against wall time, as PNG
//! and SVG files or an SVG string, from the same `History` the viewer's live charts draw.
//! Presentation only.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::report::ChartError;
use crate::report::chart_range::{padded_range, plottable_point};
use crate::train::history::History;

type DrawResult = Result<(), Box<dyn std::error::Error>>;

fn range(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    // A flat series (the Gaussian count of an update) gets a band of 1 % around it.
    padded_range(values, |lo, hi| {
        ((hi - lo) * 0.05)
            .max(hi.abs().max(lo.abs()) * 0.01)
            .max(1e-9)
    })
}

fn panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    title: &str,
    y_label: &str,
    points: &[(f64, f64)],
    colour: RGBColor,
    markers: bool,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let points: Vec<(f64, f64)> = points.iter().copied().filter(plottable_point).collect();
    let x = range(points.iter().map(|p| p.0)).unwrap_or((0.0, 1.0));
    let y = range(points.iter().map(|p| p.1)).unwrap_or((0.0, 1.0));
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 18))
        .margin(8)
        .x_label_area_size(32)
        .y_label_area_size(56)
        .build_cartesian_2d(x.0..x.1, y.0..y.1)?;
    chart
        .configure_mesh()
        .x_desc("wall time (s)")
        .y_desc(y_label)
        .light_line_style(WHITE.mix(0.0))
        .draw()?;
    chart.draw_series(LineSeries::new(
        points.iter().copied(),
        colour.stroke_width(2),
    ))?;
    if markers {
        chart.draw_series(points.iter().map(|&p| Circle::new(p, 3, colour.filled())))?;
    }
    Ok(())
}

fn draw<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, history: &History) -> DrawResult
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let areas = root.split_evenly((3, 1));
    let loss: Vec<(f64, f64)> = history
        .series(|s| s.loss)
        .into_iter()
        .map(|[x, y]| (x, y))
        .collect();
    let psnr: Vec<(f64, f64)> = history
        .evals
        .iter()
        .filter(|e| e.psnr.is_finite())
        .map(|e| (e.wall_s, e.psnr))
        .collect();
    let count: Vec<(f64, f64)> = history
        .series(|s| s.gaussians as f64)
        .into_iter()
        .map(|[x, y]| (x, y))
        .collect();
    panel(
        &areas[0],
        "Training loss",
        "loss",
        &loss,
        RGBColor(200, 60, 40),
        false,
    )?;
    panel(
        &areas[1],
        "Held-out PSNR",
        "dB",
        &psnr,
        RGBColor(40, 90, 200),
        true,
    )?;
    panel(
        &areas[2],
        "Gaussians",
        "count",
        &count,
        RGBColor(40, 150, 80),
        false,
    )?;
    root.present()?;
    Ok(())
}

/// Writes `training.png` and `training.svg` into `dir`.
pub fn write_training_charts(
    dir: &Path,
    history: &History,
) -> Result<Vec<std::path::PathBuf>, ChartError> {
    let png = dir.join("training.png");
    let svg = dir.join("training.svg");
    draw(
        BitMapBackend::new(&png, (900, 900)).into_drawing_area(),
        history,
    )
    .map_err(|e| ChartError::new(&png, e))?;
    draw(
        SVGBackend::new(&svg, (900, 900)).into_drawing_area(),
        history,
    )
    .map_err(|e| ChartError::new(&svg, e))?;
    Ok(vec![png, svg])
}

/// The curves as an SVG document, for a page (`name` says which in an error).
pub fn training_svg(name: &Path, history: &History) -> Result<String, ChartError> {
    let mut svg = String::new();
    draw(
        SVGBackend::with_string(&mut svg, (900, 720)).into_drawing_area(),
        history,
    )
    .map_err(|e| ChartError::new(name, e))?;
    Ok(svg)
}
