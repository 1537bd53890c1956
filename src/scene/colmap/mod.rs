//! COLMAP sparse models (`cameras`, `images`, `points3D`), binary and text, read and written
//! losslessly, and the conversion of COLMAP cameras to damage-twin's pinhole + distortion.
//! Pure file formats: no image pixels, no dataset layout (that is `scene::open`).

mod binary;
mod text;

use std::path::Path;

use glam::{Quat, Vec3};

use crate::scene::limits::check_image_size;
use crate::scene::{Camera, Distortion, Intrinsics, SceneError};

pub use binary::{read_binary, write_binary};
pub use text::{read_text, write_text};

/// Every camera model COLMAP defines, with the ids its binary format uses
/// (`colmap/src/colmap/sensor/models.h`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum CameraModel {
    SimplePinhole,
    Pinhole,
    SimpleRadial,
    Radial,
    OpenCv,
    OpenCvFisheye,
    FullOpenCv,
    Fov,
    SimpleRadialFisheye,
    RadialFisheye,
    ThinPrismFisheye,
    RadTanThinPrismFisheye,
}

impl CameraModel {
    /// All models in id order (`ALL[i].id() == i`).
    pub const ALL: [CameraModel; 12] = [
        CameraModel::SimplePinhole,
        CameraModel::Pinhole,
        CameraModel::SimpleRadial,
        CameraModel::Radial,
        CameraModel::OpenCv,
        CameraModel::OpenCvFisheye,
        CameraModel::FullOpenCv,
        CameraModel::Fov,
        CameraModel::SimpleRadialFisheye,
        CameraModel::RadialFisheye,
        CameraModel::ThinPrismFisheye,
        CameraModel::RadTanThinPrismFisheye,
    ];

    /// COLMAP's numeric model id (binary `cameras.bin`).
    pub fn id(self) -> i32 {
        self as i32
    }

    pub fn from_id(id: i32) -> Option<CameraModel> {
        usize::try_from(id)
            .ok()
            .and_then(|i| CameraModel::ALL.get(i).copied())
    }

    /// COLMAP's model name (text `cameras.txt`).
    pub fn name(self) -> &'static str {
        match self {
            CameraModel::SimplePinhole => "SIMPLE_PINHOLE",
            CameraModel::Pinhole => "PINHOLE",
            CameraModel::SimpleRadial => "SIMPLE_RADIAL",
            CameraModel::Radial => "RADIAL",
            CameraModel::OpenCv => "OPENCV",
            CameraModel::OpenCvFisheye => "OPENCV_FISHEYE",
            CameraModel::FullOpenCv => "FULL_OPENCV",
            CameraModel::Fov => "FOV",
            CameraModel::SimpleRadialFisheye => "SIMPLE_RADIAL_FISHEYE",
            CameraModel::RadialFisheye => "RADIAL_FISHEYE",
            CameraModel::ThinPrismFisheye => "THIN_PRISM_FISHEYE",
            CameraModel::RadTanThinPrismFisheye => "RAD_TAN_THIN_PRISM_FISHEYE",
        }
    }

    pub fn from_name(name: &str) -> Option<CameraModel> {
        CameraModel::ALL.into_iter().find(|m| m.name() == name)
    }

    /// Number of parameters COLMAP stores for this model.
    pub fn param_count(self) -> usize {
        match self {
            CameraModel::SimplePinhole => 3,           // f cx cy
            CameraModel::Pinhole => 4,                 // fx fy cx cy
            CameraModel::SimpleRadial => 4,            // f cx cy k
            CameraModel::Radial => 5,                  // f cx cy k1 k2
            CameraModel::OpenCv => 8,                  // fx fy cx cy k1 k2 p1 p2
            CameraModel::OpenCvFisheye => 8,           // fx fy cx cy k1 k2 k3 k4
            CameraModel::FullOpenCv => 12,             // fx fy cx cy k1 k2 p1 p2 k3 k4 k5 k6
            CameraModel::Fov => 5,                     // fx fy cx cy omega
            CameraModel::SimpleRadialFisheye => 4,     // f cx cy k
            CameraModel::RadialFisheye => 5,           // f cx cy k1 k2
            CameraModel::ThinPrismFisheye => 12,       // fx fy cx cy k1 k2 p1 p2 k3 k4 sx1 sy1
            CameraModel::RadTanThinPrismFisheye => 16, // fx fy cx cy k0..k5 p0 p1 s0..s3
        }
    }
}

