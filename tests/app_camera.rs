//! The viewer's navigation maths, without a window: frame-rate independence, orbit / pan / zoom /
//! fly behaviour, snapping to survey cameras, the adaptive resolution and frustum picking.
#![cfg(feature = "app")]

use damage_twin::app::camera_controller::{
    CameraController, CameraInput, NavMode, OrbitPose, estimate_up,
};
use damage_twin::app::overlay::{self, Segment, SegmentKind};
use damage_twin::app::resolution::{AdaptiveResolution, FrameSample, scaled_size};
use damage_twin::scene::{Camera, Intrinsics};
use glam::{Vec2, Vec3};

fn controller() -> CameraController {
    CameraController::new(
        Vec3::Z,
        OrbitPose {
            target: Vec3::new(1.0, -2.0, 0.5),
            distance: 10.0,
            yaw: 0.3,
            pitch: 0.2,
        },
    )
}

fn idle(dt: f32) -> CameraInput {
    CameraInput {
        dt,
        viewport_height: 600.0,
        ..CameraInput::default()
    }
}

#[test]
fn easing_is_frame_rate_independent() {
    // One zoom impulse, then 0.1 s of easing in 1 frame or in 10 frames: exp(-r·t) either way.
    let zoom = CameraInput {
        zoom: 200.0,
        ..idle(0.1)
    };
    let mut one = controller();
    one.update(&zoom);
    let mut ten = controller();
    ten.update(&CameraInput { dt: 0.01, ..zoom });
    for _ in 0..9 {
        ten.update(&idle(0.01));
    }
    let (a, b) = (one.pose(), ten.pose());
    assert!(
        (a.distance - b.distance).abs() < 1e-4,
        "{} vs {}",
        a.distance,
        b.distance
    );
    assert_eq!(one.goal(), ten.goal());
    assert!(
        a.distance < 10.0 && a.distance > one.goal().distance,
        "still easing"
    );
}

#[test]
fn flying_covers_the_same_distance_at_any_frame_rate() {
    let mut coarse = controller();
    let mut fine = controller();
    let forward = CameraInput {
        fly: Vec3::new(0.0, 0.0, 1.0),
        ..idle(0.1)
    };
    for _ in 0..10 {
        coarse.update(&forward);
    }
    for _ in 0..100 {
        fine.update(&CameraInput {
            dt: 0.01,
            ..forward
        });
    }
    // Let both settle, then compare where they ended up.
    for _ in 0..200 {
        coarse.update(&idle(0.02));
        fine.update(&idle(0.02));
    }
    let moved = (coarse.eye() - controller().eye()).length();
    assert!(
        (moved - coarse.fly_speed).abs() < 1e-3 * moved,
        "1 s at fly_speed: {moved}"
    );
    assert!(
        (coarse.eye() - fine.eye()).length() < 1e-3,
        "{} vs {}",
        coarse.eye(),
        fine.eye()
    );
}

#[test]
fn orbit_keeps_target_and_distance() {
    let mut c = controller();
    let target = c.pose().target;
    c.update(&CameraInput {
        rotate: Vec2::new(120.0, -40.0),
        ..idle(0.016)
    });
    for _ in 0..300 {
        c.update(&idle(0.016));
    }
    assert!((c.pose().target - target).length() < 1e-5);
    assert!(((c.eye() - target).length() - 10.0).abs() < 1e-3);
    assert!(!c.is_moving());
}

#[test]
fn pan_moves_the_target_with_the_cursor() {
    // At the target's depth, a pan of (dx, dy) points moves the old target by exactly that many
    // pixels on a camera whose pixel height equals the viewport's point height.
    let mut c = controller();
    let before = c.pose().target;
    c.update(&CameraInput {
        pan: Vec2::new(30.0, -20.0),
        ..idle(0.016)
    });
    for _ in 0..400 {
        c.update(&idle(0.016));
    }
    let cam = c.camera(800, 600);
    let px = cam.project(before).expect("old target in front");
    let moved = px - Vec2::new(400.0, 300.0);
    assert!((moved - Vec2::new(30.0, -20.0)).length() < 0.05, "{moved}");
}

