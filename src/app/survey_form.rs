//! The "Add survey…" dialog's fields as data: the dataset folder (picked or typed), the survey's
//! name and date, its alignment, and optionally the model its photos are segmented with; for
//! "Add survey from photos…", the photos COLMAP registers and where their dataset goes. The
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
    /// "Add survey from photos…": the photos are registered by COLMAP into the twin's posed
    /// survey first, written as `dataset`, and placed by that registration (`AlignMode::Colmap`).
    pub from_photos: bool,
    /// The new survey's photos (from photos only), as typed or picked.
    pub photos: String,
    /// Why the last try did not add the survey (shown in the dialog until the fields change or
    /// the next try).
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
            from_photos: false,
            photos: String::new(),
            error: None,
        }
    }

    /// The same for "Add survey from photos…": registered by COLMAP.
    pub fn for_project_from_photos(twin: &Twin) -> AddSurveyForm {
        AddSurveyForm {
            from_photos: true,
            align: AlignMode::Colmap,
            ..AddSurveyForm::for_project(twin)
        }
    }

    /// `folder` as the new survey's photos; an empty dataset becomes `<folder>-registered`
    /// beside it, an empty name one from the folder's name, unused in `twin`.
    pub fn choose_photos(&mut self, folder: &Path, twin: &Twin) {
        self.photos = folder.display().to_string();
        if self.dataset.trim().is_empty()
            && let Some(base) = folder.file_name()
        {
            let registered = format!("{}-registered", base.to_string_lossy());
            self.dataset = folder.with_file_name(registered).display().to_string();
        }
        self.name_from(folder, twin);
    }

    /// The same fields, ignoring the error line: an edit that changes none keeps it.
    pub fn same_inputs(&self, other: &AddSurveyForm) -> bool {
        let bare = |f: &AddSurveyForm| AddSurveyForm {
            error: None,
            ..f.clone()
        };
        bare(self) == bare(other)
    }

    /// The photos to register first ("from photos"), or why there are none.
    pub fn photos_to_register(&self) -> Result<Option<PathBuf>, String> {
        if !self.from_photos {
            return Ok(None);
        }
        match self.photos.trim() {
            "" => Err("choose the folder of the survey's photos".into()),
            photos => Ok(Some(PathBuf::from(photos))),
        }
    }

    /// `folder` as the dataset; an empty name becomes one from the folder's name, unused in
    /// `twin`.
    pub fn choose_dataset(&mut self, folder: &Path, twin: &Twin) {
        self.dataset = folder.display().to_string();
        self.name_from(folder, twin);
    }

    /// An empty name becomes one from `folder`'s name, unused in `twin`.
    fn name_from(&mut self, folder: &Path, twin: &Twin) {
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
            return Err(match self.from_photos {
                true => "choose where the registered dataset goes".into(),
                false => "choose the survey's dataset folder".into(),
            });
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
            align: match self.from_photos {
                true => AlignMode::Colmap,
                false => self.align,
            },
            segment,
            dataset_must_open: true,
        })
    }
}
