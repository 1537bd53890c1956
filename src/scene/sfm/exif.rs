//! What a photo's EXIF says about where it was taken and through which lens: the GPS position
//! (WGS84 latitude, longitude, ellipsoid-or-sea-level altitude as the device wrote it) and the
//! 35 mm-equivalent focal length. Read with `kamadak-exif`; a photo without EXIF, or with a
//! field missing or malformed, has `None` there (COLMAP then starts from its default focal
//! length, and the dataset has no GPS georeference).

use std::io::BufReader;
use std::path::Path;

use exif::{In, Tag, Value};

use crate::scene::files::open_regular;

/// A GPS fix: degrees north and east, metres up (`None` when the photo has no altitude).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GpsPosition {
    pub latitude: f64,
    pub longitude: f64,
    pub altitude: Option<f64>,
}

/// The EXIF fields the pose pipeline uses.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PhotoExif {
    pub gps: Option<GpsPosition>,
    /// 35 mm-equivalent focal length in millimetres.
    pub focal_35mm: Option<f64>,
}

/// The photo's EXIF, empty when it has none or it cannot be read (EXIF is optional: the photo
/// itself is checked when COLMAP decodes it).
pub fn read_photo_exif(path: &Path) -> PhotoExif {
    let Ok(file) = open_regular(path) else {
        return PhotoExif::default();
    };
    let Ok(exif) = exif::Reader::new().read_from_container(&mut BufReader::new(file)) else {
        return PhotoExif::default();
    };
    let focal_35mm = exif
        .get_field(Tag::FocalLengthIn35mmFilm, In::PRIMARY)
        .and_then(|f| f.value.get_uint(0))
        .map(f64::from)
        .filter(|&f| f > 0.0);
    PhotoExif {
        gps: gps(&exif),
        focal_35mm,
    }
}

fn rationals(exif: &exif::Exif, tag: Tag) -> Option<Vec<f64>> {
    match &exif.get_field(tag, In::PRIMARY)?.value {
        Value::Rational(v) => Some(v.iter().map(|r| r.to_f64()).collect()),
        Value::SRational(v) => Some(v.iter().map(|r| r.to_f64()).collect()),
        _ => None,
    }
}

fn reference(exif: &exif::Exif, tag: Tag) -> Option<u8> {
    match &exif.get_field(tag, In::PRIMARY)?.value {
        Value::Ascii(v) => v.first()?.first().copied(),
        Value::Byte(v) => v.first().copied(),
        _ => None,
    }
}

/// Degrees, minutes, seconds as degrees; `None` unless all three are finite.
fn degrees(dms: &[f64]) -> Option<f64> {
    let d = dms.first()? + dms.get(1).unwrap_or(&0.0) / 60.0 + dms.get(2).unwrap_or(&0.0) / 3600.0;
    d.is_finite().then_some(d)
}

fn gps(exif: &exif::Exif) -> Option<GpsPosition> {
    let mut latitude = degrees(&rationals(exif, Tag::GPSLatitude)?)?;
    let mut longitude = degrees(&rationals(exif, Tag::GPSLongitude)?)?;
    if reference(exif, Tag::GPSLatitudeRef) == Some(b'S') {
        latitude = -latitude;
    }
    if reference(exif, Tag::GPSLongitudeRef) == Some(b'W') {
        longitude = -longitude;
    }
    if !(latitude.abs() <= 90.0 && longitude.abs() <= 180.0) {
        return None;
    }
    let altitude = rationals(exif, Tag::GPSAltitude)
        .and_then(|v| v.first().copied())
        .filter(|a| a.is_finite())
        // GPSAltitudeRef 1: below sea level.
        .map(|a| match reference(exif, Tag::GPSAltitudeRef) {
            Some(1) => -a,
            _ => a,
        });
    Some(GpsPosition {
        latitude,
        longitude,
        altitude,
    })
}