#[test]
fn zoom_never_reaches_the_target_and_ignores_nan() {
    let mut c = controller();
    for _ in 0..1000 {
        c.update(&CameraInput {
            zoom: 5000.0,
            ..idle(0.016)
        });
    }
    assert!(c.goal().distance > 0.0);
    c.update(&CameraInput {
        zoom: f32::NAN,
        dt: f32::NAN,
        ..idle(0.016)
    });
    let cam = c.camera(64, 48);
    assert!(cam.translation.is_finite() && cam.rotation.is_finite());
}

#[test]
fn pitch_stops_short_of_the_pole() {
    let mut c = controller();
    c.update(&CameraInput {
        rotate: Vec2::new(0.0, 1e6),
        ..idle(0.016)
    });
    assert!(c.goal().pitch < std::f32::consts::FRAC_PI_2);
    for _ in 0..300 {
        c.update(&idle(0.016));
    }
    let cam = c.camera(64, 48);
    assert!(
        cam.rotation.is_finite(),
        "look_at stays defined near the pole"
    );
}

#[test]
fn fly_mode_looks_around_from_a_fixed_eye() {
    let mut c = controller();
    c.mode = NavMode::Fly;
    let eye = c.eye();
    c.update(&CameraInput {
        rotate: Vec2::new(50.0, 25.0),
        ..idle(0.016)
    });
    for _ in 0..400 {
        c.update(&idle(0.016));
    }
    assert!((c.eye() - eye).length() < 1e-3, "{} vs {eye}", c.eye());
    assert!((c.pose().target - controller().pose().target).length() > 0.1);
}

#[test]
fn snapping_to_a_survey_camera_takes_its_eye_and_direction() {
    let k = Intrinsics {
        width: 640,
        height: 480,
        fx: 500.0,
        fy: 500.0,
        cx: 320.0,
        cy: 240.0,
    };
    let survey = Camera::look_at(
        k,
        Vec3::new(8.0, 3.0, 4.0),
        Vec3::new(0.0, 0.0, 1.0),
        Vec3::Z,
    );
    let mut c = controller();
    c.snap_to(&survey);
    assert!((c.eye() - survey.position()).length() < 1e-3);
    let cam = c.camera(640, 480);
    let px = cam
        .project(Vec3::new(0.0, 0.0, 1.0))
        .expect("looked-at point in front");
    assert!((px - Vec2::new(320.0, 240.0)).length() < 0.5, "{px}");
}

#[test]
fn world_up_is_estimated_from_level_cameras() {
    let k = Intrinsics {
        width: 64,
        height: 48,
        fx: 50.0,
        fy: 50.0,
        cx: 32.0,
        cy: 24.0,
    };
    let cams: Vec<Camera> = (0..8)
        .map(|i| {
            let a = i as f32 * 0.8;
            Camera::look_at(
                k,
                Vec3::new(5.0 * a.cos(), 5.0 * a.sin(), 2.0),
                Vec3::ZERO,
                Vec3::Z,
            )
        })
        .collect();
    assert!((estimate_up(&cams) - Vec3::Z).length() < 0.3);
    assert_eq!(estimate_up(&[]), Vec3::Z);
}

/// A frame that rendered splats (`rendered`) or only redrew the panels.
fn frame(changing: bool, frame_ms: f32, rendered: bool) -> FrameSample {
    FrameSample {
        changing,
        frame_ms,
        last_frame_rendered: rendered,
    }
}

