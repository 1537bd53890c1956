//! The stability study's chart: one column per axis (textureless, views, pose noise, mask noise,
//! scale), held-out PSNR on top and held-out IoU per damage class below, against the axis's
//! settings in ascending order. Presentation only: the figures arrive measured.

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::report::ChartError;
use crate::studies::stability::row::StabilityRow;

type DrawResult = Result<(), Box<dyn std::error::Error>>;

/// The axes in the order they are drawn, with their x-axis captions.
const AXES: [(&str, &str); 5] = [
    ("textureless", "flat component colours (0: textured)"),
    ("views", "training views"),
    ("pose_noise", "pose noise (degrees)"),
    ("mask_noise", "mask corruption rate"),
    ("scale", "training downscale factor"),
];

const CLASSES: [(&str, RGBColor); 3] = [
    ("crack", RGBColor(200, 40, 40)),
    ("spalling", RGBColor(40, 140, 60)),
    ("rebar", RGBColor(40, 80, 200)),
];

fn label(value: f64) -> String {
    if value.fract() == 0.0 {
        format!("{value:.0}")
    } else {
        format!("{value}")
    }
}

/// How one panel is labelled.
struct Panel<'a> {
    caption: String,
    x_desc: &'a str,
    y_desc: &'a str,
    y_range: std::ops::Range<f64>,
    legend: bool,
}

/// One panel: `series` of (name, colour, y per row) against the rows' settings, as categories.
fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    panel: Panel,
    rows: &[&StabilityRow],
    series: &[(&str, RGBColor, Vec<f64>)],
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let Panel {
        caption,
        x_desc,
        y_desc,
        y_range,
        legend,
    } = panel;
    let n = rows.len().max(1);
    let labels: Vec<String> = rows.iter().map(|r| label(r.value)).collect();
    let mut chart = ChartBuilder::on(area)
        .caption(&caption, ("sans-serif", 16))
        .margin(10)
        .x_label_area_size(34)
        .y_label_area_size(46)
        .build_cartesian_2d(-0.5..(n as f64 - 0.5), y_range)?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .x_labels(n)
        .x_label_formatter(&|x| {
            let i = x.round();
            if (x - i).abs() < 1e-6 && i >= 0.0 {
                labels.get(i as usize).cloned().unwrap_or_default()
            } else {
                String::new()
            }
        })
        .draw()?;
    for (name, colour, ys) in series {
        let points: Vec<(f64, f64)> = ys
            .iter()
            .enumerate()
            .filter(|(_, y)| y.is_finite())
            .map(|(i, &y)| (i as f64, y))
            .collect();
        chart
            .draw_series(LineSeries::new(points.clone(), colour.stroke_width(2)))?
            .label(*name)
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 16, y)], colour.stroke_width(2)));
        chart.draw_series(
            points
                .into_iter()
                .map(|p| Circle::new(p, 4, colour.filled())),
        )?;
    }
    if legend {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerLeft)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK.mix(0.3))
            .draw()?;
    }
    Ok(())
}

fn draw<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, rows: &[StabilityRow]) -> DrawResult
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let axes: Vec<(&str, &str)> = AXES
        .iter()
        .copied()
        .filter(|(axis, _)| rows.iter().any(|r| r.axis == *axis))
        .collect();
    let psnrs = rows.iter().map(|r| r.psnr).filter(|p| p.is_finite());
    let (lo, hi) = psnrs.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
        (lo.min(p), hi.max(p))
    });
    let (lo, hi) = if lo <= hi { (lo, hi) } else { (0.0, 1.0) };
    let psnr_range = (lo - 1.0).floor()..(hi + 1.0).ceil();
    let panels = root.split_evenly((2, axes.len().max(1)));
    for (column, (axis, x_desc)) in axes.iter().enumerate() {
        let mut of_axis: Vec<&StabilityRow> = rows.iter().filter(|r| r.axis == *axis).collect();
        of_axis.sort_by(|a, b| a.value.total_cmp(&b.value));
        let psnr = vec![(
            "PSNR",
            RGBColor(30, 30, 30),
            of_axis.iter().map(|r| r.psnr).collect(),
        )];
        let top = Panel {
            caption: format!("{axis}: held-out PSNR"),
            x_desc,
            y_desc: "PSNR (dB)",
            y_range: psnr_range.clone(),
            legend: false,
        };
        draw_panel(&panels[column], top, &of_axis, &psnr)?;
        let iou: Vec<(&str, RGBColor, Vec<f64>)> = CLASSES
            .iter()
            .map(|(class, colour)| {
                let ys = of_axis
                    .iter()
                    .map(|r| r.iou.get(*class).copied().unwrap_or(f64::NAN))
                    .collect();
                (*class, *colour, ys)
            })
            .collect();
        let bottom = Panel {
            caption: format!("{axis}: held-out IoU"),
            x_desc,
            y_desc: "IoU",
            y_range: 0.0..1.0,
            // One legend, in the first column, so it hides no other panel's points.
            legend: column == 0,
        };
        draw_panel(&panels[axes.len() + column], bottom, &of_axis, &iou)?;
    }
    root.present()?;
    Ok(())
}

/// Writes `<stem>.png` and `<stem>.svg` into `dir`, one 380 px wide column per axis.
pub fn write_stability_chart(
    dir: &Path,
    stem: &str,
    rows: &[StabilityRow],
) -> Result<Vec<PathBuf>, ChartError> {
    let columns = AXES
        .iter()
        .filter(|(axis, _)| rows.iter().any(|r| r.axis == *axis))
        .count()
        .max(1) as u32;
    let size = (380 * columns, 640);
    let png = dir.join(format!("{stem}.png"));
    let svg = dir.join(format!("{stem}.svg"));
    draw(BitMapBackend::new(&png, size).into_drawing_area(), rows)
        .map_err(|e| ChartError::new(&png, e))?;
    draw(SVGBackend::new(&svg, size).into_drawing_area(), rows)
        .map_err(|e| ChartError::new(&svg, e))?;
    Ok(vec![png, svg])
}
