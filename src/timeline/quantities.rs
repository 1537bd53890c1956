//! The damage of every survey with a model, measured in metres (`damage::measure` at the
//! project's scale), each region matched with the earlier survey's regions of its class that
//! it touches: growth is the difference, a region that touches none is new.

use serde::Serialize;

use super::components::components_at;
use super::georeference::GeodeticPosition;
use super::twin::{TimelineError, Twin};
use crate::damage::DamageClass;
use crate::damage::measure::{
    MeasureConfig, MeasuredRegion, Measurement, PlaneSummary, measure_damage,
};
use crate::scene::Camera;

/// A region in metres, with its history.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ReportRegion {
    /// `<survey>-<class>-<n>`, n counting from 1 in the survey's order.
    pub id: String,
    pub class: DamageClass,
    pub centroid_m: [f64; 3],
    /// The centroid's z in metres: its height where the twin frame has z up and the ground at
    /// z = 0 (the demo building does).
    pub height_m: f64,
    /// The centroid's latitude, longitude and height, where the twin is georeferenced
    /// (`timeline::georeference`).
    pub geodetic: Option<GeodeticPosition>,
    /// The building component under the centroid, where the dataset labels components.
    pub component: Option<String>,
    pub length_m: Option<f64>,
    pub width_m: Option<f64>,
    pub area_m2: f64,
    pub gaussians: usize,
    /// Name of the survey its damage was first tagged in (None: untagged).
    pub first_seen: Option<String>,
    /// No region of the same class in the previous survey touches it.
    pub new: bool,
    /// Ids of the previous survey's regions it touches.
    pub previous: Vec<String>,
    /// Length (crack, rebar) or area (spalling) gained since the previous survey.
    pub growth: Option<f64>,
}

/// Per-class totals of a survey, in metres.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Totals {
    pub crack_length_m: f64,
    pub spalling_area_m2: f64,
    pub rebar_length_m: f64,
    pub crack_regions: usize,
    pub spalling_regions: usize,
    pub rebar_regions: usize,
    pub new_regions: usize,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SurveyQuantities {
    pub survey: String,
    pub date: String,
    pub gaussians: usize,
    pub totals: Totals,
    pub regions: Vec<ReportRegion>,
    /// The surface planes the damage was measured on.
    pub planes: Vec<PlaneSummary>,
    pub seconds: f64,
}

/// Measures every survey that has a model, oldest first.
pub fn survey_quantities(twin: &Twin) -> Result<Vec<SurveyQuantities>, TimelineError> {
    let metres = twin.project.settings.metres_per_unit.unwrap_or(1.0);
    let config = MeasureConfig::for_scale(metres);
    let georeference = twin.georeference()?;
    let names: Vec<String> = twin
        .project
        .surveys
        .iter()
        .map(|s| s.name.clone())
        .collect();
    let mut out: Vec<SurveyQuantities> = Vec::new();
    let mut previous: Option<(String, Measurement)> = None;
    // The photos of every survey so far: the twin was trained on them all, and they tell which
    // side of each surface is outside (a later survey may not photograph every facade).
    let mut cameras: Vec<Camera> = Vec::new();
    for (index, name) in names.iter().enumerate() {
        let dataset = twin.open_survey_dataset(name)?;
        cameras.extend(dataset.views.iter().map(|v| v.camera));
        let Some(splats) = twin.load_model(name)? else {
            continue;
        };
        let measurement = measure_damage(&splats, &cameras, &config);
        let centroids: Vec<glam::DVec3> = measurement
            .regions
            .iter()
            .map(|r| glam::DVec3::from_array(r.centroid))
            .collect();
        let components = components_at(&dataset, &centroids, metres);
        let mut regions = report_regions(
            name,
            &names,
            &measurement,
            previous.as_ref().map(|(n, m)| (n.as_str(), m)),
            &components,
            metres,
        );
        if let Some(g) = &georeference {
            for (region, centroid) in regions.iter_mut().zip(&centroids) {
                region.geodetic = g.geodetic(*centroid);
            }
        }
        let survey = &twin.project.surveys[index];
        out.push(SurveyQuantities {
            survey: name.clone(),
            date: survey.date.clone(),
            gaussians: splats.len(),
            totals: totals(&regions),
            regions,
            planes: measurement.planes.clone(),
            seconds: measurement.seconds,
        });
        previous = Some((name.clone(), measurement));
    }
    Ok(out)
}

fn region_id(survey: &str, class: DamageClass, n: usize) -> String {
    format!("{survey}-{}-{n}", class.id())
}

/// The ids a measurement's regions get: per class, counting from 1.
fn ids(survey: &str, measurement: &Measurement) -> Vec<String> {
    let mut counts = [0usize; 3];
    measurement
        .regions
        .iter()
        .map(|r| {
            counts[r.class.channel()] += 1;
            region_id(survey, r.class, counts[r.class.channel()])
        })
        .collect()
}

fn touches(a: &MeasuredRegion, b: &MeasuredRegion) -> bool {
    a.voxels.iter().any(|v| {
        (-1..=1).any(|dx| {
            (-1..=1)
                .any(|dy| (-1..=1).any(|dz| b.voxels.contains(&[v[0] + dx, v[1] + dy, v[2] + dz])))
        })
    })
}

fn report_regions(
    survey: &str,
    survey_names: &[String],
    measurement: &Measurement,
    previous: Option<(&str, &Measurement)>,
    components: &[Option<String>],
    metres: f64,
) -> Vec<ReportRegion> {
    let own_ids = ids(survey, measurement);
    let previous_ids = previous.map(|(name, m)| ids(name, m)).unwrap_or_default();
    measurement
        .regions
        .iter()
        .zip(own_ids)
        .zip(components)
        .map(|((region, id), component)| {
            let matched: Vec<usize> = previous
                .map(|(_, m)| {
                    (0..m.regions.len())
                        .filter(|&j| {
                            m.regions[j].class == region.class && touches(region, &m.regions[j])
                        })
                        .collect()
                })
                .unwrap_or_default();
            let size = |r: &MeasuredRegion| r.length.unwrap_or(r.area);
            let growth = previous.map(|(_, m)| {
                let before: f64 = matched.iter().map(|&j| size(&m.regions[j])).sum();
                let unit = if region.length.is_some() {
                    metres
                } else {
                    metres * metres
                };
                (size(region) - before) * unit
            });
            ReportRegion {
                id,
                class: region.class,
                centroid_m: region.centroid.map(|c| c * metres),
                height_m: region.centroid[2] * metres,
                geodetic: None,
                component: component.clone(),
                length_m: region.length.map(|l| l * metres),
                width_m: region.width.map(|w| w * metres),
                area_m2: region.area * metres * metres,
                gaussians: region.gaussians,
                first_seen: region
                    .first_survey
                    .and_then(|s| survey_names.get(usize::from(s)).cloned()),
                new: previous.is_some() && matched.is_empty(),
                previous: matched.iter().map(|&j| previous_ids[j].clone()).collect(),
                growth,
            }
        })
        .collect()
}

fn totals(regions: &[ReportRegion]) -> Totals {
    let mut t = Totals::default();
    for r in regions {
        match r.class {
            DamageClass::Crack => {
                t.crack_length_m += r.length_m.unwrap_or(0.0);
                t.crack_regions += 1;
            }
            DamageClass::Spalling => {
                t.spalling_area_m2 += r.area_m2;
                t.spalling_regions += 1;
            }
            DamageClass::Rebar => {
                t.rebar_length_m += r.length_m.unwrap_or(0.0);
                t.rebar_regions += 1;
            }
        }
        t.new_regions += usize::from(r.new);
    }
    t
}
