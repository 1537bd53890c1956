//! The update study: survey updates (`twin update`) run with different settings — steps, stopping
//! rule, the twin they start from, oracle hulls — gathered from their `metrics.json` into rows,
//! a Markdown table and one speed-against-accuracy chart (`report::tradeoff_chart`), each update
//! one mark of held-out IoU and survey 1's look against its wall time, with training the survey
//! from scratch as the cost it is measured against. The updates run as the CLI runs them; the
//! study only reads what they recorded, so each row is reproducible by its command.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::report::ChartError;
use crate::report::tradeoff_chart::{TradeoffPoint, write_tradeoff_chart};

/// One update, as its `metrics.json` recorded it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct UpdateRow {
    pub label: String,
    /// The whole update's wall time.
    pub seconds: f64,
    pub steps: u32,
    pub width: u32,
    pub height: u32,
    pub ms_per_step: f64,
    /// Held-out IoU of the survey before and after the update.
    pub iou_before: BTreeMap<String, f64>,
    pub iou_after: BTreeMap<String, f64>,
    /// Share of the held-out views' true damage pixels inside the hulls.
    pub hull_coverage: Option<BTreeMap<String, f64>>,
    /// Survey 1's held-out views outside damage, before and after.
    pub look_before: Option<f64>,
    pub look_after: Option<f64>,
    /// `seconds` over training the survey from scratch (when given).
    pub share_of_from_scratch: Option<f64>,
}

/// Why a row could not be read.
#[derive(Debug, thiserror::Error)]
pub enum UpdateStudyError {
    /// The file could not be read (the error names it).
    #[error(transparent)]
    Read(#[from] crate::scene::SceneError),
    #[error("{path}: not an update's metrics.json: {source}")]
    Parse {
        path: PathBuf,
        source: serde_json::Error,
    },
}

/// The parts of an update's `metrics.json` a row needs.
#[derive(Deserialize)]
struct Recorded {
    seconds: f64,
    previous_look_psnr_before: Option<f64>,
    previous_look_psnr_after: Option<f64>,
    refine: RecordedRefine,
}

#[derive(Deserialize)]
struct RecordedRefine {
    iterations: u32,
    width: u32,
    height: u32,
    ms_per_refine_step: f64,
    #[serde(default)]
    hull_coverage: Option<BTreeMap<String, f64>>,
    before: RecordedQuality,
    after: RecordedQuality,
}

#[derive(Deserialize)]
struct RecordedQuality {
    iou: BTreeMap<String, f64>,
}

/// The row of the update whose `metrics.json` is at `path`, labelled `label`;
/// `from_scratch_seconds` (training the survey from scratch, same host and sitting) gives its
/// share.
pub fn read_row(
    label: &str,
    path: &Path,
    from_scratch_seconds: Option<f64>,
) -> Result<UpdateRow, UpdateStudyError> {
    let bytes =
        crate::scene::files::read_regular(path, crate::scene::limits::MAX_PROJECT_JSON_BYTES)?;
    let recorded: Recorded =
        serde_json::from_slice(&bytes).map_err(|source| UpdateStudyError::Parse {
            path: path.to_path_buf(),
            source,
        })?;
    let r = recorded.refine;
    Ok(UpdateRow {
        label: label.to_string(),
        seconds: recorded.seconds,
        steps: r.iterations,
        width: r.width,
        height: r.height,
        ms_per_step: r.ms_per_refine_step,
        iou_before: r.before.iou,
        iou_after: r.after.iou,
        hull_coverage: r.hull_coverage,
        look_before: recorded.previous_look_psnr_before,
        look_after: recorded.previous_look_psnr_after,
        share_of_from_scratch: from_scratch_seconds
            .filter(|&s| s > 0.0)
            .map(|s| recorded.seconds / s),
    })
}

fn classes(rows: &[UpdateRow]) -> Vec<String> {
    rows.iter()
        .flat_map(|r| r.iou_after.keys().cloned())
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect()
}

/// The rows as a Markdown table: per class IoU before → after and the hulls' coverage.
pub fn update_table(rows: &[UpdateRow]) -> String {
    let classes = classes(rows);
    let mut out = String::from("| update | size | steps | seconds | share of from scratch |");
    for c in &classes {
        let _ = write!(out, " {c} IoU before → after | {c} in hulls |");
    }
    out.push_str(" survey 1's look before → after |\n|---|---|---|---|---|");
    out.push_str(&"---|---|".repeat(classes.len()));
    out.push_str("---|\n");
    let num =
        |v: Option<f64>, digits: usize| v.map_or("—".to_string(), |v| format!("{v:.digits$}"));
    for r in rows {
        let share = r
            .share_of_from_scratch
            .map_or("—".to_string(), |s| format!("{:.1} %", 100.0 * s));
        let _ = write!(
            out,
            "| {} | {}×{} | {} | {:.1} | {} |",
            r.label, r.width, r.height, r.steps, r.seconds, share
        );
        for c in &classes {
            let coverage = r.hull_coverage.as_ref().and_then(|h| h.get(c).copied());
            let _ = write!(
                out,
                " {} → {} | {} |",
                num(r.iou_before.get(c).copied(), 3),
                num(r.iou_after.get(c).copied(), 3),
                num(coverage, 3)
            );
        }
        let _ = writeln!(
            out,
            " {} → {} dB |",
            num(r.look_before, 2),
            num(r.look_after, 2)
        );
    }
    out
}

/// Writes the chart of `rows` (IoU after the update, and survey 1's look as the PSNR panel,
/// against the update's seconds) as `<stem>.png` and `<stem>.svg` into `dir`.
pub fn write_update_chart(
    dir: &Path,
    stem: &str,
    rows: &[UpdateRow],
) -> Result<Vec<PathBuf>, ChartError> {
    let points: Vec<TradeoffPoint> = rows
        .iter()
        .map(|r| TradeoffPoint {
            label: r.label.clone(),
            seconds: r.seconds,
            iou: r.iou_after.clone(),
            psnr: r.look_after.unwrap_or(f64::NAN),
        })
        .collect();
    write_tradeoff_chart(dir, stem, &points)
}
