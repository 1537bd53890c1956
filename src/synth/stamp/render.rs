//! Draws decals into a photo as it was stored (distorted): each pixel's ray is found through the
//! inverse lens model, met with the decals' planes, and shows the nearest decal texel unless a
//! nearer bounded plane hides it. Nearest-texel lookup, no blending: a pixel is changed exactly
//! when its truth mask is set.

use glam::{DVec2, DVec3};
use rayon::prelude::*;

use crate::scene::undistort::distort;
use crate::scene::{Camera, DamageClass, Distortion, Mask, RgbImage};

use super::decal::Decal;
use super::planes::Plane;

/// A view's lens and pose: pinhole camera plus the distortion of the image as stored.
#[derive(Clone, Copy, Debug)]
pub struct Lens {
    pub camera: Camera,
    pub distortion: Option<Distortion>,
}

impl Lens {
    fn stored_intrinsics(&self) -> [f64; 4] {
        match &self.distortion {
            Some(d) => [d.fx, d.fy, d.cx, d.cy].map(f64::from),
            None => {
                let k = &self.camera.intrinsics;
                [k.fx, k.fy, k.cx, k.cy].map(f64::from)
            }
        }
    }

    /// Camera centre in the model frame.
    pub fn origin(&self) -> DVec3 {
        self.camera.position().as_dvec3()
    }

    /// World direction of the ray through the stored image's continuous position `(x, y)`
    /// (pixel centres at +0.5).
    pub fn ray(&self, x: f64, y: f64) -> DVec3 {
        let [fx, fy, cx, cy] = self.stored_intrinsics();
        let (xd, yd) = ((x - cx) / fx, (y - cy) / fy);
        let (u, v) = match &self.distortion {
            Some(d) => undistort_point(xd, yd, d),
            None => (xd, yd),
        };
        let camera_dir = DVec3::new(u, v, 1.0);
        (self.camera.rotation.as_dquat().inverse() * camera_dir).normalize()
    }

    /// Where a world point lands in the stored image (continuous, pixel centres at +0.5), when
    /// in front of the camera.
    pub fn project(&self, p: DVec3) -> Option<DVec2> {
        let q = self.camera.rotation.as_dquat() * p + self.camera.translation.as_dvec3();
        if !(q.z > 1e-9) {
            return None;
        }
        let (u, v) = (q.x / q.z, q.y / q.z);
        let (u, v) = match &self.distortion {
            Some(d) => distort(u, v, d.k1.into(), d.k2.into(), d.p1.into(), d.p2.into()),
            None => (u, v),
        };
        let [fx, fy, cx, cy] = self.stored_intrinsics();
        Some(DVec2::new(fx * u + cx, fy * v + cy))
    }

    pub fn size(&self) -> (u32, u32) {
        (self.camera.intrinsics.width, self.camera.intrinsics.height)
    }
}

/// Normalised undistorted coordinates of distorted ones, by fixed-point iteration (the lens
/// models here are close to the identity over the image).
fn undistort_point(xd: f64, yd: f64, d: &Distortion) -> (f64, f64) {
    let (k1, k2, p1, p2) = (d.k1.into(), d.k2.into(), d.p1.into(), d.p2.into());
    let (mut u, mut v) = (xd, yd);
    for _ in 0..30 {
        let (du, dv) = distort(u, v, k1, k2, p1, p2);
        u -= du - xd;
        v -= dv - yd;
    }
    (u, v)
}

/// The nearest decal texel a ray meets in `survey`, unless hidden: (decal, texel, distance).
pub fn visible_texel(
    origin: DVec3,
    direction: DVec3,
    decals: &[&Decal],
    planes: &[Plane],
    survey: u32,
) -> Option<(usize, usize, f64)> {
    let mut best: Option<(usize, usize, f64)> = None;
    for (k, decal) in decals.iter().enumerate() {
        let plane = &planes[decal.plane];
        // Damage is on the side the photos see: a wall is not seen through from behind.
        if plane.normal.dot(direction) >= 0.0 {
            continue;
        }
        let Some(t) = plane.hit(origin, direction) else {
            continue;
        };
        let Some(texel) = decal.texel_at(origin + direction * t, survey) else {
            continue;
        };
        let class = decal.texels[texel].map(|t| t.class);
        let better = match best {
            None => true,
            Some((b, bt, bd)) => {
                let same_depth = (t - bd).abs() <= 1e-6 * bd.max(1e-9);
                let best_class = decals[b].texels[bt].map(|t| t.class);
                t < bd && !same_depth || same_depth && class > best_class
            }
        };
        if better {
            best = Some((k, texel, t));
        }
    }
    let (k, _, t) = best?;
    (!hidden(origin, direction, t, decals[k].plane, planes))
        .then_some(best)
        .flatten()
}

