//! The georeference of an SfM model: the similarity from its frame to a local east-north-up frame
//! in metres at a reference latitude, longitude and altitude (WGS84), fitted to the cameras' GPS
//! positions (or to control points, `control`). Stored with the dataset (`georef.json`), it gives
//! the twin metres (`metres_per_unit`, the similarity's scale) and north without `set-scale`,
//! and any model point a latitude, longitude and height.

use std::io::Write;
use std::path::Path;

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::scene::SceneError;
use crate::scene::atomic::write_atomic;
use crate::scene::files::read_regular;
use crate::scene::sfm::exif::GpsPosition;
use crate::scene::similarity::{Similarity, fit_trimmed, spread, umeyama};

/// The dataset file holding the georeference.
pub const GEOREF_FILE: &str = "georef.json";

// WGS84 ellipsoid.
const SEMI_MAJOR_M: f64 = 6_378_137.0;
const FLATTENING: f64 = 1.0 / 298.257_223_563;

/// Where the metric frame came from; control points win over GPS.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GeorefSource {
    Gps,
    ControlPoints,
    /// Control points in a local x/y/z frame of their own (metres, no latitude/longitude).
    LocalControlPoints,
}

/// SfM frame → local metric frame (east, north, up in metres at the reference, or the control
/// points' own x/y/z), and how well it fits.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Georeference {
    pub source: GeorefSource,
    /// The ENU origin (degrees, metres); zero for `LocalControlPoints`.
    pub latitude: f64,
    pub longitude: f64,
    pub altitude: f64,
    pub similarity: Similarity,
    /// RMS distance, in metres, of the positions the fit kept.
    pub rms_m: f64,
    /// Positions used and the ones rejected as outliers (image or point names).
    pub used: Vec<String>,
    pub rejected: Vec<String>,
    /// RMS distance of the used positions to their mean, metres: the baseline the scale rests on.
    pub baseline_m: f64,
    /// Relative 1-sigma uncertainty of the scale, `rms / (baseline · √n)`: the residual spread
    /// over the baseline and the number of positions.
    pub scale_uncertainty: f64,
    /// Why the posed model itself is in doubt, when it is: `pose` kept a mapper draw whose GPS
    /// residual is too large for a right model (`draws::GPS_PLAUSIBLE_FRACTION`). Absent in
    /// files written before it existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_doubt: Option<String>,
}

impl Georeference {
    /// Metres per model unit: the one scale the twin's `metres_per_unit` takes.
    pub fn metres_per_unit(&self) -> f64 {
        self.similarity.scale
    }

    /// A model point in the local metric frame.
    pub fn to_local(&self, p: DVec3) -> DVec3 {
        self.similarity.apply(p)
    }

    /// A model point as latitude, longitude (degrees) and height (metres); `None` for a local
    /// control-point frame, which has no geodetic position.
    pub fn to_geodetic(&self, p: DVec3) -> Option<(f64, f64, f64)> {
        (self.source != GeorefSource::LocalControlPoints).then(|| {
            let origin = (self.latitude, self.longitude, self.altitude);
            enu_to_geodetic(self.to_local(p), origin)
        })
    }

    pub fn write(&self, dataset: &Path) -> Result<(), SceneError> {
        let path = dataset.join(GEOREF_FILE);
        let text = serde_json::to_string_pretty(self)
            .map_err(|e| SceneError::invalid(&path, e.to_string()))?;
        write_atomic(&path, |w| w.write_all(text.as_bytes()))
    }

    /// The dataset's georeference, `None` when it has none.
    pub fn read(dataset: &Path) -> Result<Option<Georeference>, SceneError> {
        let path = dataset.join(GEOREF_FILE);
        if !path.exists() {
            return Ok(None);
        }
        let bytes = read_regular(&path, 1 << 20)?;
        let georef: Georeference = serde_json::from_slice(&bytes)
            .map_err(|e| SceneError::invalid(&path, e.to_string()))?;
        if !(georef.similarity.scale > 0.0 && georef.similarity.scale.is_finite()) {
            return Err(SceneError::invalid(&path, "scale is not a positive number"));
        }
        Ok(Some(georef))
    }
}

