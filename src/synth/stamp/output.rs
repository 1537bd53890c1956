//! A stamped survey on disk, laid out as `synth` writes one (docs/SYNTH.md): `images/`,
//! `sparse/0/` (COLMAP text, the capture's own lens model and poses, its sparse points),
//! `masks/<class>/` (the clean truth, as a user's masks would sit), `truth/masks/<class>/`,
//! `truth/new-damage/<class>/` (survey 2), `truth/quantities.json` and `truth/manifest.json`.

use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::scene::colmap::{
    CameraModel, ColmapCamera, ColmapImage, ColmapModel, ColmapPoint, write_text,
};
use crate::scene::{DamageClass, Dataset};
use crate::synth::SynthError;
use crate::synth::write::{create_dir, mask_png, rgb_png};

use super::decal::Decal;
use super::params::{StampError, StampParams};
use super::place::Photo;
use super::planes::Plane;
use super::render::{Lens, Stamped};
use super::run::StampSummary;

pub struct SurveyWriter {
    pub root: PathBuf,
    pub survey: u32,
    classes: Vec<DamageClass>,
}

/// The folder of survey `survey` in the output.
pub fn survey_dir(out: &Path, survey: u32) -> PathBuf {
    out.join(format!("survey-{survey}"))
}

impl SurveyWriter {
    pub fn create(
        out: &Path,
        survey: u32,
        classes: &[DamageClass],
    ) -> Result<SurveyWriter, StampError> {
        let root = survey_dir(out, survey);
        for dir in ["images", "sparse/0", "truth"] {
            create_dir(&root.join(dir))?;
        }
        for class in classes {
            create_dir(&root.join("masks").join(class.id()))?;
            create_dir(&root.join("truth/masks").join(class.id()))?;
            if survey > 1 {
                create_dir(&root.join("truth/new-damage").join(class.id()))?;
            }
        }
        Ok(SurveyWriter {
            root,
            survey,
            classes: classes.to_vec(),
        })
    }

    /// The stamped photo as `images/<name>.png` and its masks.
    pub fn write_view(&self, name: &str, stamped: &Stamped) -> Result<(), StampError> {
        let file = format!("{name}.png");
        let image_path = self.root.join("images").join(&file);
        if let Some(parent) = image_path.parent() {
            create_dir(parent)?;
        }
        let (w, h) = (stamped.image.width, stamped.image.height);
        rgb_png(&image_path, w, h, stamped.image.to_rgb8().into_raw())?;
        for (class, mask) in &stamped.masks {
            if !self.classes.contains(class) {
                continue;
            }
            for folder in ["masks", "truth/masks"] {
                let path = self.root.join(folder).join(class.id()).join(&file);
                if let Some(parent) = path.parent() {
                    create_dir(parent)?;
                }
                mask_png(&path, w, h, &mask.data)?;
            }
        }
        if self.survey > 1 {
            for (class, mask) in &stamped.new_damage {
                if self.classes.contains(class) {
                    let path = self
                        .root
                        .join("truth/new-damage")
                        .join(class.id())
                        .join(&file);
                    if let Some(parent) = path.parent() {
                        create_dir(parent)?;
                    }
                    mask_png(&path, w, h, &mask.data)?;
                }
            }
        }
        Ok(())
    }

    /// `sparse/0/` as COLMAP text: one camera per photo with its own lens model, the poses, and
    /// the capture's sparse points (without tracks).
    pub fn write_model(&self, dataset: &Dataset, photos: &[Photo]) -> Result<(), StampError> {
        let mut model = ColmapModel::default();
        for (k, (photo, view)) in photos.iter().zip(&dataset.views).enumerate() {
            let id = k as u32 + 1;
            model.cameras.push(colmap_camera(id, &photo.lens));
            model.images.push(ColmapImage::from_camera(
                id,
                id,
                format!("{}.png", view.name),
                &photo.lens.camera,
            ));
        }
        if let Some(points) = &dataset.points {
            for (k, (p, rgb)) in points.positions.iter().zip(&points.colours).enumerate() {
                model.points.push(ColmapPoint {
                    id: k as u64 + 1,
                    xyz: p.as_dvec3().to_array(),
                    rgb: *rgb,
                    error: 0.0,
                    track: Vec::new(),
                });
            }
        }
        write_text(&self.root.join("sparse/0"), &model)?;
        Ok(())
    }

