//! Segmenting a set of photos into the dataset convention (`output`), as a function with a
//! progress callback (the timeline calls it inside its own step) and as a `Job` (the CLI's
//! `segment`, the app). Photos run in parallel, as many at a time as the pool has threads, and
//! each photo's tiles in parallel too; every file is written atomically, and the files already
//! there are found before the model runs, so a refusal costs nothing.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use rayon::prelude::*;
use serde::Serialize;

use crate::scene::load::load_image_with_background;
use crate::scene::{DamageClass, Dataset};
use crate::segment::output::{check_threshold, first_existing, mask_from_probability, write_class};
use crate::segment::{PhotoSettings, SegmentError, SegmentModel, photo_probabilities};
use crate::train::job::{Job, JobError, JobOptions, Progress};

/// One photo to segment: the name its masks take (the view name: the file stem) and its file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Photo {
    pub name: String,
    pub path: PathBuf,
}

/// A dataset's photos (its registered views).
pub fn dataset_photos(dataset: &Dataset) -> Vec<Photo> {
    dataset
        .views
        .iter()
        .map(|v| Photo {
            name: v.name.clone(),
            path: v.image_path.clone(),
        })
        .collect()
}

/// The probability at or above which a pixel is damage unless told otherwise (`--threshold`, the
/// app's "Segment with…").
pub const DEFAULT_THRESHOLD: f32 = 0.5;

/// What segmentation writes and how it reads the model.
#[derive(Clone, Debug, PartialEq)]
pub struct SegmentSettings {
    /// The damage class of each output channel, in order; `None` for a channel not written (a
    /// background channel of a softmax model).
    pub classes: Vec<Option<DamageClass>>,
    pub photo: PhotoSettings,
    /// A pixel is damage where its probability (8-bit, as stored) is at least this.
    pub threshold: f32,
    /// Replace masks and probabilities already there (otherwise they are a refusal).
    pub overwrite: bool,
    /// Colour RGBA photos are composited on.
    pub background: [f32; 3],
}

/// The class of each output channel from a comma-separated list (`crack`, `-,crack,spalling`):
/// a class id, or `-` (or `background`) for a channel not written. `twin add-survey --segment`,
/// `segment` and the app's "Segment with…" read the list the same way.
pub fn parse_channel_classes(list: &str) -> Result<Vec<Option<DamageClass>>, SegmentError> {
    list.split(',')
        .map(|entry| match entry.trim() {
            "-" | "background" => Ok(None),
            id => DamageClass::from_id(id).map(Some).ok_or_else(|| {
                SegmentError::Settings(format!(
                    "unknown class {id:?}: use crack, spalling, rebar or - (not written)"
                ))
            }),
        })
        .collect()
}

impl SegmentSettings {
    /// A run with the shared crack model's preprocessing and tiling at the photos' own scale
    /// (`Preprocess::default`, `Tiling::default`), never overwriting: what the app's "Segment
    /// with…" runs when only the classes and the threshold are chosen.
    pub fn with_defaults(
        classes: Vec<Option<DamageClass>>,
        threshold: f32,
        background: [f32; 3],
    ) -> SegmentSettings {
        SegmentSettings {
            classes,
            photo: PhotoSettings {
                preprocess: crate::segment::Preprocess::default(),
                scale: crate::scene::ImageScale::Factor(1),
                tiling: crate::segment::Tiling::default(),
            },
            threshold,
            overwrite: false,
            background,
        }
    }

    /// The classes written, in channel order.
    pub fn written_classes(&self) -> Vec<DamageClass> {
        self.classes.iter().flatten().copied().collect()
    }

    fn check(&self) -> Result<(), SegmentError> {
        check_threshold(self.threshold)?;
        self.photo.tiling.check()?;
        self.photo.preprocess.check()?;
        let written = self.written_classes();
        if written.is_empty() {
            return Err(SegmentError::Settings(
                "no output channel is mapped to a damage class".into(),
            ));
        }
        for (i, class) in written.iter().enumerate() {
            if written[..i].contains(class) {
                return Err(SegmentError::Settings(format!(
                    "class {} is given to two output channels",
                    class.id()
                )));
            }
        }
        Ok(())
    }
}

/// What a segmentation run did.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SegmentSummary {
    pub photos: usize,
    pub megapixels: f64,
    pub seconds: f64,
    /// The share of all photos' pixels marked, per class id.
    pub damage_fraction: BTreeMap<String, f64>,
}

impl SegmentSummary {
    pub fn photos_per_second(&self) -> f64 {
        self.photos as f64 / self.seconds.max(1e-9)
    }

    pub fn seconds_per_megapixel(&self) -> f64 {
        self.seconds / self.megapixels.max(1e-12)
    }

    fn add(&mut self, class: DamageClass, marked: usize) {
        *self
            .damage_fraction
            .entry(class.id().to_string())
            .or_insert(0.0) += marked as f64;
    }

    /// The run in one line per fact, as the CLI prints it and the app logs it: photos, speed on
    /// `threads` threads, the damage share per class and where its masks went under `root`.
    pub fn lines(&self, threads: usize, root: &Path) -> Vec<String> {
        let mut lines = vec![format!(
            "segmented {} photos ({:.1} megapixels) in {:.1} s on {threads} threads: {:.2} \
             images/s, {:.2} s per megapixel",
            self.photos,
            self.megapixels,
            self.seconds,
            self.photos_per_second(),
            self.seconds_per_megapixel()
        )];
        for (class, share) in &self.damage_fraction {
            lines.push(format!(
                "  {class}: {:.2} % of pixels marked -> {}",
                100.0 * share,
                root.join("masks").join(class).display()
            ));
        }
        lines
    }

