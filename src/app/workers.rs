//! Short-lived worker threads for everything that may take longer than a frame: file dialogs,
//! opening datasets / projects / models, loading a survey photo, rendering a PNG. Each reports
//! once through the state's result channel; none touches the state directly.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::Context;
use crossbeam_channel::Sender;

use crate::app::commands::{Command, DialogKind};
use crate::app::files::{self, OpenTarget};
use crate::app::photo_damage::tint_damage;
use crate::app::settings::Settings;
use crate::app::state::{LoadedSurvey, WorkerResult};
use crate::scene::open::OpenOptions;
use crate::scene::{Camera, Dataset, ImageScale};
use crate::splats::Splats;
use crate::splats::ply;
use crate::timeline::Twin;

/// Longest side of a comparison photo: enough for a viewport, cheap to upload.
const PHOTO_MAX_WIDTH: u32 = 1600;

fn spawn(name: &str, f: impl FnOnce() + Send + 'static) {
    if let Err(e) = std::thread::Builder::new().name(name.into()).spawn(f) {
        tracing::error!("cannot start a {name} thread: {e}");
    }
}

/// Opens a dataset folder, a project or a PLY; reports `Opened` or an error line.
pub fn open(path: PathBuf, results: Sender<WorkerResult>) {
    spawn("damage-twin-open", move || {
        let result = match open_blocking(&path) {
            Ok(opened) => opened,
            Err(e) => WorkerResult::Command(Command::Notify(format!("error: {e:#}"))),
        };
        let _ = results.send(result);
    });
}

/// The work of `open`, on the calling thread (tests and the headless demo use it directly).
pub fn open_blocking(path: &Path) -> anyhow::Result<WorkerResult> {
    match files::classify(path) {
        OpenTarget::Dataset(root) => {
            let dataset = Dataset::open(&root, &OpenOptions::default())
                .with_context(|| format!("opening {}", root.display()))?;
            Ok(WorkerResult::Opened {
                source: root,
                dataset: Some(Arc::new(dataset)),
                splats: None,
                project_dir: None,
            })
        }
        OpenTarget::Ply(file) => {
            let splats =
                ply::read_splats(&file).with_context(|| format!("reading {}", file.display()))?;
            Ok(WorkerResult::Opened {
                source: file,
                dataset: None,
                splats: Some(Arc::new(splats)),
                project_dir: None,
            })
        }
        OpenTarget::Project(file) => {
            let twin = Twin::open(&file)?;
            // The survey shown when the project was saved from the viewer, else the latest that
            // has a model. A project without surveys is refused here.
            twin.latest()?;
            let surveys = &twin.project.surveys;
            let survey = twin
                .project
                .settings
                .shown_survey
                .as_deref()
                .and_then(|name| twin.survey_index(name).ok())
                .or_else(|| surveys.iter().rposition(|s| s.model.is_some()))
                .unwrap_or(surveys.len() - 1);
            let name = twin.project.surveys[survey].name.clone();
            let dataset = crate::app::state::survey_dataset(&twin, &name)
                .with_context(|| format!("opening survey {name}"))?;
            let splats = twin.load_model(&name)?.map(Arc::new);
            Ok(WorkerResult::OpenedProject {
                source: file,
                twin: Box::new(twin),
                survey,
                loaded: LoadedSurvey {
                    splats,
                    dataset,
                    edited: false,
                },
            })
        }
    }
}

/// Shows a native dialog on a worker thread; the chosen path comes back as a command.
pub fn dialog(kind: DialogKind, start: Option<PathBuf>, results: Sender<WorkerResult>) {
    spawn("damage-twin-dialog", move || {
        let mut d = rfd::FileDialog::new();
        if let Some(dir) = start.as_ref().and_then(|p| {
            if p.is_dir() {
                Some(p.clone())
            } else {
                p.parent().map(Path::to_path_buf)
            }
        }) {
            d = d.set_directory(dir);
        }
        let command = match kind {
            DialogKind::OpenFolder => d
                .set_title("Open a dataset or twin folder")
                .pick_folder()
                .map(Command::Open),
            DialogKind::OpenFile => d
                .set_title("Open a twin project or a model")
                .add_filter("twin project or PLY", &["ron", "ply"])
                .pick_file()
                .map(Command::Open),
            DialogKind::SaveProject => d
                .set_title("Save the twin into a folder")
                .pick_folder()
                .map(Command::SaveProject),
            DialogKind::ExportPly => d
                .set_title("Export the model")
                .add_filter("PLY", &["ply"])
                .set_file_name("model.ply")
                .save_file()
                .map(Command::ExportPly),
            DialogKind::SurveyDataset => d
                .set_title("The later survey's dataset folder")
                .pick_folder()
                .map(Command::ChooseSurveyDataset),
            DialogKind::TwinPhotos => d
                .set_title("The folder of photos to make the twin from")
                .pick_folder()
                .map(Command::ChooseTwinPhotos),
            DialogKind::SurveyPhotos => d
                .set_title("The later survey's folder of photos")
                .pick_folder()
                .map(Command::ChooseSurveyPhotos),
            DialogKind::SegmentModel => d
                .set_title("The ONNX model to segment the photos with")
                .add_filter("ONNX model", &["onnx"])
                .pick_file()
                .map(Command::ChooseSegmentModel),
            DialogKind::ExportPng => d
                .set_title("Export the current view")
                .add_filter("PNG", &["png"])
                .set_file_name("view.png")
                .save_file()
                .map(Command::ExportPng),
        };
        let command = command.unwrap_or_else(|| {
            Command::Notify("no file chosen (or no file dialog available)".into())
        });
        let _ = results.send(WorkerResult::Command(command));
    });
}

