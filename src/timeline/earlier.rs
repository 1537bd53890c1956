//! The earlier survey's own masks as evidence of old damage. The twin shows the damage it
//! learnt, and a coarse twin misses some: a crack that survey 1's distant views saw only at a few
//! pixels' width may carry no label at all, and every survey-2 view of it then calls it new. The
//! earlier survey's masks do show it. A candidate pixel of a later view is lifted to the surface
//! with the twin's depth, projected into every earlier view that sees that surface point (its
//! depth there agrees with the twin's), and it is old damage when at least half of those views'
//! masks show the same class within `radius_px` of it. The twin serves only as geometry here.

use glam::Vec3;

use crate::damage::DamageClass;
use crate::raster::{RenderOutput, RenderSettings, render};
use crate::scene::{Camera, Dataset, ImageScale, Mask, SceneError};
use crate::splats::Splats;

/// A surface point is visible in a view when the twin's depth there is within this fraction of
/// the point's own depth (3 cm at 1 m, 30 cm at 10 m: far above the twin's surface noise, far
/// below a storey).
const DEPTH_TOLERANCE: f32 = 0.03;
/// A rendered pixel has a surface when its opacity is at least this.
const MIN_ALPHA: f32 = 0.5;

/// One earlier view: its camera, the twin's depth seen from it and its masks per class.
struct EarlierView {
    camera: Camera,
    /// Surface depth per pixel (NaN where the twin is transparent).
    depth: Vec<f32>,
    /// Per class in `DamageClass::ALL` order (an empty mask where the class has none).
    masks: Vec<Mask>,
}

/// The earlier survey's views with masks, and the twin's depth from each.
pub struct EarlierSurvey {
    views: Vec<EarlierView>,
    /// Mask pixels within this distance of the projected point count as at it.
    radius_px: i64,
}

/// Per pixel the surface depth of a render (`depth / alpha`), NaN where there is no surface.
pub fn surface_depth(out: &RenderOutput) -> Vec<f32> {
    out.depth
        .iter()
        .zip(&out.alpha)
        .map(|(&d, &a)| if a >= MIN_ALPHA { d / a } else { f32::NAN })
        .collect()
}

/// The world point seen at pixel `p` of `camera` at surface depth `z` (pixel centres at +0.5).
pub fn unproject(camera: &Camera, p: usize, z: f32) -> Vec3 {
    let k = &camera.intrinsics;
    let (x, y) = ((p % k.width as usize) as f32, (p / k.width as usize) as f32);
    let in_camera = Vec3::new((x + 0.5 - k.cx) / k.fx * z, (y + 0.5 - k.cy) / k.fy * z, z);
    camera.rotation.inverse() * (in_camera - camera.translation)
}

impl EarlierSurvey {
    /// Loads `dataset`'s masks at `scale` and renders the twin's depth from each of its views.
    /// Views without masks are skipped; a survey with none gives no evidence.
    /// `radius_px`: mask pixels within this distance of the projected point count as at it
    /// (the twin's depth error moves the projection).
    pub fn load(
        twin: &Splats,
        dataset: &Dataset,
        scale: ImageScale,
        settings: &RenderSettings,
        radius_px: u32,
    ) -> Result<EarlierSurvey, SceneError> {
        let mut views = Vec::new();
        let radius_px = i64::from(radius_px);
        let Some(masks) = dataset.masks.clone() else {
            return Ok(EarlierSurvey { views, radius_px });
        };
        for index in 0..dataset.views.len() {
            let (camera, mut found) = dataset.load_view_masks(index, masks.as_ref(), scale)?;
            if found.is_empty() {
                continue;
            }
            let k = camera.intrinsics;
            let masks = DamageClass::ALL
                .iter()
                .map(|c| {
                    found
                        .remove(c)
                        .unwrap_or_else(|| Mask::empty(k.width, k.height))
                })
                .collect();
            let depth = surface_depth(&render(twin, &camera, settings));
            views.push(EarlierView {
                camera,
                depth,
                masks,
            });
        }
        Ok(EarlierSurvey { views, radius_px })
    }

    /// View `i`'s camera and the twin's surface depth from it (in `from_views` order).
    pub fn view(&self, i: usize) -> (&Camera, &[f32]) {
        let view = &self.views[i];
        (&view.camera, &view.depth)
    }

    /// True when no earlier view has masks: the survey gives no evidence.
    pub fn is_empty(&self) -> bool {
        self.views.is_empty()
    }

    /// Views already rendered: per view its camera, the twin's surface depth from it
    /// (`surface_depth`) and its masks per class in `DamageClass::ALL` order.
    pub fn from_views(views: Vec<(Camera, Vec<f32>, Vec<Mask>)>, radius_px: u32) -> EarlierSurvey {
        EarlierSurvey {
            views: views
                .into_iter()
                .map(|(camera, depth, masks)| EarlierView {
                    camera,
                    depth,
                    masks,
                })
                .collect(),
            radius_px: i64::from(radius_px),
        }
    }

    /// Whether the earlier survey showed damage of `class` at `point`: `None` when no earlier
    /// view sees the point, else whether at least half of the views that see it do.
    pub fn saw_damage(&self, point: Vec3, class: usize) -> Option<bool> {
        let (seen, damaged) = self.votes(point, class);
        (seen > 0).then_some(2 * damaged >= seen)
    }

