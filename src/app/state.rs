//! The viewer's state and the one place it changes: `AppState::apply(Command)`. Panels and the
//! viewport only read it and queue commands; worker threads (dialogs, loading, training) report
//! back through channels drained with `try_recv` in `poll`, so nothing here ever blocks the UI.

use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::Arc;

use crossbeam_channel::{Receiver, Sender};

use crate::app::camera_controller::CameraController;
use crate::app::commands::{Command, DialogKind};
use crate::app::scene_frame::SceneFrame;
use crate::app::settings::Settings;
use crate::app::training::TrainingSession;
use crate::app::viewport::FrameStats;
use crate::app::workers;
use crate::damage::measure::Measurement;
use crate::scene::{Camera, Dataset, RgbImage};
use crate::splats::Splats;
use crate::splats::selection::{self, EditHistory};
use crate::timeline::Twin;
use crate::train::history::History;

mod adding_survey;
mod editing;
mod picking;
mod posing;
mod project_records;
mod project_watch;
mod refining;
mod saving;
mod timeline;
mod view;

pub use posing::{NewTwinDialog, PoseRun, colmap_log_of};
pub use project_records::ProjectRecords;
pub use project_watch::ProjectWatch;
pub use refining::RefineSession;
pub use timeline::{LoadedSurvey, TimelineJob, TimelineView, TimelineWork, survey_dataset};
pub use view::view_camera;

/// Most log lines kept for the log panel.
const LOG_LINES: usize = 200;

/// What is open.
#[derive(Clone, Debug)]
pub struct OpenScene {
    /// The folder or file the user opened.
    pub source: PathBuf,
    /// The dataset the twin is trained from (absent for a bare PLY).
    pub dataset: Option<Arc<Dataset>>,
    /// Project folder (with `twin.ron`) the twin was loaded from or last saved to.
    pub project_dir: Option<PathBuf>,
    pub frame: SceneFrame,
}

/// The photo of a snapped view.
#[derive(Clone, Debug)]
pub enum Photo {
    Loading,
    Loaded(Arc<RgbImage>),
    Failed(String),
}

/// Looking through one survey camera, comparing render and photo.
#[derive(Clone, Debug)]
pub struct Snap {
    pub view: usize,
    pub camera: Camera,
    /// The view's photo, or its change map.
    pub photo: Photo,
    /// `photo` is the view's change map (old damage in class colours, new in the new-damage
    /// colour).
    pub change_map: bool,
}

/// Results of worker threads (everything the UI must not wait for).
pub enum WorkerResult {
    Command(Command),
    Opened {
        source: PathBuf,
        dataset: Option<Arc<Dataset>>,
        splats: Option<Arc<Splats>>,
        project_dir: Option<PathBuf>,
    },
    /// A twin project opened, showing survey `survey`.
    OpenedProject {
        source: PathBuf,
        twin: Box<Twin>,
        survey: usize,
        loaded: LoadedSurvey,
    },
    /// A survey of the open project read for stepping or comparing.
    SurveyLoaded {
        index: usize,
        result: Result<LoadedSurvey, String>,
    },
    Photo {
        view: usize,
        result: Result<Arc<RgbImage>, String>,
    },
    /// Damage regions measured on the model of `generation`.
    Regions {
        generation: u64,
        measurement: Arc<Measurement>,
    },
}

/// The last damage measurement and the model generation it was made on.
#[derive(Clone, Debug)]
pub struct MeasuredRegions {
    pub generation: u64,
    pub measurement: Arc<Measurement>,
}