/// WGS84 geodetic (degrees, metres) to earth-centred earth-fixed metres.
pub fn geodetic_to_ecef(latitude: f64, longitude: f64, height: f64) -> DVec3 {
    let (lat, lon) = (latitude.to_radians(), longitude.to_radians());
    let e2 = FLATTENING * (2.0 - FLATTENING);
    let n = SEMI_MAJOR_M / (1.0 - e2 * lat.sin().powi(2)).sqrt();
    DVec3::new(
        (n + height) * lat.cos() * lon.cos(),
        (n + height) * lat.cos() * lon.sin(),
        (n * (1.0 - e2) + height) * lat.sin(),
    )
}

/// The east, north, up axes at a latitude and longitude (degrees), in ECEF.
fn enu_axes(latitude: f64, longitude: f64) -> [DVec3; 3] {
    let (lat, lon) = (latitude.to_radians(), longitude.to_radians());
    [
        DVec3::new(-lon.sin(), lon.cos(), 0.0),
        DVec3::new(-lat.sin() * lon.cos(), -lat.sin() * lon.sin(), lat.cos()),
        DVec3::new(lat.cos() * lon.cos(), lat.cos() * lon.sin(), lat.sin()),
    ]
}

/// A geodetic position in the ENU frame at `origin` (latitude, longitude, height).
pub fn geodetic_to_enu(position: (f64, f64, f64), origin: (f64, f64, f64)) -> DVec3 {
    let d = geodetic_to_ecef(position.0, position.1, position.2)
        - geodetic_to_ecef(origin.0, origin.1, origin.2);
    let [e, n, u] = enu_axes(origin.0, origin.1);
    DVec3::new(d.dot(e), d.dot(n), d.dot(u))
}

/// An ENU point at `origin` back to latitude, longitude (degrees) and height (Bowring's
/// iteration; sub-millimetre after a few steps near the surface).
pub fn enu_to_geodetic(p: DVec3, origin: (f64, f64, f64)) -> (f64, f64, f64) {
    let [e, n, u] = enu_axes(origin.0, origin.1);
    let x = geodetic_to_ecef(origin.0, origin.1, origin.2) + e * p.x + n * p.y + u * p.z;
    let e2 = FLATTENING * (2.0 - FLATTENING);
    let lon = x.y.atan2(x.x);
    let r = (x.x * x.x + x.y * x.y).sqrt();
    let mut lat = x.z.atan2(r * (1.0 - e2));
    let mut height = 0.0;
    for _ in 0..6 {
        let nr = SEMI_MAJOR_M / (1.0 - e2 * lat.sin().powi(2)).sqrt();
        height = r / lat.cos() - nr;
        lat = x.z.atan2(r * (1.0 - e2 * nr / (nr + height)));
    }
    (lat.to_degrees(), lon.to_degrees(), height)
}

/// The GPS positions of the cameras are good to a few metres: a camera further than this from
/// the fit (and 3 × the median) is an outlier.
const GPS_OUTLIER_FLOOR_M: f64 = 3.0;

