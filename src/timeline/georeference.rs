//! The twin's georeference: the `georef.json` that `damage-twin pose` wrote beside the first
//! posed survey's dataset (GPS or control points), read in the twin's frame, so that any point of
//! the twin (a damage region's centroid) has a latitude, longitude and height, and the report can
//! say how far the GPS scale can be trusted.

use glam::{DQuat, DVec3};
use serde::Serialize;

use crate::scene::project::Alignment;
use crate::scene::sfm::georef::{GeorefSource, Georeference};
use crate::timeline::twin::{TimelineError, Twin};

/// A position on the WGS84 ellipsoid (degrees) and its height (metres, in the reference of the
/// altitudes the fit used: for phone and drone GPS, above sea level as the device reports it).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct GeodeticPosition {
    pub latitude: f64,
    pub longitude: f64,
    pub height_m: f64,
}

/// A dataset's georeference and the survey's alignment it is read through.
#[derive(Clone, Debug)]
pub struct TwinGeoreference {
    /// The survey whose dataset holds it.
    pub survey: String,
    pub georeference: Georeference,
    /// Twin frame → the dataset's frame (the inverse of the survey's alignment), when aligned.
    from_twin: Option<(f64, DQuat, DVec3)>,
}

impl TwinGeoreference {
    fn new(survey: String, georeference: Georeference, alignment: Option<&Alignment>) -> Self {
        // x_twin = s·R·x + T  ⇒  x = R⁻¹·(x_twin − T)/s.
        let from_twin = alignment.map(|a| {
            let inverse = DQuat::from_array(a.rotation).normalize().inverse();
            (a.scale, inverse, DVec3::from_array(a.translation))
        });
        TwinGeoreference {
            survey,
            georeference,
            from_twin,
        }
    }

    /// A point of the twin (model units) as latitude, longitude and height; `None` when the
    /// georeference is a local control-point frame with no geodetic position.
    pub fn geodetic(&self, twin_point: DVec3) -> Option<GeodeticPosition> {
        let point = match self.from_twin {
            Some((scale, inverse, translation)) => inverse * (twin_point - translation) / scale,
            None => twin_point,
        };
        self.georeference
            .to_geodetic(point)
            .map(|(latitude, longitude, height_m)| GeodeticPosition {
                latitude,
                longitude,
                height_m,
            })
    }

    /// Metres per twin unit by this georeference (the dataset's scale over the alignment's).
    pub fn metres_per_unit(&self) -> f64 {
        let alignment_scale = self.from_twin.map_or(1.0, |(s, _, _)| s);
        self.georeference.metres_per_unit() / alignment_scale
    }

    /// How far the georeference can be trusted, in a sentence for the report.
    pub fn trust(&self) -> String {
        let g = &self.georeference;
        let percent = 100.0 * g.scale_uncertainty;
        let source = match g.source {
            GeorefSource::Gps => "the photos' GPS",
            GeorefSource::ControlPoints | GeorefSource::LocalControlPoints => {
                "surveyed control points"
            }
        };
        let verdict = if g.scale_uncertainty <= 0.01 {
            "lengths can be trusted to about that"
        } else if g.scale_uncertainty <= 0.05 {
            "trust lengths to a few per cent; for better, add control points or set the scale \
             from a measured distance (`twin set-scale`)"
        } else {
            "do not trust lengths from this scale: the positions scatter too much for their \
             baseline; add control points or set the scale from a measured distance"
        };
        let doubt = g
            .model_doubt
            .as_ref()
            .map_or(String::new(), |why| format!("Warning: {why}. "));
        format!(
            "{doubt}Metres and coordinates come from {source} ({n} positions, {r:.2} m RMS residual, \
             {b:.1} m baseline; survey {s}): the scale is good to ±{percent:.1} % (1σ, residual \
             over baseline and √n), so a 1 m length carries ±{mm:.0} mm from the scale alone; \
             {verdict}. Positions (latitude, longitude, height) are good to about {r:.1} m, \
             the residual of the fit{gps}.",
            n = g.used.len(),
            r = g.rms_m,
            b = g.baseline_m,
            s = self.survey,
            mm = 10.0 * percent,
            gps = if g.source == GeorefSource::Gps {
                " (phone and drone GPS is good to a few metres)"
            } else {
                ""
            }
        )
    }
}

