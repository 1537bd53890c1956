//! Near floaters: Gaussians a new pose sees right in front of its camera. A later survey flies
//! where the earlier one did not, and a floater that no earlier view constrained can sit right
//! in front of a new camera and hide the twin behind it. Here is the one definition of such a
//! floater (`near_floaters`) and the render that leaves them out; what to do about them is the
//! caller's (detection and the update's light fit and seeds leave them out of their renders, the
//! update clears those over damage).

use crate::raster::{RenderSettings, camera_depths};
use crate::scene::Camera;
use crate::splats::Splats;

/// A Gaussian whose centre is nearer a new camera than this fraction of the median depth of the
/// Gaussians in front of it is a floater there.
const NEAR_FLOATER_FRACTION: f32 = 0.25;

/// The settings under which `settings` renders the twin as a new pose should see it: Gaussians
/// whose centres lie nearer the camera than a quarter of the median depth of those in front of
/// it (`near_floaters`) are left out. A later survey flies where the earlier one did not, and a
/// floater that no earlier view constrained can sit right in front of a new camera: on the demo
/// building one at 0.18 m covered survey 2's view 4 and hid a whole wall of old cracks, which
/// all came out as new damage (docs/TIMELINE.md).
///
/// The floaters are exactly the Gaussians in front of the camera whose depth is below the
/// clearance, so the near plane goes to the largest depth below it: the renderer culls
/// `!(depth > near_plane)`, which is then `depth < clearance` (NaN culled too), on the depths
/// `near_floaters` reads (`raster::camera_depths`). The render is bit for bit that of the twin
/// without its floaters (`without_near_floaters`, the plain reference), keeps the twin's
/// indices and copies nothing: the copy cost a clone of the whole twin per view.
pub fn leaving_out_near_floaters(
    twin: &Splats,
    camera: &Camera,
    settings: &RenderSettings,
) -> RenderSettings {
    let depths = camera_depths(twin, camera);
    let mut seen = *settings;
    if let Some(clearance) = floater_clearance(&depths) {
        // Below the renderer's own near plane the floaters are culled anyway.
        seen.near_plane = settings.near_plane.max(clearance.next_down());
    }
    seen
}

/// Per Gaussian, whether it is a floater in front of `camera` (see
/// `leaving_out_near_floaters`): the one definition of a near floater.
pub(crate) fn near_floaters(twin: &Splats, camera: &Camera) -> Vec<bool> {
    let depths = camera_depths(twin, camera);
    let Some(clearance) = floater_clearance(&depths) else {
        return vec![false; twin.len()];
    };
    // Behind the camera is the renderer's to cull; in front but too near is a floater.
    depths.iter().map(|&z| z > 0.0 && z < clearance).collect()
}

/// The depth below which a Gaussian in front of the camera is a floater: `NEAR_FLOATER_FRACTION`
/// of the median depth of those in front (None when none is).
fn floater_clearance(depths: &[f32]) -> Option<f32> {
    let mut in_front: Vec<f32> = depths.iter().copied().filter(|&z| z > 0.0).collect();
    if in_front.is_empty() {
        return None;
    }
    let middle = in_front.len() / 2;
    let (_, median, _) = in_front.select_nth_unstable_by(middle, f32::total_cmp);
    Some(NEAR_FLOATER_FRACTION * *median)
}

#[cfg(test)]
mod tests {
    use std::borrow::Cow;

    use super::*;
    use crate::raster::{RenderOutput, render};

