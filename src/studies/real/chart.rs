//! The real-photo study's chart, four panels: the crack model per photo against the truth; the
//! twins' IoU per class; change detection against survey 2; the measured quantities' errors.
//! Presentation only.

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::report::ChartError;
use crate::studies::real::rows::{ClassFigures, RealStudy};

type DrawResult = Result<(), Box<dyn std::error::Error>>;

const COLOURS: [RGBColor; 5] = [
    RGBColor(40, 90, 200),
    RGBColor(200, 90, 20),
    RGBColor(40, 150, 60),
    RGBColor(150, 60, 160),
    RGBColor(120, 120, 120),
];

/// One panel of grouped bars: `groups` along x, one bar per series in each.
struct Bars<'a> {
    caption: &'a str,
    y_desc: &'a str,
    groups: Vec<String>,
    /// (series name, one value per group; NaN: no bar).
    series: Vec<(String, Vec<f64>)>,
    range: (f64, f64),
}

fn draw_bars<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, bars: &Bars) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let n = bars.groups.len().max(1);
    let mut chart = ChartBuilder::on(area)
        .caption(bars.caption, ("sans-serif", 17))
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(48)
        .build_cartesian_2d(-0.5..(n as f64 - 0.5), bars.range.0..bars.range.1)?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(n.min(30))
        .x_label_formatter(&|x| {
            bars.groups
                .get(x.round() as usize)
                .cloned()
                .unwrap_or_default()
        })
        .y_desc(bars.y_desc)
        .draw()?;
    let width = 0.8 / bars.series.len().max(1) as f64;
    for (s, (name, values)) in bars.series.iter().enumerate() {
        let colour = COLOURS[s % COLOURS.len()];
        let rects = values
            .iter()
            .enumerate()
            .filter(|(_, v)| v.is_finite())
            .map(|(g, &v)| {
                let left = g as f64 - 0.4 + s as f64 * width;
                Rectangle::new([(left, 0.0), (left + width * 0.9, v)], colour.filled())
            });
        chart
            .draw_series(rects)?
            .label(name.as_str())
            .legend(move |(x, y)| Rectangle::new([(x, y - 4), (x + 16, y + 4)], colour.filled()));
    }
    chart
        .configure_series_labels()
        .border_style(BLACK)
        .background_style(WHITE.mix(0.8))
        .draw()?;
    Ok(())
}

/// The value of `class` in `figures` through `f` (NaN when absent).
fn of(figures: &[ClassFigures], class: &str, f: fn(&ClassFigures) -> f64) -> f64 {
    figures
        .iter()
        .find(|c| c.class == class)
        .map_or(f64::NAN, f)
}

fn panels(study: &RealStudy) -> [Bars<'static>; 4] {
    let views: Vec<_> = study
        .segmenter_views
        .iter()
        .filter(|v| v.truth_pixels > 0)
        .collect();
    let segmenter = Bars {
        caption: "crack model per photo against the stamped truth",
        y_desc: "crack, photo size",
        groups: views.iter().map(|v| v.view.clone()).collect(),
        series: vec![
            ("IoU".into(), views.iter().map(|v| v.iou).collect()),
            (
                "precision".into(),
                views.iter().map(|v| v.precision).collect(),
            ),
            ("recall".into(), views.iter().map(|v| v.recall).collect()),
        ],
        range: (0.0, 1.05),
    };
    let classes = ["crack", "spalling", "rebar"];
    let iou = |c: &ClassFigures| c.iou;
    let mut series = vec![(
        "twin on truth masks".to_string(),
        classes
            .iter()
            .map(|c| of(&study.truth_twin.heldout, c, iou))
            .collect(),
    )];
    if let Some(refinement) = &study.refinement {
        series.push((
            "same, at photo size".into(),
            classes
                .iter()
                .map(|c| of(&refinement.coarse_heldout, c, iou))
                .collect(),
        ));
        series.push((
            "fine-tuned, photo size".into(),
            classes
                .iter()
                .map(|c| of(&refinement.refined_heldout, c, iou))
                .collect(),
        ));
    }
    let model = &study.segmented_twin;
    series.push((
        "crack model".into(),
        vec![model.model_heldout.iou, f64::NAN, f64::NAN],
    ));
    series.push((
        "twin on the model's masks".into(),
        vec![of(&model.twin.heldout, "crack", iou), f64::NAN, f64::NAN],
    ));
    let twins = Bars {
        caption: "held-out IoU against the truth",
        y_desc: "IoU",
        groups: classes.iter().map(|c| c.to_string()).collect(),
        series,
        range: (0.0, 1.05),
    };
    let change_classes: Vec<_> = study.change.iter().map(|c| c.class.clone()).collect();
    let change = Bars {
        caption: "new damage in survey 2 (twin detect defaults)",
        y_desc: "against truth/new-damage",
        groups: change_classes.clone(),
        series: vec![
            (
                "precision".into(),
                study.change.iter().map(|c| c.precision).collect(),
            ),
            (
                "recall".into(),
                study.change.iter().map(|c| c.recall).collect(),
            ),
        ],
        range: (0.0, 1.05),
    };
    let errors: Vec<f64> = study
        .quantities
        .iter()
        .map(|q| 100.0 * q.relative_error)
        .collect();
    let reach = errors.iter().fold(10.0_f64, |a, e| a.max(e.abs())) * 1.15;
    let quantities = Bars {
        caption: "survey 1's twin measured against the truth",
        y_desc: "error (%)",
        groups: study
            .quantities
            .iter()
            .map(|q| q.quantity.clone())
            .collect(),
        series: vec![("measured − true".into(), errors)],
        range: (-reach, reach),
    };
    [segmenter, twins, change, quantities]
}

fn draw<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, study: &RealStudy) -> DrawResult
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let areas = root.split_evenly((2, 2));
    for (area, bars) in areas.iter().zip(panels(study).iter()) {
        draw_bars(area, bars)?;
    }
    root.present()?;
    Ok(())
}

/// Writes `<stem>.png` and `<stem>.svg` into `dir` (four 640×420 px panels).
pub fn write_real_chart(
    dir: &Path,
    stem: &str,
    study: &RealStudy,
) -> Result<Vec<PathBuf>, ChartError> {
    let size = (1280, 840);
    let png = dir.join(format!("{stem}.png"));
    let svg = dir.join(format!("{stem}.svg"));
    draw(BitMapBackend::new(&png, size).into_drawing_area(), study)
        .map_err(|e| ChartError::new(&png, e))?;
    draw(SVGBackend::new(&svg, size).into_drawing_area(), study)
        .map_err(|e| ChartError::new(&svg, e))?;
    Ok(vec![png, svg])
}