impl Twin {
    /// The georeference of the first survey whose dataset has one (`georef.json`), in the twin's
    /// frame; `None` when no dataset is georeferenced.
    pub fn georeference(&self) -> Result<Option<TwinGeoreference>, TimelineError> {
        for survey in &self.project.surveys {
            let dataset = self.resolve(&survey.dataset);
            if survey.dataset.as_os_str().is_empty() {
                continue;
            }
            if let Some(georef) = Georeference::read(&dataset)? {
                return Ok(Some(TwinGeoreference::new(
                    survey.name.clone(),
                    georef,
                    survey.alignment.as_ref(),
                )));
            }
        }
        Ok(None)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::sfm::georef::{enu_to_geodetic, geodetic_to_enu};
    use crate::scene::similarity::Similarity;

    fn georef(similarity: Similarity) -> Georeference {
        Georeference {
            source: GeorefSource::Gps,
            latitude: 55.698,
            longitude: 13.195,
            altitude: 40.0,
            similarity,
            rms_m: 4.0,
            used: (0..25).map(|i| i.to_string()).collect(),
            rejected: Vec::new(),
            baseline_m: 50.0,
            scale_uncertainty: 4.0 / (50.0 * 5.0),
            model_doubt: None,
        }
    }

    #[test]
    fn a_twin_point_reads_through_the_alignment_to_its_latitude_and_longitude() {
        // Dataset frame → ENU: 10 m per unit, rotated 30° about up, shifted.
        let to_enu = Similarity {
            scale: 10.0,
            rotation: DQuat::from_rotation_z(0.5).to_array(),
            translation: [5.0, -3.0, 1.0],
        };
        // Dataset → twin: half scale, rotated about x, shifted.
        let alignment = Alignment {
            scale: 0.5,
            rotation: DQuat::from_rotation_x(0.3).to_array(),
            translation: [1.0, 2.0, 3.0],
            residual: 0.0,
            shared: 3,
            inliers: 3,
        };
        let aligned = TwinGeoreference::new("s1".into(), georef(to_enu), Some(&alignment));
        let dataset_point = DVec3::new(2.0, -1.0, 0.5);
        let twin_point =
            0.5 * (DQuat::from_rotation_x(0.3) * dataset_point) + DVec3::new(1.0, 2.0, 3.0);
        let position = aligned.geodetic(twin_point).unwrap();
        let enu = geodetic_to_enu(
            (position.latitude, position.longitude, position.height_m),
            (55.698, 13.195, 40.0),
        );
        assert!(enu.distance(to_enu.apply(dataset_point)) < 1e-6, "{enu}");
        assert!((aligned.metres_per_unit() - 20.0).abs() < 1e-12);
        // Unaligned, the twin's frame is the dataset's.
        let plain = TwinGeoreference::new("s1".into(), georef(to_enu), None);
        let expected = enu_to_geodetic(to_enu.apply(dataset_point), (55.698, 13.195, 40.0));
        let p = plain.geodetic(dataset_point).unwrap();
        assert_eq!((p.latitude, p.longitude, p.height_m), expected);
        assert!(plain.trust().contains("±1.6 %"), "{}", plain.trust());
        assert!(!plain.trust().contains("Warning"), "{}", plain.trust());
        // A model `pose` doubted says so first.
        let mut doubted = georef(to_enu);
        doubted.model_doubt = Some("no mapper draw agrees with the photos' GPS".into());
        let doubted = TwinGeoreference::new("s1".into(), doubted, None);
        assert!(
            doubted
                .trust()
                .starts_with("Warning: no mapper draw agrees with the photos' GPS. Metres"),
            "{}",
            doubted.trust()
        );
    }
}
