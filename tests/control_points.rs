//! Control points on the demo building's known geometry: surveyed points in a site frame of
//! their own (rotated, shifted), marked in the survey's photos to ±0.1 px (a careful
//! operator's sub-pixel marking), recover the
//! frame within 1 cm on the check points the fit did not use; bad control points are refused
//! with one line naming the problem.

use std::fmt::Write as _;
use std::path::Path;
use std::sync::OnceLock;

use damage_twin::scene::colmap::{ColmapModel, read_text};
use damage_twin::scene::sfm::control::fit_control_points;
use damage_twin::scene::similarity::Similarity;
use damage_twin::synth::SynthParams;
use glam::{DQuat, DVec3};

/// Survey 1 of the demo building (12 views, 640×360) and its known model, made once.
fn survey() -> &'static (tempfile::TempDir, ColmapModel) {
    static DATA: OnceLock<(tempfile::TempDir, ColmapModel)> = OnceLock::new();
    DATA.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let params = SynthParams {
            width: 640,
            height: 360,
            views: 12,
            surveys: 1,
            sparse_points: 400,
            ..SynthParams::demo(dir.path())
        };
        damage_twin::synth::generate::generate(&params, &|_, _| {}).expect("synth");
        let model = read_text(&dir.path().join("survey-1/sparse/0")).unwrap();
        (dir, model)
    })
}

/// The site frame: x_site = R · x_world + t (metres both).
fn site() -> Similarity {
    Similarity {
        scale: 1.0,
        rotation: DQuat::from_rotation_z(0.7).to_array(),
        translation: [512.0, -1300.0, 42.0],
    }
}

/// A CSV of `count` building points (the known sparse points), each with its site position and
/// its pixels in every photo that has it in frame (noise of `noise_px`); the last `checks` are
/// check points.
fn control_csv(model: &ColmapModel, count: usize, checks: usize, noise_px: f64) -> String {
    let mut rng = fastrand::Rng::with_seed(11);
    let mut csv = String::from("name,x,y,z,image,pixel_x,pixel_y,check\n");
    let cameras: Vec<_> = model
        .images
        .iter()
        .map(|i| {
            let cam = model.cameras.iter().find(|c| c.id == i.camera_id).unwrap();
            let (k, _) = cam.to_pinhole(Path::new("cameras.txt")).unwrap();
            let (q, t) = i.pose().unwrap();
            (i.name.clone(), k, q.as_dquat(), t.as_dvec3())
        })
        .collect();
    let mut written = 0;
    for point in model.points.iter().step_by(7) {
        if written == count {
            break;
        }
        let x = DVec3::from_array(point.xyz);
        let mut rows = Vec::new();
        for (name, k, q, t) in &cameras {
            let c = *q * x + *t;
            if c.z <= 0.1 {
                continue;
            }
            let u =
                f64::from(k.fx) * c.x / c.z + f64::from(k.cx) + (rng.f64() - 0.5) * 2.0 * noise_px;
            let v =
                f64::from(k.fy) * c.y / c.z + f64::from(k.cy) + (rng.f64() - 0.5) * 2.0 * noise_px;
            if (0.0..f64::from(k.width)).contains(&u) && (0.0..f64::from(k.height)).contains(&v) {
                rows.push((name.clone(), u, v));
            }
        }
        if rows.len() < 3 {
            continue;
        }
        let s = site().apply(x);
        let check = if written >= count - checks { "1" } else { "" };
        for (name, u, v) in rows {
            writeln!(
                csv,
                "P{written},{:.4},{:.4},{:.4},{name},{u:.3},{v:.3},{check}",
                s.x, s.y, s.z
            )
            .unwrap();
        }
        written += 1;
    }
    assert_eq!(written, count, "not enough visible points");
    csv
}