/// Everything the viewer shows.
pub struct AppState {
    pub settings: Settings,
    pub camera: CameraController,
    pub scene: Option<OpenScene>,
    /// The model on screen (latest training snapshot, or loaded).
    pub splats: Option<Arc<Splats>>,
    /// Bumped whenever `splats` changes (the renderer re-uploads on change).
    pub splats_generation: u64,
    /// Bumped whenever what `splats` draws changes (not by selection-only edits): the GPU
    /// selection pass re-uploads the model then.
    pub drawn_generation: u64,
    /// The GPU selection pass on a hardware GPU (None until first used; Some(None): none).
    gpu_selector: Option<Option<crate::gpu::select::GpuSelector>>,
    pub training: Option<TrainingSession>,
    pub history: History,
    pub snap: Option<Snap>,
    /// Damage regions of the model, once measured.
    pub regions: Option<MeasuredRegions>,
    /// A measurement is running on a worker thread.
    pub measuring: bool,
    /// Selection and visibility edits of the model on screen, for undo and redo.
    pub edits: EditHistory,
    /// A refinement of the selection, while it runs.
    pub refine: Option<RefineSession>,
    /// The open project's surveys (a twin project, not a bare dataset or model).
    pub timeline: Option<TimelineView>,
    /// The "Add survey…" dialog's fields while it is open.
    pub add_survey: Option<crate::app::survey_form::AddSurveyForm>,
    /// The "New twin from photos…" dialog and its COLMAP run while it is open.
    pub new_twin: Option<NewTwinDialog>,
    /// The dataset whose COLMAP log the log window shows.
    pub colmap_log: Option<PathBuf>,
    /// Surface points of the distance measurement (zero, one or two).
    pub distance: Vec<glam::Vec3>,
    pub log: VecDeque<String>,
    /// Viewport size in pixels, as last laid out (for PNG export at screen size).
    pub viewport_pixels: [u32; 2],
    /// The viewport's frame time and render resolution, for the statistics panel.
    pub frame_stats: FrameStats,
    /// Whether dialogs may open (false in tests and headless use).
    pub interactive: bool,
    /// Start training as soon as the next dataset has opened (the demo).
    pub train_on_open: bool,
    results_tx: Sender<WorkerResult>,
    results_rx: Receiver<WorkerResult>,
}

impl AppState {
    pub fn new(settings: Settings) -> AppState {
        let (results_tx, results_rx) = crossbeam_channel::unbounded();
        let frame = SceneFrame::from_cameras(&[], &[]);
        AppState {
            settings,
            camera: frame.controller(),
            scene: None,
            splats: None,
            splats_generation: 0,
            drawn_generation: 0,
            gpu_selector: None,
            training: None,
            history: History::default(),
            snap: None,
            regions: None,
            measuring: false,
            edits: EditHistory::default(),
            refine: None,
            timeline: None,
            add_survey: None,
            new_twin: None,
            colmap_log: None,
            distance: Vec::new(),
            log: VecDeque::new(),
            viewport_pixels: [960, 540],
            frame_stats: FrameStats::default(),
            interactive: false,
            train_on_open: false,
            results_tx,
            results_rx,
        }
    }

    /// A sender worker threads report through.
    pub fn results_sender(&self) -> Sender<WorkerResult> {
        self.results_tx.clone()
    }

    pub fn log_line(&mut self, line: impl Into<String>) {
        let line = line.into();
        tracing::info!("{line}");
        if self.log.len() >= LOG_LINES {
            self.log.pop_front();
        }
        self.log.push_back(line);
    }

    /// Replaces the model on screen (edits of the one before cannot be undone on it).
    pub fn set_splats(&mut self, splats: Arc<Splats>) {
        self.edits.clear();
        self.show_edited(splats);
    }

    fn show_edited(&mut self, splats: Arc<Splats>) {
        self.splats = Some(splats);
        self.splats_generation += 1;
        self.drawn_generation += 1;
    }

    /// Survey cameras of the open dataset.
    pub fn survey_cameras(&self) -> Vec<Camera> {
        self.scene
            .as_ref()
            .and_then(|s| s.dataset.as_ref())
            .map(|d| d.views.iter().map(|v| v.camera).collect())
            .unwrap_or_default()
    }

