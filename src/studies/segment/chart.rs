//! The segmentation study's chart: left, the model's IoU per crack set at each (scale, tile)
//! setting; right, the demo building's crack IoU against the truth — the model's masks and the
//! twin trained on them, on the training and held-out views. Presentation only.

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::report::ChartError;
use crate::studies::segment::rows::SegmentStudy;

type DrawResult = Result<(), Box<dyn std::error::Error>>;

const SET_COLOURS: [(&str, RGBColor); 3] = [
    ("crackforest", RGBColor(40, 90, 200)),
    ("tunnel", RGBColor(200, 90, 20)),
    ("welding", RGBColor(40, 150, 60)),
];

fn draw_sets<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, study: &SegmentStudy) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let settings = &study.config.settings;
    let n = settings.len().max(1);
    let mut chart = ChartBuilder::on(area)
        .caption("crack model IoU by scale and tile", ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(48)
        .build_cartesian_2d(-0.5..(n as f64 - 0.5), 0.0..1.0)?;
    chart
        .configure_mesh()
        .x_labels(n)
        .x_label_formatter(&|x| {
            let i = x.round() as usize;
            settings
                .get(i)
                .map(|(s, t)| format!("scale {s}, tile {t}"))
                .unwrap_or_default()
        })
        .y_desc("IoU (per-image mean)")
        .draw()?;
    for (set, colour) in SET_COLOURS {
        let points: Vec<(f64, f64)> = settings
            .iter()
            .enumerate()
            .filter_map(|(i, (s, t))| {
                study
                    .crack_sets
                    .iter()
                    .find(|r| r.set == set && &r.scale == s && r.tile == *t)
                    .map(|r| (i as f64, r.iou))
            })
            .collect();
        if points.is_empty() {
            continue;
        }
        chart
            .draw_series(LineSeries::new(points.clone(), colour.stroke_width(2)))?
            .label(set)
            .legend(move |(x, y)| Rectangle::new([(x, y - 4), (x + 16, y + 4)], colour.filled()));
        chart.draw_series(
            points
                .into_iter()
                .map(|p| Circle::new(p, 4, colour.filled())),
        )?;
    }
    chart
        .configure_series_labels()
        .border_style(BLACK)
        .background_style(WHITE.mix(0.8))
        .draw()?;
    Ok(())
}

fn draw_demo<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, study: &SegmentStudy) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let Some(demo) = &study.demo else {
        return Ok(());
    };
    let bars = [
        (
            "model, training views",
            demo.model_iou,
            RGBColor(200, 60, 60),
        ),
        ("twin, training views", demo.twin_iou, RGBColor(40, 90, 200)),
        (
            "model, held-out",
            demo.model_heldout_iou,
            RGBColor(230, 140, 140),
        ),
        (
            "twin, held-out",
            demo.twin_heldout_iou,
            RGBColor(120, 160, 230),
        ),
    ];
    let top = bars.iter().map(|b| b.1).fold(0.1, f64::max) * 1.25;
    let mut chart = ChartBuilder::on(area)
        .caption(
            "demo building: crack IoU against the truth",
            ("sans-serif", 18),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(48)
        .build_cartesian_2d(-0.5..(bars.len() as f64 - 0.5), 0.0..top)?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(bars.len())
        .x_label_formatter(&|x| {
            bars.get(x.round() as usize)
                .map(|b| b.0.to_string())
                .unwrap_or_default()
        })
        .y_desc("crack IoU (pooled)")
        .draw()?;
    for (i, (_, value, colour)) in bars.iter().enumerate() {
        let x = i as f64;
        chart.draw_series(std::iter::once(Rectangle::new(
            [(x - 0.35, 0.0), (x + 0.35, *value)],
            colour.filled(),
        )))?;
        chart.draw_series(std::iter::once(Text::new(
            format!("{value:.3}"),
            (x - 0.15, *value + top * 0.03),
            ("sans-serif", 13),
        )))?;
    }
    Ok(())
}

fn draw<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, study: &SegmentStudy) -> DrawResult
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let panels = root.split_evenly((1, 2));
    draw_sets(&panels[0], study)?;
    draw_demo(&panels[1], study)?;
    root.present()?;
    Ok(())
}

/// Writes `<stem>.png` and `<stem>.svg` into `dir` (two 640×450 px panels).
pub fn write_segment_chart(
    dir: &Path,
    stem: &str,
    study: &SegmentStudy,
) -> Result<Vec<PathBuf>, ChartError> {
    let size = (1280, 450);
    let png = dir.join(format!("{stem}.png"));
    let svg = dir.join(format!("{stem}.svg"));
    draw(BitMapBackend::new(&png, size).into_drawing_area(), study)
        .map_err(|e| ChartError::new(&png, e))?;
    draw(SVGBackend::new(&svg, size).into_drawing_area(), study)
        .map_err(|e| ChartError::new(&svg, e))?;
    Ok(vec![png, svg])
}