/// Whether a bounded plane other than `own` meets the ray nearer than `t`. A plane nearer by
/// less than twice its inlier distance is the same surface (sequential RANSAC splits one wall
/// into parallel planes a centimetre apart) and hides nothing.
pub fn hidden(origin: DVec3, direction: DVec3, t: f64, own: usize, planes: &[Plane]) -> bool {
    planes.iter().enumerate().any(|(i, plane)| {
        i != own
            && plane.hit(origin, direction).is_some_and(|tp| {
                let (a, b) = plane.coords(origin + direction * tp);
                tp < t - 2.0 * plane.tolerance && plane.covers(a, b)
            })
    })
}

/// A stamped photo and its truth.
pub struct Stamped {
    pub image: RgbImage,
    /// Per class, the pixels showing it.
    pub masks: Vec<(DamageClass, Mask)>,
    /// Per class, the pixels showing damage that first appears in this survey (survey 2).
    pub new_damage: Vec<(DamageClass, Mask)>,
}

/// Stamps `decals` into `photo` for `survey`, under the per-channel light `gain` (applied to the
/// whole photo: a changed exposure and white balance).
pub fn stamp_view(
    photo: &RgbImage,
    lens: &Lens,
    decals: &[Decal],
    planes: &[Plane],
    survey: u32,
    gain: [f32; 3],
) -> Stamped {
    let (w, h) = (photo.width as usize, photo.height as usize);
    let shown: Vec<&Decal> = decals.iter().filter(|d| d.first_survey <= survey).collect();
    let origin = lens.origin();
    // Per pixel: the class shown (0 none, 1 + class channel) and whether it is new.
    let rows: Vec<Vec<(u8, bool, [f32; 3])>> = (0..h)
        .into_par_iter()
        .map(|y| {
            (0..w)
                .map(|x| {
                    let i = (y * w + x) * 3;
                    let base = [0, 1, 2].map(|c| (photo.data[i + c] * gain[c]).clamp(0.0, 1.0));
                    let direction = lens.ray(x as f64 + 0.5, y as f64 + 0.5);
                    match visible_texel(origin, direction, &shown, planes, survey) {
                        Some((k, texel, _)) => {
                            let decal = shown[k];
                            let t = decal.texels[texel].expect("visible texels are set");
                            let colour = decal.colours[texel];
                            (
                                1 + t.class.channel() as u8,
                                t.appears == survey && survey > 1,
                                [0, 1, 2].map(|c| (colour[c] * gain[c]).clamp(0.0, 1.0)),
                            )
                        }
                        None => (0, false, base),
                    }
                })
                .collect()
        })
        .collect();
    let mut image = RgbImage::filled(photo.width, photo.height, [0.0; 3]);
    let mut masks: Vec<(DamageClass, Mask)> = DamageClass::ALL
        .iter()
        .map(|&c| (c, Mask::empty(photo.width, photo.height)))
        .collect();
    let mut new_damage = masks.clone();
    for (y, row) in rows.iter().enumerate() {
        for (x, &(class, new, colour)) in row.iter().enumerate() {
            let i = y * w + x;
            image.data[i * 3..i * 3 + 3].copy_from_slice(&colour);
            if class > 0 {
                masks[class as usize - 1].1.data[i] = 1;
                if new {
                    new_damage[class as usize - 1].1.data[i] = 1;
                }
            }
        }
    }
    Stamped {
        image,
        masks,
        new_damage,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Intrinsics;
    use glam::{Quat, Vec3};

    #[test]
    fn a_ray_through_a_projected_point_comes_back_to_it() {
        let k = Intrinsics {
            width: 640,
            height: 480,
            fx: 500.0,
            fy: 500.0,
            cx: 320.0,
            cy: 240.0,
        };
        let camera = Camera::new(k, Quat::from_rotation_y(0.3), Vec3::new(0.2, -0.1, 1.0));
        let lens = Lens {
            camera,
            distortion: Some(Distortion {
                fx: 500.0,
                fy: 500.0,
                cx: 320.0,
                cy: 240.0,
                k1: 0.08,
                k2: 0.0,
                p1: 0.0,
                p2: 0.0,
            }),
        };
        let p = DVec3::new(1.2, 0.7, 4.0);
        let px = lens.project(p).unwrap();
        let ray = lens.ray(px.x, px.y);
        let to_p = (p - lens.origin()).normalize();
        assert!(ray.dot(to_p) > 1.0 - 1e-12, "{}", ray.dot(to_p));
    }
}