    /// Drains worker results and training events without blocking. Returns true when anything
    /// changed (the UI repaints).
    pub fn poll(&mut self) -> bool {
        let mut changed = false;
        while let Ok(result) = self.results_rx.try_recv() {
            changed = true;
            self.on_worker_result(result);
        }
        changed |= self.poll_refine();
        changed |= self.poll_timeline();
        changed |= self.poll_new_twin();
        changed |= self.refresh_project_records();
        changed |= self.poll_project_watch();
        if let Some(session) = &mut self.training {
            let update = session.poll(&mut self.history);
            if update.changed {
                changed = true;
            }
            for line in update.log {
                self.log_line(line);
            }
            if let Some(splats) = update.snapshot {
                self.set_splats(splats);
            }
        }
        changed
    }

    fn on_worker_result(&mut self, result: WorkerResult) {
        match result {
            WorkerResult::Command(command) => self.apply(command),
            WorkerResult::Opened {
                source,
                dataset,
                splats,
                project_dir,
            } => {
                self.on_opened(source, dataset, splats, project_dir);
            }
            WorkerResult::OpenedProject {
                source,
                twin,
                survey,
                loaded,
            } => {
                let dir = twin.dir().to_path_buf();
                self.on_opened(
                    source,
                    loaded.dataset.clone(),
                    loaded.splats.clone(),
                    Some(dir),
                );
                self.timeline = Some(TimelineView::new(*twin, survey, loaded));
            }
            WorkerResult::SurveyLoaded { index, result } => self.on_survey_loaded(index, result),
            WorkerResult::Photo { view, result } => {
                if let Some(snap) = &mut self.snap
                    && snap.view == view
                {
                    snap.photo = match result {
                        Ok(image) => Photo::Loaded(image),
                        Err(e) => Photo::Failed(e),
                    };
                }
            }
            WorkerResult::Regions {
                generation,
                measurement,
            } => {
                self.measuring = false;
                self.log_line(format!(
                    "measured {} damage regions on {} planes in {:.1} s",
                    measurement.regions.len(),
                    measurement.planes.len(),
                    measurement.seconds
                ));
                self.regions = Some(MeasuredRegions {
                    generation,
                    measurement,
                });
            }
        }
    }

    fn on_opened(
        &mut self,
        source: PathBuf,
        dataset: Option<Arc<Dataset>>,
        splats: Option<Arc<Splats>>,
        project_dir: Option<PathBuf>,
    ) {
        self.stop_training();
        // Whatever the project's timeline was running belongs to the project that is closing.
        if let Some(job) = self.timeline.take().and_then(|t| t.job) {
            job.cancel();
        }
        self.add_survey = None;
        self.snap = None;
        self.regions = None;
        self.history.clear();
        let cameras: Vec<Camera> = dataset
            .as_ref()
            .map(|d| d.views.iter().map(|v| v.camera).collect())
            .unwrap_or_default();
        let points: Vec<glam::Vec3> =
            match (&splats, dataset.as_ref().and_then(|d| d.points.as_ref())) {
                (Some(s), _) => s.means.clone(),
                (None, Some(p)) => p.positions.clone(),
                (None, None) => Vec::new(),
            };
        let frame = SceneFrame::from_cameras(&cameras, &points);
        self.camera = frame.controller();
        self.camera.fly_speed *= self.settings.fly_speed;
        self.camera.mode = self.settings.nav_mode;
        self.camera.fov_y = self.settings.fov_deg.to_radians();
        self.settings.remember(&source);
        if let Some(d) = &dataset {
            self.log_line(format!(
                "opened {} ({} views, {:?})",
                source.display(),
                d.views.len(),
                d.format
            ));
            for w in d.warnings.iter().take(5) {
                self.log_line(format!("warning: {w}"));
            }
        } else {
            self.log_line(format!("opened {}", source.display()));
        }
        match splats {
            Some(s) => self.set_splats(s),
            None => {
                self.splats = None;
                self.splats_generation += 1;
            }
        }
        self.scene = Some(OpenScene {
            source,
            dataset,
            project_dir,
            frame,
        });
        if std::mem::take(&mut self.train_on_open) {
            self.apply(Command::StartTraining);
        }
    }

