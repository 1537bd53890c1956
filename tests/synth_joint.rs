//! `synth --survey2-frame joint`: survey 2 is one COLMAP model of the old and new images in a
//! random similarity frame. Mapped back through the recorded similarity, the old cameras are
//! survey 1's and the new ones survey 2's within the stated pose noise; known 3D damage points
//! land in the new images' masks; survey 1's files are copied byte for byte.

use std::path::Path;

use damage_twin::damage::DamageClass;
use damage_twin::scene::Camera;
use damage_twin::scene::colmap::{ColmapModel, read_text};
use damage_twin::synth::geometry::Ray;
use damage_twin::synth::joint::{JointFrame, Similarity, new_view_name};
use damage_twin::synth::{self, Survey2Frame, SynthParams, World, view_name};
use glam::{DQuat, DVec3, Vec3};

fn params(out: &Path, frame: Survey2Frame) -> SynthParams {
    SynthParams {
        width: 320,
        height: 180,
        views: 5,
        views_survey2: 7,
        sparse_points: 1500,
        mask_noise: 0.4,
        survey2_frame: frame,
        ..SynthParams::demo(out)
    }
}

fn pose(model: &ColmapModel, name: &str) -> (DQuat, DVec3) {
    let im = model
        .images
        .iter()
        .find(|im| im.name == name)
        .unwrap_or_else(|| panic!("{name}"));
    let [w, x, y, z] = im.qvec;
    (
        DQuat::from_xyzw(x, y, z, w).normalize(),
        DVec3::from_array(im.tvec),
    )
}

fn centre(q: DQuat, t: DVec3) -> DVec3 {
    -(q.inverse() * t)
}