/// Fits the georeference from camera centres (`centres`: name, SfM centre, camera "up" direction
/// in the SfM frame) to their photos' GPS fixes. Outliers are rejected (`fit_trimmed`); a fix
/// without altitude takes the mean altitude of the others. Cameras along one line (a street, a
/// single strip) leave the roll about that line free: there the photos' mean up direction is
/// held to point up (photos are taken upright), which fixes it. `Err` says why no fit is
/// possible (fewer than 3 fixes, all at one place, too many outliers).
pub fn fit_gps(centres: &[(String, DVec3, DVec3, GpsPosition)]) -> Result<Georeference, String> {
    if centres.len() < 3 {
        return Err(format!(
            "{} registered photo(s) carry GPS: a georeference needs at least 3",
            centres.len()
        ));
    }
    let altitudes: Vec<f64> = centres.iter().filter_map(|c| c.3.altitude).collect();
    let mean_altitude = if altitudes.is_empty() {
        0.0
    } else {
        altitudes.iter().sum::<f64>() / altitudes.len() as f64
    };
    let n = centres.len() as f64;
    let origin = (
        centres.iter().map(|c| c.3.latitude).sum::<f64>() / n,
        centres.iter().map(|c| c.3.longitude).sum::<f64>() / n,
        mean_altitude,
    );
    let from: Vec<DVec3> = centres.iter().map(|c| c.1).collect();
    let to: Vec<DVec3> = centres
        .iter()
        .map(|c| {
            let g = c.3;
            geodetic_to_enu(
                (g.latitude, g.longitude, g.altitude.unwrap_or(mean_altitude)),
                origin,
            )
        })
        .collect();
    let baseline = spread(&to);
    if !(baseline > 1.0) {
        return Err(format!(
            "the photos' GPS positions lie within {baseline:.2} m of each other: too close to \
             give a scale"
        ));
    }
    let trimmed = fit_trimmed(&from, &to, GPS_OUTLIER_FLOOR_M)
        .ok_or("the camera centres are degenerate (all at one place)")?;
    if trimmed.kept.len() * 2 < centres.len() {
        return Err(format!(
            "only {} of {} GPS positions agree with the model: the GPS is unusable",
            trimmed.kept.len(),
            centres.len()
        ));
    }
    let kept_from: Vec<DVec3> = trimmed.kept.iter().map(|&i| from[i]).collect();
    let kept_to: Vec<DVec3> = trimmed.kept.iter().map(|&i| to[i]).collect();
    let mut similarity = trimmed.similarity;
    if is_nearly_collinear(&kept_to) {
        // Pairs `centre + up` ↔ `gps + (0, 0, 1)·length` hold the photos' mean up to ENU up.
        let mean_up = centres
            .iter()
            .map(|c| c.2)
            .sum::<DVec3>()
            .normalize_or_zero();
        let length_sfm = spread(&kept_from);
        let length_m = length_sfm * similarity.scale;
        let mut f = kept_from.clone();
        let mut t = kept_to.clone();
        for (a, b) in kept_from.iter().zip(&kept_to) {
            f.push(*a + mean_up * length_sfm);
            t.push(*b + DVec3::Z * length_m);
        }
        if let Some(fit) = umeyama(&f, &t) {
            similarity = fit;
        }
    }
    let rms = (kept_from
        .iter()
        .zip(&kept_to)
        .map(|(a, b)| similarity.apply(*a).distance_squared(*b))
        .sum::<f64>()
        / kept_from.len() as f64)
        .sqrt();
    let name = |i: usize| centres[i].0.clone();
    Ok(Georeference {
        source: GeorefSource::Gps,
        latitude: origin.0,
        longitude: origin.1,
        altitude: origin.2,
        similarity,
        rms_m: rms,
        used: trimmed.kept.iter().map(|&i| name(i)).collect(),
        rejected: (0..centres.len())
            .filter(|i| !trimmed.kept.contains(i))
            .map(name)
            .collect(),
        baseline_m: baseline,
        scale_uncertainty: rms / (baseline * (trimmed.kept.len() as f64).sqrt()),
        model_doubt: None,
    })
}

