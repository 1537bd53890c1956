//! The "Add survey…" dialog's fields as data: the dataset folder (picked or typed), the survey's
//! name and date, its alignment, and optionally the model its photos are segmented with. The
//! panel edits a copy, a file dialog fills a path in, and `request` turns the fields into the
//! library's `SurveyToAdd`: the checks and the work are `timeline::add_survey`'s, the same as
//! `twin add-survey`'s.

use std::path::{Path, PathBuf};

use crate::scene::project::Survey;
use crate::scene::survey_name::survey_name_from;
use crate::segment::{DEFAULT_THRESHOLD, SegmentSettings, parse_channel_classes};
use crate::timeline::Twin;
use crate::timeline::add_survey::{SegmentWith, SurveyToAdd};
use crate::timeline::survey::AlignMode;

/// The dialog's fields.
#[derive(Clone, Debug, PartialEq)]
pub struct AddSurveyForm {
    /// The survey's dataset folder, as typed or picked.
    pub dataset: String,
    pub name: String,
    /// YYYY-MM-DD.
    pub date: String,
    pub align: AlignMode,
    /// Segment the photos first ("Segment with…").
    pub segment: bool,
    /// The ONNX model, as typed or picked.
    pub model: String,
    /// The class of each output channel: `crack`, or `-,crack,spalling` for a multi-class model.
    pub classes: String,
    pub threshold: f32,
    /// Why the last try did not add the survey (shown in the dialog until the next try).
    pub error: Option<String>,
}

impl AddSurveyForm {
    /// An empty form for `twin`: dated today (or the latest survey's date when later), placed in
    /// the same frame, segmenting cracks at the default threshold when asked.
    pub fn for_project(twin: &Twin) -> AddSurveyForm {
        AddSurveyForm {
            dataset: String::new(),
            name: String::new(),
            date: twin.next_survey_date(),
            align: AlignMode::SameFrame,
            segment: false,
            model: String::new(),
            classes: "crack".into(),
            threshold: DEFAULT_THRESHOLD,
            error: None,
        }
    }

    /// `folder` as the dataset; an empty name becomes one from the folder's name, unused in
    /// `twin`.
    pub fn choose_dataset(&mut self, folder: &Path, twin: &Twin) {
        self.dataset = folder.display().to_string();
        if self.name.trim().is_empty()
            && let Some(base) = folder.file_name()
        {
            self.name = twin.unused_name(&survey_name_from(&base.to_string_lossy()));
        }
    }

    /// The survey the fields describe, or why they do not describe one yet. RGBA photos are
    /// composited on `background` (the project's).
    pub fn request(&self, background: [f32; 3]) -> Result<SurveyToAdd, String> {
        let dataset = self.dataset.trim();
        if dataset.is_empty() {
            return Err("choose the survey's dataset folder".into());
        }
        let name = self.name.trim();
        Survey::check_name(name).map_err(|e| e.to_string())?;
        let segment = if self.segment {
            let model = self.model.trim();
            if model.is_empty() {
                return Err("choose the ONNX model to segment the photos with".into());
            }
            let classes = parse_channel_classes(&self.classes).map_err(|e| e.to_string())?;
            Some(SegmentWith {
                model: PathBuf::from(model),
                settings: SegmentSettings::with_defaults(classes, self.threshold, background),
            })
        } else {
            None
        };
        Ok(SurveyToAdd {
            name: name.to_string(),
            date: self.date.trim().to_string(),
            dataset: PathBuf::from(dataset),
            align: self.align,
            segment,
            dataset_must_open: true,
        })
    }
}