#[test]
fn resolution_drops_while_moving_slowly_and_recovers_at_rest() {
    let mut r = AdaptiveResolution::default();
    for _ in 0..30 {
        r.update(frame(true, 160.0, true), 40.0, 0.25);
    }
    assert!(
        (r.scale() - 0.25).abs() < 1e-6,
        "four times too slow hits the floor: {}",
        r.scale()
    );
    for _ in 0..30 {
        r.update(frame(true, 20.0, true), 40.0, 0.25);
    }
    assert!(r.scale() > 0.9, "fast frames raise it again: {}", r.scale());
    r.update(frame(true, 160.0, true), 40.0, 0.25);
    assert!(!r.settling(), "still changing");
    r.update(frame(false, 10.0, false), 40.0, 0.25);
    assert!(r.settling(), "at rest below full resolution");
    for _ in 0..5 {
        r.update(frame(false, 100.0, false), 40.0, 0.25);
    }
    assert_eq!(r.scale(), 1.0);
    assert!(!r.settling());
    assert_eq!(scaled_size(1000, 500, 0.25), (250, 125));
    assert_eq!(scaled_size(3, 3, 0.0001), (1, 1));
}

#[test]
fn resolution_ignores_frames_that_did_not_render() {
    // Training with a resting camera: a slow render every few frames, fast panel-only frames
    // in between. Only the renders count, so the scale comes down and stays down.
    let mut r = AdaptiveResolution::default();
    for _ in 0..10 {
        r.update(frame(true, 1000.0, true), 40.0, 0.25);
        for _ in 0..5 {
            r.update(frame(true, 15.0, false), 40.0, 0.25);
        }
    }
    assert!(
        (r.scale() - 0.25).abs() < 1e-6,
        "panel-only frames must not raise it: {}",
        r.scale()
    );
    assert!(
        r.frame_ms() > 500.0,
        "smoothed render time {}",
        r.frame_ms()
    );
    // One full-resolution render twenty-five times over budget halves the scale at once.
    let mut r = AdaptiveResolution::default();
    r.update(frame(true, 1000.0, true), 40.0, 0.1);
    assert!((r.scale() - 0.5).abs() < 1e-6, "{}", r.scale());
}

#[test]
fn clicking_inside_a_frustum_picks_that_camera() {
    let k = Intrinsics {
        width: 400,
        height: 300,
        fx: 300.0,
        fy: 300.0,
        cx: 200.0,
        cy: 150.0,
    };
    let a = Camera::look_at(
        k,
        Vec3::new(-2.0, -6.0, 1.0),
        Vec3::new(-2.0, 0.0, 1.0),
        Vec3::Z,
    );
    let b = Camera::look_at(
        k,
        Vec3::new(2.0, -6.0, 1.0),
        Vec3::new(2.0, 0.0, 1.0),
        Vec3::Z,
    );
    let view = Camera::look_at(
        k,
        Vec3::new(0.0, -16.0, 1.0),
        Vec3::new(0.0, 0.0, 1.0),
        Vec3::Z,
    );
    let cams = [a, b];
    // Click on the centre of b's image rectangle at depth 0.5.
    let corners = overlay::frustum_corners(&b, 0.5);
    let centre = corners.iter().copied().sum::<Vec3>() / 4.0;
    let click = view.project(centre).unwrap();
    assert_eq!(
        overlay::pick_frustum(&view, &cams, 0.5, 0.01, click, 4.0),
        Some(1)
    );
    assert_eq!(
        overlay::pick_frustum(&view, &cams, 0.5, 0.01, Vec2::new(5.0, 5.0), 4.0),
        None
    );
}

#[test]
fn segments_behind_the_camera_are_clipped() {
    let k = Intrinsics {
        width: 100,
        height: 100,
        fx: 100.0,
        fy: 100.0,
        cx: 50.0,
        cy: 50.0,
    };
    let view = Camera::look_at(k, Vec3::ZERO, Vec3::new(0.0, 1.0, 0.0), Vec3::Z);
    let behind = Segment {
        a: Vec3::new(0.0, -1.0, 0.0),
        b: Vec3::new(0.0, -2.0, 0.0),
        kind: SegmentKind::Grid,
    };
    assert!(overlay::project_segment(&view, &behind, 0.01).is_none());
    let crossing = Segment {
        a: Vec3::new(0.1, -1.0, 0.0),
        b: Vec3::new(0.1, 1.0, 0.0),
        kind: SegmentKind::Grid,
    };
    let (p, q) = overlay::project_segment(&view, &crossing, 0.01).expect("half in front");
    assert!(p.is_finite() && q.is_finite());
}