    fn stop_training(&mut self) {
        if let Some(session) = self.training.take() {
            session.cancel();
        }
    }

    /// Performs one command.
    pub fn apply(&mut self, command: Command) {
        match command {
            Command::Open(path) => {
                self.log_line(format!("opening {}", path.display()));
                workers::open(path, self.results_sender());
            }
            Command::ShowDialog(kind) => {
                if self.interactive {
                    let start = self.scene.as_ref().map(|s| s.source.clone());
                    workers::dialog(kind, start, self.results_sender());
                } else {
                    self.log_line("file dialogs are disabled here");
                }
            }
            Command::SaveProject(dir) => self.save_project(&dir),
            Command::SaveProjectHere => {
                match self.scene.as_ref().and_then(|s| s.project_dir.clone()) {
                    Some(dir) => self.save_project(&dir),
                    None => self.apply(Command::ShowDialog(DialogKind::SaveProject)),
                }
            }
            Command::ExportPly(path) => match &self.splats {
                Some(splats) => {
                    let result = crate::splats::ply::write_splats(&path, splats);
                    self.report(
                        result.map_err(Into::into),
                        &format!("exported {}", path.display()),
                    );
                }
                None => self.log_line("nothing to export yet: no model"),
            },
            Command::ExportPng(path) => match &self.splats {
                Some(splats) => {
                    let [w, h] = self.viewport_pixels;
                    let camera = self.view_camera(w, h);
                    let mut settings = self.settings.clone();
                    if let Some(t) = &self.timeline {
                        settings.damage = t.layer(&settings.damage, t.current);
                    }
                    workers::export_png(
                        path,
                        splats.clone(),
                        camera,
                        settings,
                        self.results_sender(),
                    );
                }
                None => self.log_line("nothing to render yet: no model"),
            },
            Command::StartTraining => self.start_training(),
            Command::PauseTraining => {
                if let Some(t) = &mut self.training {
                    t.pause();
                }
            }
            Command::ResumeTraining => {
                if let Some(t) = &mut self.training {
                    t.resume();
                }
            }
            Command::StopTraining => {
                if let Some(t) = &mut self.training {
                    t.stop();
                }
            }
            Command::SnapToView(index) => self.snap_to(index),
            Command::MeasureRegions => match &self.splats {
                Some(splats) if !self.measuring => {
                    self.measuring = true;
                    workers::measure_regions(
                        splats.clone(),
                        self.splats_generation,
                        self.survey_cameras(),
                        self.results_sender(),
                    );
                }
                Some(_) => self.log_line("already measuring"),
                None => self.log_line("nothing to measure yet: no model"),
            },
            Command::FocusRegion(index) => self.focus_region(index),
            Command::Select { shape, camera, op } => self.select_shape(&shape, &camera, op),
            Command::SelectAt {
                pixel,
                camera,
                how,
                op,
            } => self.select_at(pixel, &camera, how, op),
            Command::SelectFromMask { class, op } => self.select_from_mask(class, op),
            Command::MeasureAt { pixel, camera } => self.measure_at(pixel, &camera),
            Command::ClearDistance => self.distance.clear(),
            Command::FrameSelection => self.frame_selection(),
            Command::SelectDamage {
                class,
                threshold,
                survey,
                op,
            } => self.edit_model(|m| {
                let hit = selection::damage_hits(m, class.channel(), threshold, survey);
                selection::select(m, &hit, op)
            }),
            Command::SetDamageClass { class, on } => {
                self.edit_model(|m| selection::set_label(m, class.channel(), on));
            }
            Command::SelectAll => self.edit_model(|m| selection::select_all(m, true)),
            Command::SelectNone => self.edit_model(|m| selection::select_all(m, false)),
            Command::InvertSelection => self.edit_model(selection::invert),
            Command::HideSelected => self.edit_model(selection::hide_selected),
            Command::UnhideAll => self.edit_model(selection::unhide_all),
            Command::RefineSelection {
                strategy,
                iterations,
            } => self.start_refine(strategy, iterations),
            Command::CancelRefine => self.cancel_refine(),
            Command::ShowSurvey(index) => self.show_survey(index),
            Command::CompareSurvey(index) => self.compare_survey(index),
            Command::DetectChanges => self.detect_changes(),
            Command::UpdateTwin {
                strategy,
                iterations,
            } => self.update_twin(strategy, iterations),
            Command::CancelTimelineJob => self.cancel_timeline_job(),
            Command::OpenAddSurvey => self.open_add_survey(),
            Command::EditAddSurvey(form) => self.edit_add_survey(*form),
            Command::ChooseSurveyDataset(folder) => self.choose_survey_dataset(folder),
            Command::ChooseSegmentModel(file) => self.choose_segment_model(file),
            Command::AddSurvey => self.start_add_survey(),
            Command::CloseAddSurvey => self.add_survey = None,
            Command::OpenAddSurveyFromPhotos => self.open_add_survey_from_photos(),
            Command::ChooseSurveyPhotos(folder) => self.choose_survey_photos(folder),
            Command::OpenNewTwin => self.open_new_twin(),
            Command::EditNewTwin(form) => self.edit_new_twin(*form),
            Command::ChooseTwinPhotos(folder) => self.choose_twin_photos(folder),
            Command::NewTwinFromPhotos => self.start_new_twin(),
            Command::CancelNewTwin => self.cancel_new_twin(),
            Command::CloseNewTwin => self.close_new_twin(),
            Command::ShowColmapLog(dataset) => self.colmap_log = dataset,
            Command::ShowChangeMaps(on) => {
                if let Some(t) = &mut self.timeline {
                    t.show_change_maps = on;
                }
                if let Some(view) = self.snap.as_ref().map(|s| s.view) {
                    self.snap_to(view);
                }
            }
            Command::Undo => self.undo_redo(false),
            Command::Redo => self.undo_redo(true),
            Command::Unsnap => self.unsnap(),
            Command::MoveCamera(input) => self.camera.update(&input),
            Command::RecordViewportFrame { pixels, stats } => {
                self.viewport_pixels = pixels;
                self.frame_stats = stats;
            }
            Command::ResetView => self.reset_view(),
            Command::UpdateSettings(settings) => {
                let settings = settings.sanitised();
                // What a snapped photo shows changed: load it again with the new settings.
                let reload = (settings.photo_damage, settings.show_ignore_masks)
                    != (self.settings.photo_damage, self.settings.show_ignore_masks);
                self.camera.mode = settings.nav_mode;
                self.camera.fov_y = settings.fov_deg.to_radians();
                if let Some(scene) = &self.scene {
                    self.camera.fly_speed = scene.frame.camera_distance * 0.5 * settings.fly_speed;
                }
                self.settings = settings;
                if let Some(view) = self.snap.as_ref().filter(|_| reload).map(|s| s.view) {
                    self.snap_to(view);
                }
            }
            Command::Notify(line) => self.log_line(line),
        }
    }

    fn report(&mut self, result: anyhow::Result<()>, success: &str) {
        match result {
            Ok(()) => self.log_line(success),
            Err(e) => self.log_line(format!("error: {e:#}")),
        }
    }

    fn start_training(&mut self) {
        let Some(dataset) = self.scene.as_ref().and_then(|s| s.dataset.clone()) else {
            self.log_line("open a dataset to train");
            return;
        };
        if self.training.as_ref().is_some_and(|t| t.is_running()) {
            self.log_line("training is already running");
            return;
        }
        self.history.clear();
        // The damage layer's colours are the palette of a run that does not choose its own;
        // overlay training chooses colours against the photos (RunConfig::contrasting_palette)
        // and saves them with the model, whose damage is read back in them.
        let palette = crate::damage::Palette {
            colours: self.settings.damage.colours,
        };
        self.training = Some(TrainingSession::start(
            dataset,
            self.settings.training.clone(),
            palette,
            self.settings.background,
        ));
        self.log_line("training started");
    }
}