fn read(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn grey(path: &Path) -> image::GrayImage {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_luma8()
}

#[test]
fn joint_model_maps_back_to_both_surveys_within_the_pose_noise() {
    let dir = tempfile::tempdir().unwrap();
    let same = tempfile::tempdir().unwrap();
    let p = params(dir.path(), Survey2Frame::Joint);
    synth::generate(&p, &|_, _| {}).expect("joint synth runs");
    synth::generate(&params(same.path(), Survey2Frame::Same), &|_, _| {}).expect("synth runs");
    let s1 = dir.path().join("survey-1");
    let s2 = dir.path().join("survey-2");

    let frame: JointFrame =
        serde_json::from_str(&std::fs::read_to_string(s2.join("truth/joint_frame.json")).unwrap())
            .expect("joint_frame.json parses");
    let sim: Similarity = frame.similarity();
    eprintln!(
        "similarity: scale {}, rotation {:?}, translation {:?}",
        sim.scale, sim.rotation, sim.translation
    );
    assert!(sim.scale >= 0.3 && sim.scale <= 3.0);
    assert!(sim.translation.length() > 10.0 * sim.scale.min(1.0));
    let old: Vec<String> = (0..p.views).map(view_name).collect();
    let new: Vec<String> = (0..p.views_survey2).map(new_view_name).collect();
    assert_eq!((&frame.old_images, &frame.new_images), (&old, &new));

    // Survey 1 is written as in the same-frame run, and its images and masks are copied.
    for name in &old {
        assert!(
            read(&s1.join("images").join(name))
                == read(&same.path().join("survey-1/images").join(name))
        );
        assert!(read(&s2.join("images").join(name)) == read(&s1.join("images").join(name)));
        for class in DamageClass::ALL {
            let mask = Path::new("masks").join(class.id()).join(name);
            assert!(
                read(&s2.join(&mask)) == read(&s1.join(&mask)),
                "{}",
                mask.display()
            );
        }
        assert!(
            !s2.join("truth/masks/crack").join(name).exists(),
            "truth/ is the new images'"
        );
    }
    // The new images are survey 2's renders under new names.
    for (i, name) in new.iter().enumerate() {
        let before = same.path().join("survey-2/images").join(view_name(i));
        assert!(
            read(&s2.join("images").join(name)) == read(&before),
            "{name}"
        );
        assert!(s2.join("truth/new-damage/spalling").join(name).exists());
    }

    // Cameras: joint → twin frame through the inverse similarity, against the written survey 1
    // model and survey 2's true path.
    let joint = read_text(&s2.join("sparse/0")).expect("joint model reads");
    let model1 = read_text(&s1.join("sparse/0")).expect("survey 1 model reads");
    assert_eq!(joint.images.len(), p.views + p.views_survey2);
    let world = World::new(&p);
    let truth2 = world.cameras(&p, 2);
    let mut truths: Vec<(String, DQuat, DVec3)> = old
        .iter()
        .map(|n| {
            let (q, t) = pose(&model1, n);
            (n.clone(), q, t)
        })
        .collect();
    for (name, cam) in new.iter().zip(&truth2) {
        truths.push((
            name.clone(),
            cam.rotation.as_dquat(),
            cam.translation.as_dvec3(),
        ));
    }
    let (mut sum_angle, mut sum_shift, mut max_angle, mut max_shift) = (0.0, 0.0, 0.0f64, 0.0f64);
    for (name, q_true, t_true) in &truths {
        let (qj, tj) = pose(&joint, name);
        let (q, t) = sim.inverse_pose(qj, tj);
        let angle = q.angle_between(*q_true).to_degrees();
        let shift = (centre(q, t) - centre(*q_true, *t_true)).length();
        sum_angle += angle * angle;
        sum_shift += shift * shift;
        max_angle = max_angle.max(angle);
        max_shift = max_shift.max(shift);
    }
    let n = truths.len() as f64;
    let (rms_angle, rms_shift) = ((sum_angle / n).sqrt(), (sum_shift / n).sqrt());
    let noise = &frame.pose_noise;
    eprintln!(
        "pose error over {n} images: rotation rms {rms_angle:.4}° max {max_angle:.4}°, centre rms {:.2} mm max {:.2} mm (stated {}°, {} m rms)",
        1e3 * rms_shift,
        1e3 * max_shift,
        noise.rotation_rms_degrees,
        noise.translation_rms_m
    );
    // Six per-axis sigmas bound a 3D Gaussian's norm (chi with 3 degrees of freedom) except
    // with probability ~1e-7; the rms of 12 draws lies within ±50 % of the stated rms except
    // with probability ~1e-3 (and the draws are seeded, so the test is repeatable).
    assert!(max_angle < 6.0 * noise.rotation_sigma_degrees_per_axis);
    assert!(max_shift < 6.0 * noise.translation_sigma_m_per_axis);
    assert!(
        rms_angle > 0.5 * noise.rotation_rms_degrees
            && rms_angle < 1.5 * noise.rotation_rms_degrees
    );
    assert!(rms_shift > 0.5 * noise.translation_rms_m && rms_shift < 1.5 * noise.translation_rms_m);

    // Sparse points: survey 1's, mapped through the similarity only.
    for (a, b) in model1.points.iter().zip(&joint.points) {
        let back = sim.inverse_apply(DVec3::from_array(b.xyz));
        assert!(
            (back - DVec3::from_array(a.xyz)).length() < 1e-4,
            "point {}",
            a.id
        );
        assert_eq!(a.track, b.track);
    }
    assert!(joint.points.len() > model1.points.len());

    // Masks of the new images: survey 2's damage points, mapped into the joint frame and
    // projected with the joint cameras, land in the class's mask.
    let k = world.cameras(&p, 2)[0].intrinsics;
    let points = world.damage_points(2, 0.02, false);
    let new_points = world.damage_points(2, 0.01, true);
    let (mut checked, mut missed, mut missed_exact, mut seeing) = (0usize, 0usize, 0usize, 0usize);
    for (i, name) in new.iter().enumerate() {
        let (qj, tj) = pose(&joint, name);
        let cam_joint = Camera::new(k, qj.as_quat(), tj.as_vec3());
        let eye = truth2[i].position();
        let visible = |x: Vec3| {
            let dist = (x - eye).length();
            let hit = world
                .geometry
                .intersect(&Ray::new(eye, (x - eye) / dist), 1e4)?;
            if !((hit.t - dist).abs() < 2e-3) {
                return None;
            }
            let inside = |px: glam::Vec2| {
                (px.x >= 1.0
                    && px.y >= 1.0
                    && px.x < k.width as f32 - 1.0
                    && px.y < k.height as f32 - 1.0)
                    .then_some((px.x as u32, px.y as u32))
            };
            let px = inside(cam_joint.project(sim.apply(x.as_dvec3()).as_vec3())?)?;
            // Where the exact (noise-free) camera puts it, for the misses the masks alone make.
            let exact = inside(truth2[i].project(x)?)?;
            Some((px, exact))
        };
        let masks: Vec<_> = DamageClass::ALL
            .iter()
            .map(|c| grey(&s2.join("truth/masks").join(c.id()).join(name)))
            .collect();
        for dp in &points {
            let Some((px, exact)) = visible(dp.position) else {
                continue;
            };
            checked += 1;
            let found = |(x, y): (u32, u32)| {
                let hit = |m: &image::GrayImage| {
                    (y - 1..=y + 1)
                        .any(|yy| (x - 1..=x + 1).any(|xx| m.get_pixel(xx, yy)[0] == 255))
                };
                // Rebar wins over spalling at coarse resolution (as in synth_truth).
                hit(&masks[dp.class.channel()])
                    || (dp.class == DamageClass::Spalling && hit(&masks[2]))
            };
            missed += !found(px) as usize;
            missed_exact += !found(exact) as usize;
        }
        let seen = new_points
            .iter()
            .filter(|dp| visible(dp.position).is_some())
            .count();
        let pixels: usize = DamageClass::ALL
            .iter()
            .map(|c| {
                grey(&s2.join("truth/new-damage").join(c.id()).join(name))
                    .pixels()
                    .filter(|p| p[0] == 255)
                    .count()
            })
            .sum();
        assert_eq!(
            seen > 0,
            pixels > 0,
            "{name}: {seen} new-damage points visible, {pixels} pixels"
        );
        seeing += (seen > 0) as usize;
    }
    eprintln!(
        "{checked} visible damage points in the new images, {missed} missed through the joint \
         cameras, {missed_exact} through the exact ones; {seeing} views see new damage"
    );
    // Measured: 1.5 % missed through either camera (points on outline borders, where the exact
    // classification and the pixel's differ; survey 2 flies farther out than survey 1, so more
    // points are border points than in synth_truth). The pose noise (about half a pixel at
    // 320 px) must not add more than 0.2 % of the points to that.
    assert!(checked > 10_000, "{checked}");
    assert!(missed * 50 <= checked, "{missed} of {checked} missed");
    assert!(
        missed * 1000 <= missed_exact * 1000 + 2 * checked,
        "{missed} vs {missed_exact}"
    );
    assert!(seeing > 0);
}