    /// How many views see `point` (the twin's surface there is the point's), and how many of
    /// those show damage of `class` within the radius of it.
    pub fn votes(&self, point: Vec3, class: usize) -> (usize, usize) {
        let (mut seen, mut damaged) = (0usize, 0usize);
        for view in &self.views {
            let Some((x, y)) = view.camera.pixel_of(point) else {
                continue;
            };
            let k = &view.camera.intrinsics;
            let (x, y) = (i64::from(x), i64::from(y));
            let (w, h) = (i64::from(k.width), i64::from(k.height));
            let z = view.camera.world_to_camera(point).z;
            let surface = view.depth[(y * w + x) as usize];
            // Occluded (or no surface there): this view says nothing about the point.
            if !((surface - z).abs() <= DEPTH_TOLERANCE * z) {
                continue;
            }
            seen += 1;
            let r = self.radius_px;
            let mask = &view.masks[class];
            let near = (y - r).max(0)..=(y + r).min(h - 1);
            let hit = near.into_iter().any(|yy| {
                ((x - r).max(0)..=(x + r).min(w - 1))
                    .any(|xx| mask.data[(yy * w + xx) as usize] != 0)
            });
            damaged += usize::from(hit);
        }
        (seen, damaged)
    }

    /// Drops from `candidates` (one mask per class of a later view seen by `camera`, with the
    /// twin's `depth` from it) every pixel the earlier survey already showed as that class.
    /// Returns how many pixels it dropped.
    pub fn drop_old(&self, camera: &Camera, depth: &[f32], candidates: &mut [Mask]) -> usize {
        let mut dropped = 0;
        for (class, mask) in candidates.iter_mut().enumerate() {
            for (p, (value, &z)) in mask.data.iter_mut().zip(depth).enumerate() {
                if *value == 0 || !z.is_finite() {
                    continue;
                }
                if self.saw_damage(unproject(camera, p, z), class) == Some(true) {
                    *value = 0;
                    dropped += 1;
                }
            }
        }
        dropped
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Intrinsics;
    use glam::{Quat, Vec2};

    #[test]
    fn unproject_inverts_project_at_pixel_centres() {
        let k = Intrinsics {
            width: 64,
            height: 48,
            fx: 50.0,
            fy: 52.0,
            cx: 31.0,
            cy: 25.0,
        };
        let camera = Camera::new(
            k,
            Quat::from_euler(glam::EulerRot::XYZ, 0.1, -0.2, 0.05),
            Vec3::new(0.3, -0.1, 2.0),
        );
        for p in [0usize, 17, 64 * 20 + 40, 64 * 48 - 1] {
            let point = unproject(&camera, p, 3.5);
            assert!((camera.world_to_camera(point).z - 3.5).abs() < 1e-4);
            let pixel = camera.project(point).expect("in front");
            let expected = Vec2::new((p % 64) as f32 + 0.5, (p / 64) as f32 + 0.5);
            assert!((pixel - expected).length() < 1e-3, "{pixel} {expected}");
        }
    }

    #[test]
    fn only_views_that_see_the_point_vote() {
        let k = Intrinsics {
            width: 20,
            height: 20,
            fx: 20.0,
            fy: 20.0,
            cx: 10.0,
            cy: 10.0,
        };
        // Three views of a wall at z = 5 straight ahead; the point is at the image centre.
        let camera = Camera::new(k, Quat::IDENTITY, Vec3::ZERO);
        let point = Vec3::new(0.0, 0.0, 5.0);
        let view = |damaged: bool, depth: f32| {
            let mut crack = Mask::empty(20, 20);
            if damaged {
                crack.data[10 * 20 + 11] = 1; // one pixel off: within the radius
            }
            EarlierView {
                camera,
                depth: vec![depth; 400],
                masks: vec![crack, Mask::empty(20, 20), Mask::empty(20, 20)],
            }
        };
        let survey = |views| EarlierSurvey {
            views,
            radius_px: 1,
        };
        // Two views see damage, one sees none: old damage.
        let seen = survey(vec![view(true, 5.0), view(true, 5.0), view(false, 5.0)]);
        assert_eq!(seen.saw_damage(point, 0), Some(true));
        assert_eq!(seen.saw_damage(point, 1), Some(false));
        // The damaged views are occluded (the twin's surface is nearer): they do not count.
        let occluded = survey(vec![view(true, 3.0), view(true, 3.0), view(false, 5.0)]);
        assert_eq!(occluded.saw_damage(point, 0), Some(false));
        // Nobody sees it: no evidence.
        let blind = survey(vec![view(true, 2.0)]);
        assert_eq!(blind.saw_damage(point, 0), None);
        // drop_old removes the candidate pixel at the point, not one elsewhere.
        let mut candidates = vec![
            Mask::empty(20, 20),
            Mask::empty(20, 20),
            Mask::empty(20, 20),
        ];
        candidates[0].data[10 * 20 + 10] = 1;
        candidates[1].data[10 * 20 + 10] = 1;
        let dropped = seen.drop_old(&camera, &[5.0; 400], &mut candidates);
        assert_eq!(dropped, 1);
        assert_eq!(candidates[0].data[10 * 20 + 10], 0);
        assert_eq!(candidates[1].data[10 * 20 + 10], 1);
    }
}