#[test]
fn the_known_frame_is_recovered_within_a_centimetre_on_check_points() {
    let (dir, model) = survey();
    let csv = dir.path().join("control.csv");
    std::fs::write(&csv, control_csv(model, 8, 3, 0.1)).unwrap();
    let fit = fit_control_points(model, Path::new("sparse/0"), &csv).unwrap();
    let check_rms = fit.check_rms_m.expect("check points");
    eprintln!(
        "control points: fit RMS {:.4} m on {} points, check RMS {check_rms:.4} m on 3, scale {:.6}",
        fit.georeference.rms_m,
        fit.georeference.used.len(),
        fit.georeference.similarity.scale
    );
    assert_eq!(fit.georeference.used.len(), 5);
    assert_eq!(fit.points.iter().filter(|p| p.check).count(), 3);
    for point in fit.points.iter().filter(|p| p.check) {
        assert!(point.residual_m < 0.01, "{point:?}");
    }
    assert!((fit.georeference.similarity.scale - 1.0).abs() < 1e-3);
    // A model point maps into the site frame as the known transform says.
    let probe = DVec3::new(1.0, 2.0, 3.0);
    assert!(
        fit.georeference
            .to_local(probe)
            .distance(site().apply(probe))
            < 0.01
    );
}

fn refusal(csv_text: &str) -> String {
    let (dir, model) = survey();
    let csv = dir.path().join(format!("bad-{}.csv", fastrand::u32(..)));
    std::fs::write(&csv, csv_text).unwrap();
    let err = fit_control_points(model, Path::new("sparse/0"), &csv)
        .unwrap_err()
        .to_string();
    assert_eq!(err.lines().count(), 1, "{err}");
    err
}

#[test]
fn bad_control_points_are_refused_with_a_clear_line() {
    let (_, model) = survey();
    let good = control_csv(model, 4, 0, 0.0);
    // A wrong image name.
    let wrong_image = good.replacen(&model.images[0].name, "DJI_0001.JPG", 1);
    let wrong_image = if wrong_image == good {
        good.replacen(&model.images[1].name, "DJI_0001.JPG", 1)
    } else {
        wrong_image
    };
    let err = refusal(&wrong_image);
    assert!(
        err.contains("DJI_0001.JPG") && err.contains("not a registered photo"),
        "{err}"
    );
    // Fewer than 3 points for the fit.
    let two: String = good
        .lines()
        .filter(|l| !l.starts_with("P2,") && !l.starts_with("P3,"))
        .map(|l| format!("{l}\n"))
        .collect();
    let err = refusal(&two);
    assert!(
        err.contains("2 control point(s)") && err.contains("at least 3"),
        "{err}"
    );
    // A point behind two neighbouring cameras: its pixels are where the projection puts it,
    // but the rays meet behind them.
    let posed: Vec<_> = model
        .images
        .iter()
        .take(2)
        .map(|i| {
            let (q, t) = i.pose().unwrap();
            (i.name.clone(), q.as_dquat(), t.as_dvec3())
        })
        .collect();
    let centre = |q: DQuat, t: DVec3| -(q.inverse() * t);
    let ahead = |q: DQuat| q.inverse() * DVec3::Z;
    let mid = (centre(posed[0].1, posed[0].2) + centre(posed[1].1, posed[1].2)) / 2.0;
    let back = mid - (ahead(posed[0].1) + ahead(posed[1].1)).normalize() * 8.0;
    let cam = &model.cameras[0];
    let (f, cx, cy) = (cam.params[0], cam.params[2], cam.params[3]);
    let mut behind: String = good
        .lines()
        .filter(|l| !l.starts_with("P1,"))
        .map(|l| format!("{l}\n"))
        .collect();
    for (name, q, t) in &posed {
        let c = *q * back + *t;
        assert!(c.z < 0.0);
        let (u, v) = (f * c.x / c.z + cx, f * c.y / c.z + cy);
        writeln!(behind, "P1,1,2,3,{name},{u:.3},{v:.3},").unwrap();
    }
    let err = refusal(&behind);
    assert!(
        err.contains("P1") && err.contains("behind the camera"),
        "{err}"
    );
    // A header that is neither frame.
    let err = refusal("name,east,north,up,image,pixel_x,pixel_y\n");
    assert!(
        err.contains("line 1") && err.contains("expected the header"),
        "{err}"
    );
}