/// A whole sparse model, entries in file order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ColmapModel {
    pub cameras: Vec<ColmapCamera>,
    pub images: Vec<ColmapImage>,
    pub points: Vec<ColmapPoint>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct ColmapCamera {
    pub id: u32,
    pub model: CameraModel,
    pub width: u64,
    pub height: u64,
    /// Exactly `model.param_count()` values.
    pub params: Vec<f64>,
}

/// A registered image: world-to-camera pose and its 2D keypoints.
#[derive(Clone, Debug, PartialEq)]
pub struct ColmapImage {
    pub id: u32,
    /// Rotation quaternion, COLMAP order `w x y z`.
    pub qvec: [f64; 4],
    pub tvec: [f64; 3],
    pub camera_id: u32,
    /// File name relative to the images folder (may contain `/`).
    pub name: String,
    /// Keypoint position and the id of its 3D point (`-1`: none).
    pub points2d: Vec<([f64; 2], i64)>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct ColmapPoint {
    pub id: u64,
    pub xyz: [f64; 3],
    pub rgb: [u8; 3],
    pub error: f64,
    /// (image id, keypoint index) observations.
    pub track: Vec<(u32, u32)>,
}

impl ColmapCamera {
    /// A PINHOLE camera with these intrinsics (for writers of synthetic datasets).
    pub fn pinhole(id: u32, k: &Intrinsics) -> ColmapCamera {
        ColmapCamera {
            id,
            model: CameraModel::Pinhole,
            width: k.width as u64,
            height: k.height as u64,
            params: vec![k.fx as f64, k.fy as f64, k.cx as f64, k.cy as f64],
        }
    }

    /// The pinhole camera damage-twin renders with, and the distortion to remove on load.
    /// PINHOLE / SIMPLE_PINHOLE map directly; SIMPLE_RADIAL, RADIAL and OPENCV keep the same size
    /// and fx, fy, cx, cy and return their distortion (`None` when every coefficient is zero);
    /// every other model is `Unsupported`. `path` names the file the camera came from.
    pub fn to_pinhole(&self, path: &Path) -> Result<(Intrinsics, Option<Distortion>), SceneError> {
        let p = &self.params;
        if p.len() != self.model.param_count() {
            return Err(SceneError::invalid(
                path,
                format!(
                    "camera {}: {} needs {} parameters, found {}",
                    self.id,
                    self.model.name(),
                    self.model.param_count(),
                    p.len()
                ),
            ));
        }
        // (fx, fy, cx, cy, k1, k2, p1, p2)
        let (fx, fy, cx, cy, k1, k2, p1, p2) = match self.model {
            CameraModel::SimplePinhole => (p[0], p[0], p[1], p[2], 0.0, 0.0, 0.0, 0.0),
            CameraModel::Pinhole => (p[0], p[1], p[2], p[3], 0.0, 0.0, 0.0, 0.0),
            CameraModel::SimpleRadial => (p[0], p[0], p[1], p[2], p[3], 0.0, 0.0, 0.0),
            CameraModel::Radial => (p[0], p[0], p[1], p[2], p[3], p[4], 0.0, 0.0),
            CameraModel::OpenCv => (p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7]),
            other => {
                return Err(SceneError::unsupported(
                    path,
                    format!(
                        "camera {}: model {} (only PINHOLE, SIMPLE_PINHOLE, SIMPLE_RADIAL, \
                         RADIAL and OPENCV can be undistorted; run COLMAP's image_undistorter)",
                        self.id,
                        other.name()
                    ),
                ));
            }
        };
        // Within the limits before anything is sized from it (a 4294967295² camera wrapped the
        // renderer's tile count to 0; a 999999² one asked for 312 GB).
        check_image_size(self.width, self.height)
            .map_err(|m| SceneError::invalid(path, format!("camera {}: {m}", self.id)))?;
        let (width, height) = (self.width as u32, self.height as u32);
        // `!(f > 0)` rejects NaN as well.
        if !(fx > 0.0 && fy > 0.0 && fx.is_finite() && fy.is_finite())
            || ![cx, cy, k1, k2, p1, p2].iter().all(|v| v.is_finite())
        {
            return Err(SceneError::invalid(
                path,
                format!(
                    "camera {}: parameters {:?} are not a valid {}",
                    self.id,
                    p,
                    self.model.name()
                ),
            ));
        }
        let intrinsics = Intrinsics {
            width,
            height,
            fx: fx as f32,
            fy: fy as f32,
            cx: cx as f32,
            cy: cy as f32,
        };
        let distortion = [k1, k2, p1, p2]
            .iter()
            .any(|&v| v != 0.0)
            .then_some(Distortion {
                fx: fx as f32,
                fy: fy as f32,
                cx: cx as f32,
                cy: cy as f32,
                k1: k1 as f32,
                k2: k2 as f32,
                p1: p1 as f32,
                p2: p2 as f32,
            });
        Ok((intrinsics, distortion))
    }
}

