//! The hierarchy study's rows as CSV, a Markdown table and the speed-against-accuracy chart
//! (`report::tradeoff_chart`, each method one point).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::report::ChartError;
use crate::report::tradeoff_chart::{
    TimeAxis, TradeoffPoint, write_tradeoff_chart, write_tradeoff_chart_on,
};
use crate::studies::hierarchy::rows::HierarchyRow;

impl From<&HierarchyRow> for TradeoffPoint {
    fn from(row: &HierarchyRow) -> TradeoffPoint {
        TradeoffPoint {
            label: row.method.name().to_string(),
            seconds: row.seconds,
            iou: row.iou.clone(),
            psnr: row.psnr,
        }
    }
}

/// Writes the chart of `rows` against wall time as `<stem>.png` and `<stem>.svg` into `dir`,
/// and, when every row has its CPU seconds, against CPU time as `<stem>-cpu.png` and `.svg`.
pub fn write_hierarchy_chart(
    dir: &Path,
    stem: &str,
    rows: &[HierarchyRow],
) -> Result<Vec<PathBuf>, ChartError> {
    let points: Vec<TradeoffPoint> = rows.iter().map(TradeoffPoint::from).collect();
    let mut written = write_tradeoff_chart(dir, stem, &points)?;
    let on_cpu: Option<Vec<TradeoffPoint>> = rows
        .iter()
        .map(|row| {
            Some(TradeoffPoint {
                seconds: row.cpu_seconds?,
                ..TradeoffPoint::from(row)
            })
        })
        .collect();
    if let Some(points) = on_cpu.filter(|p| !p.is_empty()) {
        let cpu_stem = format!("{stem}-cpu");
        written.extend(write_tradeoff_chart_on(
            dir,
            &cpu_stem,
            &points,
            TimeAxis::Cpu,
        )?);
    }
    Ok(written)
}

/// A figure with `decimals` decimals, empty where missing.
fn or_blank(value: Option<f64>, decimals: usize) -> String {
    value.map_or(String::new(), |v| format!("{v:.decimals$}"))
}

fn classes(rows: &[HierarchyRow]) -> Vec<String> {
    rows.iter()
        .flat_map(|r| r.iou.keys().cloned())
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect()
}

/// The rows as CSV: method, seconds, cpu_seconds (empty where not recorded), psnr, gaussians,
/// then one IoU column per class.
pub fn hierarchy_csv(rows: &[HierarchyRow]) -> String {
    let classes = classes(rows);
    let mut out = String::from("method,seconds,cpu_seconds,psnr,gaussians");
    for c in &classes {
        let _ = write!(out, ",iou_{c}");
    }
    out.push('\n');
    for r in rows {
        let _ = write!(
            out,
            "{},{:.1},{},{:.3},{}",
            r.method.name(),
            r.seconds,
            or_blank(r.cpu_seconds, 1),
            r.psnr,
            r.gaussians
        );
        for c in &classes {
            let _ = write!(out, ",{:.4}", r.iou.get(c).copied().unwrap_or(f64::NAN));
        }
        out.push('\n');
    }
    out
}

/// The rows as a Markdown table (for docs/).
pub fn hierarchy_table(rows: &[HierarchyRow]) -> String {
    let classes = classes(rows);
    let mut out = String::from("| method | wall time | CPU time | PSNR |");
    for c in &classes {
        let _ = write!(out, " {c} IoU |");
    }
    out.push_str(" Gaussians |\n|---|---|---|---|");
    for _ in &classes {
        out.push_str("---|");
    }
    out.push_str("---|\n");
    for r in rows {
        let _ = write!(
            out,
            "| {} | {:.0} s | {} | {:.2} dB |",
            r.method.name(),
            r.seconds,
            r.cpu_seconds
                .map_or("–".to_string(), |cpu| format!("{cpu:.0} s")),
            r.psnr
        );
        for c in &classes {
            let _ = write!(out, " {:.3} |", r.iou.get(c).copied().unwrap_or(f64::NAN));
        }
        let _ = writeln!(out, " {} |", r.gaussians);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(serde::Deserialize)]
    struct Study {
        rows: Vec<HierarchyRow>,
    }

    #[test]
    fn the_csv_of_the_saved_study_is_the_one_in_docs() {
        let json = include_str!("../../../docs/figures/hierarchy-study.json");
        let study: Study = serde_json::from_str(json).expect("the study in docs/ parses");
        let csv = include_str!("../../../docs/figures/hierarchy-study.csv");
        assert_eq!(hierarchy_csv(&study.rows), csv);
        let table = hierarchy_table(&study.rows);
        assert_eq!(table.lines().count(), study.rows.len() + 2);
    }
}
