//! The survey timeline on a partitioned twin: a twin whose model was merged from a block plan
//! (`blocks`). Each such survey keeps a record (`surveys/<name>/blocks.json`) naming the plan its
//! model came from and which blocks were trained for it and which were kept from the survey
//! before. `twin detect` attributes the changes it finds to blocks (`changed`); `twin update`
//! retrains only the changed blocks of a plan derived for the new survey (same cuts, its photos)
//! through the same engines, then merges them with the unchanged blocks of the previous model
//! kept as they were (`update`). docs/CLUSTER.md and docs/TIMELINE.md.

pub mod changed;
pub mod update;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::blocks::Plan;
use crate::scene::files::read_text;
use crate::timeline::twin::{TimelineError, Twin};

/// The record's file name inside a survey's folder.
pub const BLOCKS_FILE: &str = "blocks.json";
/// What `format` holds.
pub const BLOCKS_FORMAT: &str = "damage-twin-survey-blocks";
/// Largest record read (it lists block indices).
const MAX_RECORD_BYTES: u64 = 4 << 20;

/// How a survey's model was made from blocks (`surveys/<name>/blocks.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SurveyBlocks {
    pub format: String,
    /// The plan folder the model was merged from (absolute: the shared directory).
    pub plan: PathBuf,
    /// The digest of that plan when the model was recorded.
    pub plan_digest: String,
    /// The survey whose model the kept blocks came from (None: every block was trained on this
    /// survey's photos).
    pub previous: Option<String>,
    /// Blocks trained on this survey's photos.
    pub trained: Vec<usize>,
    /// Blocks kept as they were in `previous`'s model (unchanged, or too few photos now).
    pub kept: Vec<usize>,
}

impl SurveyBlocks {
    /// The record of a model merged from every block of `plan` (in `plan_dir`).
    pub fn whole(plan_dir: &Path, plan: &Plan) -> SurveyBlocks {
        SurveyBlocks {
            format: BLOCKS_FORMAT.into(),
            plan: plan_dir.to_path_buf(),
            plan_digest: plan.digest(),
            previous: None,
            trained: (0..plan.blocks.len())
                .filter(|&k| plan.blocks[k].skipped.is_none())
                .collect(),
            kept: Vec::new(),
        }
    }
}

fn io(path: &Path, message: impl std::fmt::Display) -> TimelineError {
    TimelineError::Io {
        path: path.to_path_buf(),
        message: message.to_string(),
    }
}

/// Survey `name`'s block record, or None for a model not made from blocks.
pub fn load_survey_blocks(twin: &Twin, name: &str) -> Result<Option<SurveyBlocks>, TimelineError> {
    let path = twin.survey_file(name, BLOCKS_FILE)?;
    if !path.exists() {
        return Ok(None);
    }
    let text = read_text(&path, MAX_RECORD_BYTES)?;
    let record: SurveyBlocks = serde_json::from_str(&text)
        .map_err(|e| io(&path, format!("not a survey's block record: {e}")))?;
    if record.format != BLOCKS_FORMAT {
        return Err(io(
            &path,
            format!("format is {:?}, not {BLOCKS_FORMAT:?}", record.format),
        ));
    }
    Ok(Some(record))
}

/// Records that survey `name`'s model was merged from every block of the plan in `plan_dir`
/// (`twin new --plan`), written as `Twin::save_model` writes (inside the caller's `commit`, with
/// the model). The plan must be of the survey's dataset.
pub fn record_plan(twin: &mut Twin, name: &str, plan_dir: &Path) -> Result<(), TimelineError> {
    let plan = crate::blocks::load_plan(plan_dir)?;
    let dataset = twin.resolve(&twin.survey(name)?.dataset);
    let same = match (
        std::fs::canonicalize(&plan.dataset),
        std::fs::canonicalize(&dataset),
    ) {
        (Ok(a), Ok(b)) => a == b,
        _ => crate::timeline::twin::same_folder(&plan.dataset, &dataset),
    };
    if !same {
        return Err(io(
            &crate::blocks::plan_file(plan_dir),
            format!(
                "the plan is of {}, not of survey `{name}`'s dataset {}",
                plan.dataset.display(),
                dataset.display()
            ),
        ));
    }
    let dir =
        std::fs::canonicalize(crate::blocks::plan_folder(plan_dir)).map_err(|e| io(plan_dir, e))?;
    let record = SurveyBlocks::whole(&dir, &plan);
    twin.write_survey_json(name, BLOCKS_FILE, &record).map(drop)
}