impl ColmapImage {
    /// A registered image with `camera`'s pose and no keypoints (for writers of synthetic datasets).
    pub fn from_camera(
        id: u32,
        camera_id: u32,
        name: impl Into<String>,
        camera: &Camera,
    ) -> ColmapImage {
        let q = camera.rotation;
        let t = camera.translation;
        ColmapImage {
            id,
            qvec: [q.w as f64, q.x as f64, q.y as f64, q.z as f64],
            tvec: [t.x as f64, t.y as f64, t.z as f64],
            camera_id,
            name: name.into(),
            points2d: Vec::new(),
        }
    }

    /// World-to-camera rotation (normalised) and translation, `None` when not finite or the
    /// quaternion is zero.
    pub fn pose(&self) -> Option<(Quat, Vec3)> {
        let [w, x, y, z] = self.qvec;
        let q = glam::DQuat::from_xyzw(x, y, z, w);
        let norm = q.length();
        // `!(norm > eps)` also rejects NaN.
        if !(norm > 1e-12) || !norm.is_finite() || !self.tvec.iter().all(|v| v.is_finite()) {
            return None;
        }
        let q = q / norm;
        let rotation = Quat::from_xyzw(q.x as f32, q.y as f32, q.z as f32, q.w as f32);
        let [tx, ty, tz] = self.tvec;
        Some((rotation, Vec3::new(tx as f32, ty as f32, tz as f32)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn model_ids_names_and_param_counts_match_colmap() {
        for (i, m) in CameraModel::ALL.into_iter().enumerate() {
            assert_eq!(m.id(), i as i32);
            assert_eq!(CameraModel::from_id(i as i32), Some(m));
            assert_eq!(CameraModel::from_name(m.name()), Some(m));
        }
        assert_eq!(CameraModel::from_id(12), None);
        assert_eq!(CameraModel::from_id(-1), None);
        assert_eq!(CameraModel::OpenCv.param_count(), 8);
        assert_eq!(CameraModel::FullOpenCv.param_count(), 12);
        assert_eq!(CameraModel::RadTanThinPrismFisheye.param_count(), 16);
    }

    #[test]
    fn simple_radial_becomes_pinhole_plus_k1_and_fisheye_is_refused() {
        let cam = ColmapCamera {
            id: 1,
            model: CameraModel::SimpleRadial,
            width: 1024,
            height: 768,
            params: vec![759.0, 512.0, 384.0, 0.0142],
        };
        let (k, d) = cam.to_pinhole(Path::new("cameras.bin")).unwrap();
        assert_eq!(
            (k.width, k.fx, k.fy, k.cx, k.cy),
            (1024, 759.0, 759.0, 512.0, 384.0)
        );
        let d = d.unwrap();
        assert_eq!((d.k1, d.k2, d.p1, d.p2), (0.0142, 0.0, 0.0, 0.0));

        let fisheye = ColmapCamera {
            model: CameraModel::OpenCvFisheye,
            params: vec![1.0; 8],
            ..cam
        };
        let err = fisheye.to_pinhole(Path::new("cameras.bin")).unwrap_err();
        assert!(matches!(err, SceneError::Unsupported { .. }), "{err}");
        assert!(err.to_string().contains("OPENCV_FISHEYE"), "{err}");
    }
}
