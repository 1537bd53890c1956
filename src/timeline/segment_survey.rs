//! A survey that arrives as photos alone: before it is added, its photos are segmented by a model
//! (`segment`) and the masks written into its dataset, in the convention every reader of a survey
//! uses (`masks/<class>/<photo>.png`, beside `probabilities/`). Written there, not into the
//! project: detection, the update, `inspect`, the app and the user's own annotation tool all find
//! them where a survey's masks always are, and an inspector can look at and correct them before
//! the twin learns from them. Masks already in the dataset are never overwritten (a refusal names
//! the first), so a survey's hand-made masks cannot be lost to a model.

use std::path::Path;

use crate::segment::{
    SegmentModel, SegmentSettings, SegmentSummary, dataset_photos, segment_photos,
};
use crate::timeline::survey::AlignMode;
use crate::timeline::twin::{TimelineError, Twin};

/// A survey as `twin add-survey` names it.
#[derive(Clone, Copy, Debug)]
pub struct NewSurvey<'a> {
    pub name: &'a str,
    pub date: &'a str,
    pub dataset: &'a Path,
    pub align: AlignMode,
}

impl Twin {
    /// Segments the photos `survey` would bring (placed by its alignment: a joint
    /// model's new images only) with `model`, writing their masks into the dataset. The survey is
    /// checked as `add_placed_survey` would add it (name, date, registration) first, on a copy,
    /// so a survey that would be refused is not segmented; the project itself is unchanged (add
    /// the survey after). `on_progress(done, total)` returning false cancels.
    pub fn segment_new_survey(
        &self,
        survey: NewSurvey,
        model: &SegmentModel,
        settings: &SegmentSettings,
        on_progress: &mut dyn FnMut(usize, usize) -> bool,
    ) -> Result<SegmentSummary, TimelineError> {
        let mut check = self.clone();
        check.add_placed_survey(survey.name, survey.date, survey.dataset, survey.align)?;
        let placed = check.open_survey_dataset(survey.name)?;
        let photos = dataset_photos(&placed);
        let settings = SegmentSettings {
            overwrite: false,
            ..settings.clone()
        };
        Ok(segment_photos(
            model,
            &placed.root,
            &photos,
            &settings,
            on_progress,
        )?)
    }
}