    /// The twin without its near floaters in front of `camera` (`near_floaters`), as a copy: the
    /// plain reference of `leaving_out_near_floaters`, which renders the same without copying.
    fn without_near_floaters<'a>(twin: &'a Splats, camera: &Camera) -> Cow<'a, Splats> {
        let floaters = near_floaters(twin, camera);
        if !floaters.iter().any(|&f| f) {
            return Cow::Borrowed(twin);
        }
        let keep: Vec<bool> = floaters.iter().map(|&f| !f).collect();
        let mut seen = twin.clone();
        seen.retain(&keep);
        Cow::Owned(seen)
    }

    fn camera(rotation: glam::Quat, translation: glam::Vec3) -> Camera {
        let k = crate::scene::Intrinsics {
            width: 64,
            height: 48,
            fx: 60.0,
            fy: 60.0,
            cx: 32.0,
            cy: 24.0,
        };
        Camera::new(k, rotation, translation)
    }

    /// Every value of two renders, bit for bit.
    fn assert_same_bits(got: &RenderOutput, want: &RenderOutput, what: &str) {
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!((got.width, got.height), (want.width, want.height), "{what}");
        assert!(bits(&got.color) == bits(&want.color), "{what}: colour");
        assert!(bits(&got.alpha) == bits(&want.alpha), "{what}: alpha");
        assert!(bits(&got.depth) == bits(&want.depth), "{what}: depth");
        assert!(bits(&got.labels) == bits(&want.labels), "{what}: labels");
    }

    /// A Gaussian of `twin` at `mean` with its own colour and labels.
    fn push(twin: &mut Splats, mean: glam::Vec3, log_scale: f32, id: u64) {
        let t = id as f32 * 0.37;
        twin.push(
            mean,
            glam::Vec3::splat(log_scale),
            glam::Quat::from_rotation_z(t),
            1.5,
            &[t.sin(), t.cos(), 0.3 * t.sin()],
            &[t.cos(), -t.sin(), 0.5],
            id,
            0,
        );
    }

    #[test]
    fn raising_the_near_plane_renders_the_twin_without_its_floaters_bit_for_bit() {
        // From the origin looking along +z the depth is z exactly, so the edge cases sit where
        // they should: a wall of 48 Gaussians all at 10 m (the median; equal depths, so the
        // blending order of ties counts), floaters at 0.5 m and 1 m, one just below the
        // 2.5 m clearance (a floater) and one exactly at it (not a floater, and drawn), one
        // inside the renderer's own near plane and one behind the camera.
        let mut twin = Splats::empty(0, 3);
        for i in 0..48u64 {
            let (x, y) = ((i % 8) as f32 - 3.5, (i / 8) as f32 - 2.5);
            push(&mut twin, glam::Vec3::new(x, y, 10.0), -0.7, i);
        }
        let clearance = 2.5f32;
        for (id, z) in [(48, 0.5), (49, 1.0), (50, clearance.next_down())] {
            push(&mut twin, glam::Vec3::new(0.1, -0.1, z), -3.0, id);
        }
        push(&mut twin, glam::Vec3::new(-0.2, 0.1, clearance), -2.5, 51);
        push(&mut twin, glam::Vec3::new(0.0, 0.0, 0.005), -3.0, 52);
        push(&mut twin, glam::Vec3::new(0.0, 0.0, -3.0), -1.0, 53);
        let front = camera(glam::Quat::IDENTITY, glam::Vec3::ZERO);
        let floaters = near_floaters(&twin, &front);
        let ids = |flags: &[bool]| -> Vec<u64> {
            (0..twin.len())
                .filter(|&g| flags[g])
                .map(|g| twin.meta.ids[g])
                .collect()
        };
        assert_eq!(ids(&floaters), [48, 49, 50, 52], "the floaters");

        let settings = RenderSettings::new(glam::Vec3::new(0.1, 0.2, 0.3), 0);
        let seen = leaving_out_near_floaters(&twin, &front, &settings);
        let fast = render(&twin, &front, &seen);
        let plain = render(&without_near_floaters(&twin, &front), &front, &settings);
        assert_same_bits(&fast, &plain, "from the front");
        // The Gaussian at the clearance is drawn: without it the render differs.
        let mut keep = floaters.iter().map(|&f| !f).collect::<Vec<_>>();
        keep[51] = false;
        let mut without_edge = twin.clone();
        without_edge.retain(&keep);
        let edge = render(&without_edge, &front, &settings);
        assert!(
            edge.color != plain.color,
            "the Gaussian at the clearance draws"
        );

        // Turned and moved cameras over a random twin: depths are no longer exact, and the
        // near plane still culls what `near_floaters` calls a floater.
        let mut rng = fastrand::Rng::with_seed(7);
        let mut u = |lo: f32, hi: f32| lo + (hi - lo) * rng.f32();
        let mut cloud = Splats::empty(0, 3);
        for id in 0..400u64 {
            let z = if id % 10 == 0 {
                u(0.2, 2.0)
            } else {
                u(6.0, 14.0)
            };
            let mean = glam::Vec3::new(u(-4.0, 4.0), u(-3.0, 3.0), z);
            push(&mut cloud, mean, u(-3.5, -1.0), id);
        }
        for turn in 0..6 {
            let a = turn as f32 * 0.05;
            let camera = camera(
                glam::Quat::from_euler(glam::EulerRot::XYZ, a, -0.7 * a, 0.3 * a),
                glam::Vec3::new(0.1 * a, -0.2 * a, 0.3 * a),
            );
            assert!(near_floaters(&cloud, &camera).iter().any(|&f| f));
            let fast = render(
                &cloud,
                &camera,
                &leaving_out_near_floaters(&cloud, &camera, &settings),
            );
            let plain = render(&without_near_floaters(&cloud, &camera), &camera, &settings);
            assert_same_bits(&fast, &plain, &format!("turn {turn}"));
        }
    }

    #[test]
    fn a_floater_in_front_of_a_new_camera_is_left_out() {
        let k = crate::scene::Intrinsics {
            width: 32,
            height: 32,
            fx: 30.0,
            fy: 30.0,
            cx: 16.0,
            cy: 16.0,
        };
        let camera = Camera::new(k, glam::Quat::IDENTITY, glam::Vec3::ZERO);
        let mut twin = Splats::empty(0, 0);
        // A wall of nine Gaussians 10 m ahead, one floater 0.2 m ahead, one behind the camera.
        let mut push = |z: f32, x: f32, id: u64| {
            twin.push(
                glam::Vec3::new(x, 0.0, z),
                glam::Vec3::splat(-1.0),
                glam::Quat::IDENTITY,
                2.0,
                &[0.5; 3],
                &[],
                id,
                0,
            )
        };
        for i in 0..9 {
            push(10.0, i as f32 - 4.0, i);
        }
        push(0.2, 0.0, 9);
        push(-3.0, 0.0, 10);
        let seen = without_near_floaters(&twin, &camera);
        assert_eq!(seen.len(), 10);
        assert!(!seen.meta.ids.contains(&9), "the floater is left out");
        assert!(
            seen.meta.ids.contains(&10),
            "behind the camera is the renderer's to cull"
        );
        assert_eq!(twin.len(), 11, "the twin itself is untouched");
    }
}
