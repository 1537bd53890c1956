//! Where the twin is on the earth and how its surveys were placed, for the report: the
//! georeference (`timeline::georeference`: source, residual, baseline, how far its scale can be
//! trusted) and each COLMAP-registered survey's residual (`timeline::register_survey`).

use std::collections::BTreeMap;
use std::fmt::Write as _;

use serde::Serialize;

use crate::report::inspection::escape;
use crate::scene::sfm::georef::GeorefSource;
use crate::timeline::georeference::TwinGeoreference;
use crate::timeline::register_survey::SurveyRegistration;

/// The twin's georeference as the report states it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ReportGeoreference {
    /// The survey whose dataset holds it.
    pub survey: String,
    pub source: GeorefSource,
    /// The ENU origin (degrees, metres).
    pub latitude: f64,
    pub longitude: f64,
    pub altitude: f64,
    /// Metres per twin unit by the georeference (the project's scale may have been set apart).
    pub metres_per_unit: f64,
    pub rms_m: f64,
    pub baseline_m: f64,
    pub positions: usize,
    /// Relative 1-sigma uncertainty of the scale.
    pub scale_uncertainty: f64,
    /// How far it can be trusted, in a sentence.
    pub trust: String,
}

impl ReportGeoreference {
    pub fn of(twin: &TwinGeoreference) -> ReportGeoreference {
        let g = &twin.georeference;
        ReportGeoreference {
            survey: twin.survey.clone(),
            source: g.source,
            latitude: g.latitude,
            longitude: g.longitude,
            altitude: g.altitude,
            metres_per_unit: twin.metres_per_unit(),
            rms_m: g.rms_m,
            baseline_m: g.baseline_m,
            positions: g.used.len(),
            scale_uncertainty: g.scale_uncertainty,
            trust: twin.trust(),
        }
    }
}

/// The page's section on the georeference and the registrations (empty when there is neither).
pub fn placement_html(
    georeference: Option<&ReportGeoreference>,
    registrations: &BTreeMap<String, SurveyRegistration>,
) -> String {
    let mut h = String::new();
    if georeference.is_none() && registrations.is_empty() {
        return h;
    }
    h.push_str("<h2>Position and registration</h2>");
    if let Some(g) = georeference {
        let _ = write!(
            h,
            "<p>Georeferenced ({:?}) at {:.6}° N, {:.6}° E, {:.1} m; {:.4} m per model unit. {}</p>",
            g.source,
            g.latitude,
            g.longitude,
            g.altitude,
            g.metres_per_unit,
            escape(&g.trust)
        );
    }
    for (survey, record) in registrations {
        let _ = write!(
            h,
            "<p>Survey {}: {}.</p>",
            escape(survey),
            escape(&record.describe())
        );
    }
    h
}