    /// Marked pixel counts become shares of the `pixels` looked at.
    fn finish(mut self, pixels: f64, started: Instant) -> SegmentSummary {
        for v in self.damage_fraction.values_mut() {
            *v /= pixels.max(1.0);
        }
        self.megapixels = pixels / 1e6;
        self.seconds = started.elapsed().as_secs_f64();
        self
    }
}

/// Segments `photos` with `model` into `root`'s masks and probabilities. `on_progress(done,
/// total)` is called after each group of photos; returning false stops the run (`Cancelled`;
/// the photos done so far keep their files).
pub fn segment_photos(
    model: &SegmentModel,
    root: &Path,
    photos: &[Photo],
    settings: &SegmentSettings,
    on_progress: &mut dyn FnMut(usize, usize) -> bool,
) -> Result<SegmentSummary, SegmentError> {
    settings.check()?;
    if settings.classes.len() != model.channels() {
        return Err(SegmentError::Shape {
            path: model.path().to_path_buf(),
            message: format!(
                "the model gives {} output channels; {} classes were named",
                model.channels(),
                settings.classes.len()
            ),
        });
    }
    let names: Vec<String> = photos.iter().map(|p| p.name.clone()).collect();
    if !settings.overwrite
        && let Some(path) = first_existing(root, &settings.written_classes(), &names)
    {
        return Err(SegmentError::Exists { path });
    }
    let started = Instant::now();
    let mut summary = SegmentSummary::default();
    let mut pixels = 0.0;
    let group = rayon::current_num_threads().max(1);
    let mut done = 0;
    for chunk in photos.chunks(group) {
        let counted: Vec<(usize, Vec<(DamageClass, usize)>)> = chunk
            .par_iter()
            .map(|photo| segment_one(model, root, photo, settings))
            .collect::<Result<_, _>>()?;
        for (photo_pixels, marked) in counted {
            pixels += photo_pixels as f64;
            for (class, n) in marked {
                summary.add(class, n);
            }
        }
        done += chunk.len();
        if !on_progress(done, photos.len()) && done < photos.len() {
            return Err(SegmentError::Cancelled);
        }
    }
    summary.photos = photos.len();
    Ok(summary.finish(pixels, started))
}

/// One photo: its pixel count and the pixels marked per class.
fn segment_one(
    model: &SegmentModel,
    root: &Path,
    photo: &Photo,
    settings: &SegmentSettings,
) -> Result<(usize, Vec<(DamageClass, usize)>), SegmentError> {
    let image = load_image_with_background(&photo.path, settings.background)?;
    let maps = photo_probabilities(model, &image, &photo.path, &settings.photo)?;
    let mut marked = Vec::new();
    for (class, map) in settings.classes.iter().zip(&maps) {
        if let Some(class) = *class {
            let mask = write_class(root, class, &photo.name, map, settings.threshold)?;
            marked.push((class, mask.count()));
        }
    }
    Ok((image.pixel_count(), marked))
}

/// Rewrites `photos`' masks of `classes` from their stored probabilities at `threshold`: a new
/// threshold without running the model again.
pub fn masks_from_probabilities(
    root: &Path,
    photos: &[Photo],
    classes: &[DamageClass],
    threshold: f32,
) -> Result<SegmentSummary, SegmentError> {
    check_threshold(threshold)?;
    let started = Instant::now();
    let counted: Vec<(usize, Vec<(DamageClass, usize)>)> = photos
        .par_iter()
        .map(|photo| {
            let mut pixels = 0;
            let mut marked = Vec::new();
            for &class in classes {
                let mask = mask_from_probability(root, class, &photo.name, threshold)?;
                pixels = mask.data.len();
                marked.push((class, mask.count()));
            }
            Ok((pixels, marked))
        })
        .collect::<Result<_, SegmentError>>()?;
    let mut summary = SegmentSummary {
        photos: photos.len(),
        ..SegmentSummary::default()
    };
    let mut pixels = 0.0;
    for (n, marked) in counted {
        pixels += n as f64;
        for (class, m) in marked {
            summary.add(class, m);
        }
    }
    Ok(summary.finish(pixels, started))
}

/// [`segment_photos`] as a job: the model is read on the worker, progress is counted in
/// photos, cancel stops after the photos in flight.
pub fn segment_job(
    model_path: PathBuf,
    channels: usize,
    root: PathBuf,
    photos: Vec<Photo>,
    settings: SegmentSettings,
    options: JobOptions,
) -> Job<SegmentSummary> {
    Job::spawn("segment", options, move |context| {
        context.log(format!("reading {}", model_path.display()));
        let model = SegmentModel::open(&model_path, channels).map_err(JobError::other)?;
        context.progress(Progress::counted("segment", 0, photos.len(), 0));
        segment_photos(&model, &root, &photos, &settings, &mut |done, total| {
            context.progress(Progress::counted("segment", done, total, 0));
            !context.should_stop()
        })
        .map_err(JobError::other)
    })
}