/// Whether points spread along one line: their second principal extent is under a fifth of the
/// first.
fn is_nearly_collinear(points: &[DVec3]) -> bool {
    let n = points.len().max(1) as f64;
    let mean = points.iter().copied().sum::<DVec3>() / n;
    let mut cov = glam::DMat3::ZERO;
    for p in points {
        let d = *p - mean;
        cov += glam::DMat3::from_cols(d * d.x, d * d.y, d * d.z);
    }
    // Power iteration for the largest eigenvalue; the second from the trace of the rest.
    let mut v = DVec3::new(1.0, 0.7, 0.3);
    for _ in 0..50 {
        v = (cov * v).normalize_or_zero();
    }
    let first = v.dot(cov * v);
    let deflated = cov - first * glam::DMat3::from_cols(v * v.x, v * v.y, v * v.z);
    let mut w = DVec3::new(0.3, -1.0, 0.5);
    for _ in 0..50 {
        w = (deflated * w).normalize_or_zero();
    }
    let second = w.dot(deflated * w);
    !(second > 0.04 * first)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn enu_round_trips_and_a_metre_north_is_a_metre() {
        let origin = (55.698, 13.195, 37.0);
        let p = geodetic_to_enu((55.698 + 1e-5, 13.195, 37.0), origin);
        // 1e-5 degrees of latitude is about 1.113 m at 55.7° N.
        assert!((p.y - 1.1135).abs() < 0.002 && p.x.abs() < 1e-6, "{p}");
        let q = DVec3::new(120.0, -45.0, 8.0);
        let (lat, lon, h) = enu_to_geodetic(q, origin);
        assert!(geodetic_to_enu((lat, lon, h), origin).distance(q) < 1e-6);
    }

    #[test]
    fn known_points_convert_as_published_and_round_trip() {
        // WGS84 in ECEF: the equator at Greenwich is one semi-major axis out, the pole one
        // semi-minor axis (6 356 752.314 m) up; (45° N, 45° E, 0 m) is the textbook point
        // (3 194 419.145, 3 194 419.145, 4 487 348.409).
        let close = |a: DVec3, b: DVec3| a.distance(b) < 1e-3;
        assert!(close(
            geodetic_to_ecef(0.0, 0.0, 0.0),
            DVec3::new(6_378_137.0, 0.0, 0.0)
        ));
        assert!(close(
            geodetic_to_ecef(90.0, 0.0, 0.0),
            DVec3::new(0.0, 0.0, 6_356_752.314)
        ));
        assert!(close(
            geodetic_to_ecef(45.0, 45.0, 0.0),
            DVec3::new(3_194_419.145, 3_194_419.145, 4_487_348.409)
        ));
        // ENU at Lund: 1000 m up is 1000 m higher at the same latitude and longitude; 1000 m
        // east is 1000 / (N cos φ) radians of longitude (N the prime vertical radius).
        let origin = (55.698, 13.195, 37.0);
        let (lat, lon, h) = enu_to_geodetic(DVec3::new(0.0, 0.0, 1000.0), origin);
        assert!((lat - origin.0).abs() < 1e-9 && (lon - origin.1).abs() < 1e-9);
        assert!((h - 1037.0).abs() < 1e-6, "{h}");
        let e2 = FLATTENING * (2.0 - FLATTENING);
        let phi = origin.0.to_radians();
        let n = SEMI_MAJOR_M / (1.0 - e2 * phi.sin().powi(2)).sqrt();
        let (lat, lon, _) = enu_to_geodetic(DVec3::new(1000.0, 0.0, 0.0), origin);
        let expected = origin.1 + (1000.0 / ((n + origin.2) * phi.cos())).to_degrees();
        assert!((lon - expected).abs() < 1e-8, "{lon} {expected}");
        // 1 km east along the tangent plane is a great circle's start, which bends south of the
        // parallel in the northern hemisphere: ≈ d² tan φ / 2R = 0.12 m, about 1e-6°.
        assert!(lat < origin.0 && origin.0 - lat < 2e-6, "{lat}");
        // Round trips over a few kilometres, to a tenth of a millimetre.
        for p in [
            DVec3::new(3000.0, -2500.0, 120.0),
            DVec3::new(-40.0, 15.0, -5.0),
            DVec3::ZERO,
        ] {
            let (lat, lon, h) = enu_to_geodetic(p, origin);
            assert!(
                geodetic_to_enu((lat, lon, h), origin).distance(p) < 1e-4,
                "{p}"
            );
        }
    }

    #[test]
    fn gps_fit_recovers_scale_north_and_rejects_a_bad_fix() {
        // Cameras on a 40 m × 25 m grid in a model frame at 1/5 scale, rotated and shifted.
        let origin = (55.7, 13.2, 30.0);
        let known = Similarity {
            scale: 5.0,
            rotation: glam::DQuat::from_rotation_z(0.8).to_array(),
            translation: [3.0, -2.0, 1.0],
        };
        let inverse_rotation = known.quat().inverse();
        let mut centres = Vec::new();
        for i in 0..12 {
            let enu = DVec3::new((i % 4) as f64 * 13.0, (i / 4) as f64 * 12.0, 10.0);
            let model =
                inverse_rotation * (enu - DVec3::from_array(known.translation)) / known.scale;
            let (lat, lon, h) = enu_to_geodetic(enu, origin);
            let gps = GpsPosition {
                latitude: lat,
                longitude: lon,
                altitude: Some(h),
            };
            centres.push((format!("{i:02}.jpg"), model, DVec3::Z, gps));
        }
        centres[5].3.latitude += 4e-4; // 45 m off
        let fit = fit_gps(&centres).unwrap();
        assert_eq!(fit.rejected, vec!["05.jpg".to_string()], "{fit:?}");
        assert!((fit.metres_per_unit() - 5.0).abs() < 0.02, "{fit:?}");
        assert!(fit.rms_m < 0.05, "{fit:?}");
        // The model point of the first camera maps back to its latitude and longitude.
        let (lat, lon, _) = fit.to_geodetic(centres[0].1).unwrap();
        assert!((lat - centres[0].3.latitude).abs() < 1e-6);
        assert!((lon - centres[0].3.longitude).abs() < 1e-6);
        assert!(fit_gps(&centres[..2]).is_err());
    }
}
