//! The workbench's pointing tools through the whole app with synthetic events (egui_kittest,
//! software wgpu): C picks the Gaussian drawing the clicked pixel, I selects its colour, O and X
//! a sphere and a box around the surface point clicked, the front-most toggle leaves a hidden
//! layer out of a rectangle that straight-through selection takes, M measures between two
//! surface points, and F frames the selection.
#![cfg(feature = "app")]

use std::sync::Arc;

use damage_twin::app::commands::Command;
use damage_twin::app::settings::{Settings, ViewportRenderer};
use damage_twin::app::{Launch, TwinApp};
use damage_twin::scene::Camera;
use damage_twin::splats::Splats;
use damage_twin::splats::model::SH_C0;
use damage_twin::splats::model::state::SELECTED;
use egui::{Key, Modifiers, Pos2, pos2};
use egui_kittest::Harness;
use glam::{Quat, Vec3};

/// A layer of 21 × 21 Gaussians `spacing` apart in the plane through `origin` spanned by `u`
/// and `v`; grey below the middle row, red from it up (`v` > 0).
#[allow(clippy::too_many_arguments)]
fn layer(
    s: &mut Splats,
    origin: Vec3,
    u: Vec3,
    v: Vec3,
    spacing: f32,
    log_scale: f32,
    id: &mut u64,
) {
    for i in -10..=10 {
        for j in -10..=10 {
            s.means
                .push(origin + u * (i as f32 * spacing) + v * (j as f32 * spacing));
            s.log_scales.push(Vec3::splat(log_scale));
            s.rotations.push(Quat::IDENTITY);
            s.raw_opacities.push(6.0);
            let rgb: [f32; 3] = if j > 0 {
                [1.0, 0.0, 0.0]
            } else {
                [0.5, 0.5, 0.5]
            };
            s.sh.extend(rgb.map(|c| (c - 0.5) / SH_C0));
            s.meta.push(*id, 0);
            *id += 1;
        }
    }
}

fn harness(settings: Settings) -> Harness<'static, TwinApp> {
    let mut harness = Harness::builder()
        .with_size(egui::vec2(800.0, 560.0))
        .with_accessibility_check(false)
        .wgpu_setup(damage_twin::app::wgpu_setup())
        .build_eframe(move |cc| {
            let mut app = TwinApp::new(cc, Launch::Empty);
            app.state.interactive = false;
            app.state.apply(Command::UpdateSettings(Box::new(settings)));
            app
        });
    harness.run_steps(2);
    settle(&mut harness);
    harness
}

/// Runs frames until the camera's easing has come to rest (the tests project with it).
fn settle(h: &mut Harness<'_, TwinApp>) {
    for _ in 0..600 {
        if !h.state().state.camera.is_moving() {
            return;
        }
        h.run_steps(1);
    }
    panic!("the camera kept moving");
}

fn settings(front_most: bool) -> Settings {
    Settings {
        show_charts: false,
        viewport_renderer: ViewportRenderer::Cpu,
        selection_front_most: front_most,
        volume_radius: 0.1,
        ..Settings::default()
    }
}

/// The viewer's camera at the viewport's size, and its right, up and forward in the world.
fn camera(h: &Harness<'_, TwinApp>) -> (Camera, Vec3, Vec3, Vec3) {
    let rect = h.state().viewport.last_rect();
    let camera = h
        .state()
        .state
        .view_camera(rect.width() as u32, rect.height() as u32);
    let to_world = camera.rotation.inverse();
    (
        camera,
        to_world * Vec3::X,
        -(to_world * Vec3::Y),
        to_world * Vec3::Z,
    )
}

/// A wall of Gaussians of size `sigma` facing the camera through the origin (red above the
/// middle row), and, when `behind`, a second one 0.3 behind it.
fn show_walls(h: &mut Harness<'_, TwinApp>, behind: bool, sigma: f32) -> Splats {
    let (_, right, up, forward) = camera(h);
    let mut s = Splats::empty(0, 0);
    let mut id = 0;
    layer(&mut s, Vec3::ZERO, right, up, 0.04, sigma.ln(), &mut id);
    if behind {
        layer(&mut s, forward * 0.3, right, up, 0.04, sigma.ln(), &mut id);
    }
    h.state_mut().state.set_splats(Arc::new(s.clone()));
    h.run_steps(2);
    settle(h);
    s
}

fn selected(h: &Harness<'_, TwinApp>) -> Vec<usize> {
    let s = h.state().state.splats.as_ref().unwrap();
    (0..s.len())
        .filter(|&g| s.meta.state[g] & SELECTED != 0)
        .collect()
}

fn click(h: &mut Harness<'_, TwinApp>, at: Pos2) {
    h.hover_at(at);
    h.run_steps(1);
    for pressed in [true, false] {
        h.event(egui::Event::PointerButton {
            pos: at,
            button: egui::PointerButton::Primary,
            pressed,
            modifiers: Modifiers::NONE,
        });
        h.run_steps(1);
    }
    h.hover_at(pos2(5.0, 5.0));
    h.run_steps(2);
}

fn centre(h: &Harness<'_, TwinApp>) -> Pos2 {
    h.state().viewport.last_rect().center()
}