/// Loads view `index`'s photo (at most `PHOTO_MAX_WIDTH` wide) for the comparison; with
/// `settings.show_ignore_masks`, the pixels its ignore mask keeps out of training are dimmed
/// towards magenta; with `settings.photo_damage`, its damage is tinted over it in the damage
/// layer's colours (`photo_damage`).
pub fn load_photo(
    dataset: Arc<Dataset>,
    index: usize,
    settings: &Settings,
    results: Sender<WorkerResult>,
) {
    let show_ignore = settings.show_ignore_masks;
    let (damage, colours) = (settings.photo_damage, settings.damage.colours);
    spawn("damage-twin-photo", move || {
        let width = dataset
            .views
            .get(index)
            .map(|v| v.camera.intrinsics.width)
            .unwrap_or(PHOTO_MAX_WIDTH);
        let scale = if width > PHOTO_MAX_WIDTH {
            ImageScale::Width(PHOTO_MAX_WIDTH)
        } else {
            ImageScale::Factor(1)
        };
        // A pre-downscaled copy may be stored narrower than the photo cap: as stored then
        // (loading refuses to upscale).
        let result = dataset
            .load_view(index, scale)
            .or_else(|_| dataset.load_view(index, ImageScale::Factor(1)))
            .map(|mut v| {
                for problem in tint_damage(&dataset, index, &mut v, damage, colours) {
                    eprintln!("warning: {problem}");
                }
                let mut image = v.image;
                if let (true, Some(ignore)) = (show_ignore, &v.ignore) {
                    mark_ignored(&mut image, ignore);
                }
                Arc::new(image)
            })
            .map_err(|e| e.to_string());
        let _ = results.send(WorkerResult::Photo {
            view: index,
            result,
        });
    });
}

/// Dims the pixels `ignore` keeps out (0) towards magenta, so they read as "not learnt from".
pub fn mark_ignored(image: &mut crate::scene::RgbImage, ignore: &crate::scene::Mask) {
    const MAGENTA: [f32; 3] = [1.0, 0.0, 1.0];
    for (rgb, &use_pixel) in image.data.chunks_exact_mut(3).zip(&ignore.data) {
        if use_pixel == 0 {
            for (v, m) in rgb.iter_mut().zip(MAGENTA) {
                *v = 0.35 * *v + 0.3 * m;
            }
        }
    }
}

/// Loads a picture file (a change map) as view `index`'s comparison picture.
pub fn load_picture(path: PathBuf, index: usize, results: Sender<WorkerResult>) {
    spawn("damage-twin-picture", move || {
        let result = crate::scene::load::load_image(&path)
            .map(Arc::new)
            .map_err(|e| e.to_string());
        let _ = results.send(WorkerResult::Photo {
            view: index,
            result,
        });
    });
}

/// Measures the damage regions of `splats` (model `generation`), photographed by `cameras`
/// (metric defaults: the app shows metres).
pub fn measure_regions(
    splats: Arc<Splats>,
    generation: u64,
    cameras: Vec<Camera>,
    results: Sender<WorkerResult>,
) {
    spawn("damage-twin-measure", move || {
        let config = crate::damage::measure::MeasureConfig::default();
        let measurement = crate::damage::measure::measure_damage(&splats, &cameras, &config);
        let _ = results.send(WorkerResult::Regions {
            generation,
            measurement: Arc::new(measurement),
        });
    });
}

/// Renders the model from `camera` on the CPU reference renderer and writes a PNG.
pub fn export_png(
    path: PathBuf,
    splats: Arc<Splats>,
    camera: Camera,
    settings: Settings,
    results: Sender<WorkerResult>,
) {
    spawn("damage-twin-png", move || {
        let style = settings.display_style();
        let line = match crate::damage::display::render_png(&path, &splats, &camera, &style) {
            Ok(()) => format!("exported {}", path.display()),
            Err(e) => format!("error: {e:#}"),
        };
        let _ = results.send(WorkerResult::Command(Command::Notify(line)));
    });
}
