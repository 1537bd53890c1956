//! The hierarchy study's rows as CSV, a Markdown table and the speed-against-accuracy chart
//! (`report::tradeoff_chart`, each method one point).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::report::ChartError;
use crate::report::tradeoff_chart::{TradeoffPoint, write_tradeoff_chart};
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

/// Writes the chart of `rows` as `<stem>.png` and `<stem>.svg` into `dir`.
pub fn write_hierarchy_chart(
    dir: &Path,
    stem: &str,
    rows: &[HierarchyRow],
) -> Result<Vec<PathBuf>, ChartError> {
    let points: Vec<TradeoffPoint> = rows.iter().map(TradeoffPoint::from).collect();
    write_tradeoff_chart(dir, stem, &points)
}

fn classes(rows: &[HierarchyRow]) -> Vec<String> {
    rows.iter()
        .flat_map(|r| r.iou.keys().cloned())
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect()
}

/// The rows as CSV: method, seconds, psnr, gaussians, then one IoU column per class.
pub fn hierarchy_csv(rows: &[HierarchyRow]) -> String {
    let classes = classes(rows);
    let mut out = String::from("method,seconds,psnr,gaussians");
    for c in &classes {
        let _ = write!(out, ",iou_{c}");
    }
    out.push('\n');
    for r in rows {
        let _ = write!(
            out,
            "{},{:.1},{:.3},{}",
            r.method.name(),
            r.seconds,
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
    let mut out = String::from("| method | wall time | PSNR |");
    for c in &classes {
        let _ = write!(out, " {c} IoU |");
    }
    out.push_str(" Gaussians |\n|---|---|---|");
    for _ in &classes {
        out.push_str("---|");
    }
    out.push_str("---|\n");
    for r in rows {
        let _ = write!(
            out,
            "| {} | {:.0} s | {:.2} dB |",
            r.method.name(),
            r.seconds,
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
