//! The capture's metres: `--metres-per-unit` when given, else its `georef.json`, else a fit of
//! its camera centres to the photos' EXIF GPS (`scene::sfm::georef::fit_gps`, as `pose` does).

use glam::DVec3;
use serde::Serialize;

use crate::scene::Dataset;
use crate::scene::sfm::exif::read_photo_exif;
use crate::scene::sfm::georef::{Georeference, fit_gps};

use super::params::StampError;

/// Metres per model unit and where the figure came from.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Scale {
    pub metres_per_unit: f64,
    /// `option`, `georef.json` or `exif-gps`.
    pub source: String,
    /// The GPS fit's relative 1-sigma scale uncertainty, when from GPS.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub uncertainty: Option<f64>,
}

pub fn capture_scale(dataset: &Dataset, given: Option<f64>) -> Result<Scale, StampError> {
    if let Some(metres_per_unit) = given {
        return Ok(Scale {
            metres_per_unit,
            source: "option".into(),
            uncertainty: None,
        });
    }
    if let Some(georef) = Georeference::read(&dataset.root)? {
        return Ok(Scale {
            metres_per_unit: georef.metres_per_unit(),
            source: "georef.json".into(),
            uncertainty: Some(georef.scale_uncertainty),
        });
    }
    let centres: Vec<_> = dataset
        .views
        .iter()
        .filter_map(|view| {
            let gps = read_photo_exif(&view.image_path).gps?;
            let rotation = view.camera.rotation.as_dquat();
            let centre = view.camera.position().as_dvec3();
            let up = rotation.inverse() * DVec3::NEG_Y;
            Some((view.name.clone(), centre, up, gps))
        })
        .collect();
    match fit_gps(&centres) {
        Ok(georef) => Ok(Scale {
            metres_per_unit: georef.metres_per_unit(),
            source: "exif-gps".into(),
            uncertainty: Some(georef.scale_uncertainty),
        }),
        Err(why) => Err(StampError::refused(
            &dataset.root,
            format!("no metres: no georef.json and no GPS scale ({why}); give --metres-per-unit"),
        )),
    }
}