#[test]
fn click_eyedropper_sphere_and_box_select_what_they_point_at() {
    let mut h = harness(settings(false));
    // σ of 1.2 cm at 4 cm spacing: the Gaussian under the pointer draws most of its pixel.
    let model = show_walls(&mut h, false, 0.012);
    let c = centre(&h);
    let (camera, ..) = camera(&h);
    let origin = h.state().viewport.last_rect().min;

    h.key_press(Key::C);
    h.run_steps(1);
    click(&mut h, c);
    let picked = selected(&h);
    assert_eq!(picked.len(), 1, "{picked:?}");
    let on_screen = camera.project(model.means[picked[0]]).expect("in front");
    let clicked = glam::Vec2::new(c.x - origin.x, c.y - origin.y);
    assert!(
        on_screen.distance(clicked) < 6.0,
        "the picked Gaussian is under the pointer: {on_screen} vs {clicked}"
    );

    // Eyedropper on the grey half: every grey Gaussian, no red one.
    h.key_press(Key::I);
    h.run_steps(1);
    let grey: Vec<usize> = (0..model.len()).filter(|g| g % 21 <= 10).collect();
    let c = centre(&h);
    click(&mut h, c + egui::vec2(0.0, 30.0));
    assert_eq!(selected(&h), grey);

    // Sphere and box of 0.1 around the surface point at the centre of a closed wall.
    let model = show_walls(&mut h, false, 0.03);
    for (key, inside) in [
        (Key::O, (|d: Vec3| d.length() <= 0.1) as fn(Vec3) -> bool),
        (Key::X, |d: Vec3| d.abs().max_element() <= 0.1),
    ] {
        h.key_press(key);
        h.run_steps(1);
        // An edit's log line can move the viewport's edge: the centre as laid out now.
        let c = centre(&h);
        click(&mut h, c);
        let got = selected(&h);
        let surely_in: Vec<usize> = (0..model.len())
            .filter(|&g| inside(model.means[g] * 1.1))
            .collect();
        let maybe_in: Vec<usize> = (0..model.len())
            .filter(|&g| inside(model.means[g] * 0.9))
            .collect();
        assert!(
            surely_in.iter().all(|g| got.contains(g)),
            "{key:?}: {got:?}"
        );
        assert!(got.iter().all(|g| maybe_in.contains(g)), "{key:?}: {got:?}");
        assert!(got.len() >= 9, "{key:?}: {}", got.len());
    }
}

#[test]
fn front_most_leaves_the_hidden_wall_out_where_straight_through_takes_it() {
    for front_most in [false, true] {
        let mut h = harness(settings(front_most));
        // σ of 3 cm at 4 cm spacing: a closed surface.
        let model = show_walls(&mut h, true, 0.03);
        let c = centre(&h);
        h.key_press(Key::R);
        h.run_steps(1);
        let (a, b) = (c + egui::vec2(-100.0, -100.0), c + egui::vec2(100.0, 100.0));
        h.hover_at(a);
        h.run_steps(1);
        h.event(egui::Event::PointerButton {
            pos: a,
            button: egui::PointerButton::Primary,
            pressed: true,
            modifiers: Modifiers::NONE,
        });
        h.run_steps(1);
        h.hover_at(b);
        h.run_steps(1);
        h.event(egui::Event::PointerButton {
            pos: b,
            button: egui::PointerButton::Primary,
            pressed: false,
            modifiers: Modifiers::NONE,
        });
        h.run_steps(2);
        let got = selected(&h);
        let front = got.iter().filter(|&&g| g < 441).count();
        let back = got.iter().filter(|&&g| g >= 441).count();
        assert!(
            front > 20,
            "front-most {front_most}: {front} of the front wall"
        );
        if front_most {
            assert_eq!(back, 0, "the wall behind draws nothing there");
        } else {
            assert!(back > 20, "straight through takes the wall behind: {back}");
        }
        assert_eq!(model.len(), 882);
    }
}

#[test]
fn measure_two_surface_points_and_frame_the_selection() {
    let mut h = harness(settings(false));
    let model = show_walls(&mut h, false, 0.03);
    let c = centre(&h);
    let (camera, right, ..) = camera(&h);
    let origin = h.state().viewport.last_rect().min;
    h.key_press(Key::M);
    h.run_steps(1);
    let (a, b) = (c + egui::vec2(-50.0, 0.0), c + egui::vec2(50.0, 0.0));
    click(&mut h, a);
    click(&mut h, b);
    let points = h.state().state.distance.clone();
    assert_eq!(points.len(), 2, "{:?}", h.state().state.log);
    for (p, at) in points.iter().zip([a, b]) {
        let screen = camera.project(*p).expect("in front");
        let want = glam::Vec2::new(at.x - origin.x, at.y - origin.y);
        assert!(screen.distance(want) < 1.5, "{screen} vs {want}");
        assert!(
            p.dot(camera.rotation.inverse() * Vec3::Z).abs() < 0.02,
            "on the wall: {p}"
        );
    }
    let text = h.state().state.distance_text().expect("a distance");
    assert!(text.contains("model units"), "{text}");
    assert!((points[1] - points[0]).dot(right) > 0.0);

    // F frames the selection: the orbit's goal goes to the selected Gaussians' centre.
    let corner: Vec<usize> = (0..model.len())
        .filter(|g| g / 21 >= 15 && g % 21 >= 15)
        .collect();
    h.key_press(Key::Escape);
    h.run_steps(1);
    let mut edited = model.clone();
    for &g in &corner {
        edited.meta.state[g] |= SELECTED;
    }
    h.state_mut().state.set_splats(Arc::new(edited));
    h.key_press(Key::F);
    h.run_steps(2);
    let want = corner.iter().map(|&g| model.means[g]).sum::<Vec3>() / corner.len() as f32;
    let goal = h.state().state.camera.goal().target;
    assert!(goal.distance(want) < 0.05, "{goal} vs {want}");
}