    pub fn write_json(&self, relative: &str, value: &impl Serialize) -> Result<(), StampError> {
        let path = self.root.join(relative);
        let text = serde_json::to_string_pretty(value)
            .map_err(|e| SynthError::InvalidParams(format!("{}: {e}", path.display())))?;
        std::fs::write(&path, text).map_err(|source| SynthError::Io { path, source })?;
        Ok(())
    }
}

/// The lens as COLMAP writes it: SIMPLE_RADIAL when that is all it is, else OPENCV, else PINHOLE.
fn colmap_camera(id: u32, lens: &Lens) -> ColmapCamera {
    let k = &lens.camera.intrinsics;
    let Some(d) = &lens.distortion else {
        return ColmapCamera::pinhole(id, k);
    };
    let (model, params) = if d.k2 == 0.0 && d.p1 == 0.0 && d.p2 == 0.0 && d.fx == d.fy {
        (CameraModel::SimpleRadial, vec![d.fx, d.cx, d.cy, d.k1])
    } else {
        (
            CameraModel::OpenCv,
            vec![d.fx, d.fy, d.cx, d.cy, d.k1, d.k2, d.p1, d.p2],
        )
    };
    ColmapCamera {
        id,
        model,
        width: k.width as u64,
        height: k.height as u64,
        params: params.into_iter().map(f64::from).collect(),
    }
}

#[derive(Serialize)]
struct PlaneRecord {
    normal: [f64; 3],
    offset: f64,
    inliers: usize,
    usable: bool,
}

#[derive(Serialize)]
struct DecalRecord {
    id: u32,
    kind: &'static str,
    plane: usize,
    /// The raster's four 3D corners (model frame), texel (0,0) first.
    corners: [[f64; 3]; 4],
    texel_m: f64,
    first_survey: u32,
    source: Option<String>,
    facade_colour: Option<super::decal::ColourStats>,
}

#[derive(Serialize)]
struct Manifest<'a> {
    survey: u32,
    capture: String,
    seed: u64,
    classes: Vec<&'static str>,
    crack_sources: Vec<String>,
    scale: &'a super::scale::Scale,
    /// Per-channel gain applied to the whole photo in this survey (exposure × white balance).
    light_gain: [f32; 3],
    planes: Vec<PlaneRecord>,
    decals: Vec<DecalRecord>,
    formats: [&'static str; 5],
}

#[allow(clippy::too_many_arguments)]
pub fn write_manifest(
    writer: &SurveyWriter,
    params: &StampParams,
    summary: &StampSummary,
    planes: &[Plane],
    usable: &[usize],
    decals: &[Decal],
    lights: &[[f32; 3]],
    survey: u32,
) -> Result<(), StampError> {
    let mpu = summary.scale.metres_per_unit;
    let manifest = Manifest {
        survey,
        capture: params.capture.display().to_string(),
        seed: params.seed,
        classes: params.classes.iter().map(|c| c.id()).collect(),
        crack_sources: params
            .crack_sources
            .iter()
            .map(|p| p.display().to_string())
            .collect(),
        scale: &summary.scale,
        light_gain: lights[survey as usize - 1],
        planes: planes
            .iter()
            .enumerate()
            .map(|(i, p)| PlaneRecord {
                normal: p.normal.to_array(),
                offset: p.offset,
                inliers: p.inliers.len(),
                usable: usable.contains(&i),
            })
            .collect(),
        decals: decals
            .iter()
            .filter(|d| d.first_survey <= survey)
            .map(|d| DecalRecord {
                id: d.id,
                kind: if d.source.is_some() { "crack" } else { "spall" },
                plane: d.plane,
                corners: d.corners().map(|c| c.to_array()),
                texel_m: d.texel * mpu,
                first_survey: d.first_survey,
                source: d.source.clone(),
                facade_colour: d.facade_stats,
            })
            .collect(),
        formats: [
            "images/<name>.png: the capture's photo as stored (lens distortion kept), damage drawn in, light_gain applied",
            "masks/<class>/<name>.png and truth/masks/<class>/<name>.png: 0/255, the pixels showing that class (classes exclusive: rebar, spalling, crack)",
            "truth/new-damage/<class>/<name>.png (survey 2): pixels showing damage absent in survey 1 (growth included)",
            "truth/quantities.json: lengths in metres, areas in square metres, centroids in the model frame",
            "sparse/0: COLMAP text, the capture's lens models and poses, its sparse points without tracks",
        ],
    };
    writer.write_json("truth/manifest.json", &manifest)
}
