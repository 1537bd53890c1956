//! Every state change the viewer can make, as data (rerun style): panels push `Command`s, the app
//! applies them between frames, and tests or headless callers apply the same commands. No UI
//! here and no effect of its own: `AppState::apply` performs them.

use std::path::PathBuf;

use crate::app::settings::Settings;

/// Which file a dialog asks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DialogKind {
    /// A dataset folder (COLMAP, transforms.json, synth output) or a project folder.
    OpenFolder,
    /// A `twin.ron` project or a `.ply` model.
    OpenFile,
    /// Folder to save the twin project into.
    SaveProject,
    ExportPly,
    ExportPng,
    /// A later survey's dataset folder, for "Add survey…".
    SurveyDataset,
    /// The ONNX model "Add survey…" segments the photos with.
    SegmentModel,
    /// The folder of photos "New twin from photos…" poses.
    TwinPhotos,
    /// The later survey's photos "Add survey from photos…" registers.
    SurveyPhotos,
}

/// What a click selects.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PointSelect {
    /// The Gaussian drawing most of the clicked pixel.
    Gaussian,
    /// Every visible Gaussian whose base colour is within the settings' colour match of the
    /// clicked Gaussian's (eyedropper).
    Colour,
    /// The Gaussians whose centres lie in a sphere (radius from the settings) around the
    /// surface point clicked.
    Sphere,
    /// The same with an axis-aligned cube (half-size from the settings).
    Box,
}

/// A state change.
#[derive(Clone, Debug, PartialEq)]
pub enum Command {
    /// Open a dataset folder, a project (`twin.ron` or its folder) or a `.ply` model.
    Open(PathBuf),
    /// Ask the user for a path on a worker thread; the answer comes back as another command.
    ShowDialog(DialogKind),
    /// Save the twin project (`twin.ron` + model PLY) into a folder, atomically.
    SaveProject(PathBuf),
    /// Save into the project folder the twin came from (or ask where).
    SaveProjectHere,
    /// Write the current model as a standard 3DGS PLY.
    ExportPly(PathBuf),
    /// Write a PNG of the current view.
    ExportPng(PathBuf),
    StartTraining,
    PauseTraining,
    ResumeTraining,
    StopTraining,
    /// Look through survey view `index` and compare with its photo.
    SnapToView(usize),
    /// Leave the snapped view (navigation continues from it).
    Unsnap,
    /// Move the free camera by one frame of navigation input (its easing included). The
    /// viewport sends one every frame it is not snapped, having drawn with the same move.
    MoveCamera(crate::app::camera_controller::CameraInput),
    /// The viewport's size in pixels as laid out this frame, and the frame's statistics (for PNG
    /// export at screen size and for the statistics panel).
    RecordViewportFrame {
        pixels: [u32; 2],
        stats: crate::app::viewport::FrameStats,
    },
    /// Frame the whole scene again.
    ResetView,
    /// Replace the settings (panels edit a copy and submit it).
    UpdateSettings(Box<Settings>),
    /// Show a line in the log / status bar.
    Notify(String),
    /// Measure the model's damage regions (on a worker thread).
    MeasureRegions,
    /// Select region `index` of the last measurement (its damage Gaussians) and frame it.
    FocusRegion(usize),
    /// Combine the Gaussians inside `shape` (screen shapes in pixels of `camera`) with the
    /// selection.
    Select {
        shape: crate::splats::selection::Shape,
        camera: Box<crate::scene::Camera>,
        op: crate::splats::selection::SetOp,
    },
    /// Combine what a click at `pixel` (pixels of `camera`) selects with the selection.
    SelectAt {
        pixel: glam::Vec2,
        camera: Box<crate::scene::Camera>,
        how: PointSelect,
        op: crate::splats::selection::SetOp,
    },
    /// Combine the Gaussians the snapped view's mask of `class` lifts to (blending-weight
    /// majority) with the selection.
    SelectFromMask {
        class: crate::damage::DamageClass,
        op: crate::splats::selection::SetOp,
    },
    /// Add the surface point at `pixel` to the distance measurement (a third point starts a
    /// new one).
    MeasureAt {
        pixel: glam::Vec2,
        camera: Box<crate::scene::Camera>,
    },
    ClearDistance,
    /// Frame the selection (the whole scene when nothing is selected).
    FrameSelection,
    SelectAll,
    SelectNone,
    InvertSelection,
    /// Hide the selection (neither drawn nor selectable until unhidden).
    HideSelected,
    UnhideAll,
    /// Combine the visible Gaussians of damage class `class` at `threshold` or more (first seen
    /// in `survey`, when given) with the selection.
    SelectDamage {
        class: crate::damage::DamageClass,
        threshold: f32,
        survey: Option<u16>,
        op: crate::splats::selection::SetOp,
    },
    /// Set (or clear) damage class `class` on the selection: a person overruling the segmenter.
    SetDamageClass {
        class: crate::damage::DamageClass,
        on: bool,
    },
    /// Refine the selected Gaussians on the open dataset (hull masks, full resolution, the rest
    /// frozen); the result becomes the model, undoably.
    RefineSelection {
        strategy: crate::damage::refine::Strategy,
        iterations: u32,
    },
    CancelRefine,
    /// Show survey `index` of the open project (its model and photos; the camera stays).
    ShowSurvey(usize),
    /// Show survey `index` beside the one shown, with the same camera (None: stop comparing).
    CompareSurvey(Option<usize>),
    /// Find the shown survey's new damage against the twin before it (change maps).
    DetectChanges,
    /// Update the twin with the shown survey's photos and masks (its model is written).
    UpdateTwin {
        strategy: crate::damage::refine::Strategy,
        iterations: u32,
    },
    CancelTimelineJob,
    /// Open the "Add survey…" dialog for the open project.
    OpenAddSurvey,
    /// Replace the dialog's fields (the panel edits a copy and submits it).
    EditAddSurvey(Box<crate::app::survey_form::AddSurveyForm>),
    /// A folder chosen as the new survey's dataset (its name fills an empty survey name).
    ChooseSurveyDataset(PathBuf),
    /// A file chosen as the model the new survey's photos are segmented with.
    ChooseSegmentModel(PathBuf),
    /// Add the survey the dialog describes (segmented first when asked), on a worker; cancel
    /// with `CancelTimelineJob`.
    AddSurvey,
    CloseAddSurvey,
    /// Open the "Add survey…" dialog for photos that COLMAP registers into the twin's frame.
    OpenAddSurveyFromPhotos,
    /// A folder chosen as the new survey's photos (fills an empty dataset and name).
    ChooseSurveyPhotos(PathBuf),
    /// Open the "New twin from photos…" dialog.
    OpenNewTwin,
    /// Replace its fields (the panel edits a copy and submits it).
    EditNewTwin(Box<crate::app::twin_form::NewTwinForm>),
    /// A folder chosen as the new twin's photos (fills the empty fields beside it).
    ChooseTwinPhotos(PathBuf),
    /// Pose the photos with COLMAP and make the twin project, on a worker.
    NewTwinFromPhotos,
    CancelNewTwin,
    CloseNewTwin,
    /// Show the log of the COLMAP run writing this dataset (None: close the log window).
    ShowColmapLog(Option<PathBuf>),
    /// Snapping to a view shows its change map instead of its photo.
    ShowChangeMaps(bool),
    /// Undo or redo the last selection, visibility or damage-class edit.
    Undo,
    Redo,
}
