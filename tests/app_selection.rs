//! The selection tools driven through the whole app with synthetic pointer and key events
//! (egui_kittest, software wgpu): rectangle, lasso, polygon and brush strokes select what the
//! CPU reference (`splats::selection::hits` with the viewport's camera) says they cover, with the
//! set operation of the modifiers held; Ctrl+A, Ctrl+I, H, Shift+H, Ctrl+Z and Ctrl+Shift+Z; the
//! selection survives a PLY save and reload.
#![cfg(feature = "app")]

use std::sync::Arc;

use damage_twin::app::settings::{Settings, ViewportRenderer};
use damage_twin::app::{Launch, TwinApp};
use damage_twin::splats::Splats;
use damage_twin::splats::model::state::{HIDDEN, SELECTED};
use damage_twin::splats::selection::{Shape, hits};
use egui::{Key, Modifiers, Pos2, pos2};
use egui_kittest::Harness;
use glam::{Quat, Vec2, Vec3};

/// 21 × 21 Gaussians 4 cm apart around the origin, where the empty viewer looks.
fn grid() -> Splats {
    let mut s = Splats::empty(0, 0);
    let mut id = 0;
    for i in -10..=10 {
        for j in -10..=10 {
            s.means
                .push(Vec3::new(i as f32 * 0.04, j as f32 * 0.04, 0.0));
            s.log_scales.push(Vec3::splat(-4.5));
            s.rotations.push(Quat::IDENTITY);
            s.raw_opacities.push(4.0);
            s.sh.extend_from_slice(&[0.0, 0.0, 0.0]);
            s.meta.push(id, 0);
            id += 1;
        }
    }
    s
}

fn harness() -> Harness<'static, TwinApp> {
    let settings = Settings {
        show_charts: false,
        viewport_renderer: ViewportRenderer::Cpu,
        ..Settings::default()
    };
    let mut harness = Harness::builder()
        .with_size(egui::vec2(800.0, 560.0))
        .with_accessibility_check(false)
        .wgpu_setup(damage_twin::app::wgpu_setup())
        .build_eframe(move |cc| {
            let mut app = TwinApp::new(cc, Launch::Empty);
            app.state.interactive = false;
            app.state
                .apply(damage_twin::app::commands::Command::UpdateSettings(
                    Box::new(settings),
                ));
            app
        });
    harness.run_steps(2);
    harness.state_mut().state.set_splats(Arc::new(grid()));
    harness.run_steps(2);
    harness
}

fn selected(h: &Harness<'_, TwinApp>) -> Vec<u32> {
    let s = h.state().state.splats.as_ref().unwrap();
    (0..s.len() as u32)
        .filter(|&g| s.meta.state[g as usize] & SELECTED != 0)
        .collect()
}

/// What the CPU reference selects for `shape` (given in screen points) with the viewport's camera.
fn reference(h: &Harness<'_, TwinApp>, shape: impl Fn(Pos2) -> Shape) -> Vec<u32> {
    let rect = h.state().viewport.last_rect();
    let state = &h.state().state;
    let camera = state.view_camera(rect.width() as u32, rect.height() as u32);
    let splats = state.splats.as_ref().unwrap();
    hits(splats, &camera, &shape(rect.min))
        .into_iter()
        .enumerate()
        .filter(|&(_, hit)| hit)
        .map(|(g, _)| g as u32)
        .collect()
}

fn local(origin: Pos2, p: Pos2) -> Vec2 {
    Vec2::new(p.x - origin.x, p.y - origin.y)
}

/// A primary-button stroke through `points`, with `modifiers` held.
fn stroke(h: &mut Harness<'_, TwinApp>, points: &[Pos2], modifiers: Modifiers) {
    h.event(egui::Event::ModifiersChanged(modifiers));
    h.hover_at(points[0]);
    h.run_steps(1);
    h.event(egui::Event::PointerButton {
        pos: points[0],
        button: egui::PointerButton::Primary,
        pressed: true,
        modifiers,
    });
    h.run_steps(1);
    for &p in &points[1..] {
        h.hover_at(p);
        h.run_steps(1);
    }
    let last = *points.last().unwrap();
    h.event(egui::Event::PointerButton {
        pos: last,
        button: egui::PointerButton::Primary,
        pressed: false,
        modifiers,
    });
    h.run_steps(1);
    h.event(egui::Event::ModifiersChanged(Modifiers::NONE));
    h.hover_at(pos2(5.0, 5.0));
    h.run_steps(2);
}

fn centre(h: &Harness<'_, TwinApp>) -> Pos2 {
    h.state().viewport.last_rect().center()
}

#[test]
fn rectangle_lasso_and_set_operations_match_the_reference() {
    let mut h = harness();
    let c = centre(&h);
    h.key_press(Key::R);
    h.run_steps(1);
    let (a, b) = (c + egui::vec2(-60.0, -40.0), c + egui::vec2(20.0, 30.0));
    let mid = c + egui::vec2(-20.0, -5.0);
    // Each reference is taken with the layout the stroke meets (an edit's log line can move the
    // viewport's edge afterwards).
    let first = reference(&h, |o| Shape::Rect {
        a: local(o, a),
        b: local(o, b),
    });
    stroke(&mut h, &[a, mid, b], Modifiers::NONE);
    assert!(first.len() > 20, "{}", first.len());
    assert_eq!(selected(&h), first, "rectangle, set");
    // Shift adds a second rectangle.
    let (a2, b2) = (c + egui::vec2(40.0, 40.0), c + egui::vec2(90.0, 80.0));
    stroke(
        &mut h,
        &[a2, c + egui::vec2(60.0, 60.0), b2],
        Modifiers::SHIFT,
    );
    let second = reference(&h, |o| Shape::Rect {
        a: local(o, a2),
        b: local(o, b2),
    });
    let mut union: Vec<u32> = first.iter().chain(&second).copied().collect();
    union.sort_unstable();
    union.dedup();
    assert!(union.len() > first.len());
    assert_eq!(selected(&h), union, "rectangle, add");
    // Ctrl removes what a lasso covers.
    h.key_press(Key::L);
    h.run_steps(1);
    let lasso = [
        c + egui::vec2(-70.0, -50.0),
        c + egui::vec2(0.0, -50.0),
        c + egui::vec2(0.0, 10.0),
        c + egui::vec2(-70.0, 10.0),
    ];
    let removed = reference(&h, |o| {
        Shape::Polygon(lasso.iter().map(|&p| local(o, p)).collect())
    });
    stroke(&mut h, &lasso, Modifiers::COMMAND);
    let left: Vec<u32> = union
        .iter()
        .copied()
        .filter(|g| !removed.contains(g))
        .collect();
    assert!(left.len() < union.len() && !left.is_empty());
    assert_eq!(selected(&h), left, "lasso, remove");
    // Shift+Ctrl intersects with a big rectangle over the left half.
    h.key_press(Key::R);
    h.run_steps(1);
    let (a3, b3) = (c + egui::vec2(-200.0, -200.0), c + egui::vec2(30.0, 200.0));
    let half = reference(&h, |o| Shape::Rect {
        a: local(o, a3),
        b: local(o, b3),
    });
    stroke(&mut h, &[a3, c, b3], Modifiers::SHIFT | Modifiers::COMMAND);
    let both: Vec<u32> = left.iter().copied().filter(|g| half.contains(g)).collect();
    assert_eq!(selected(&h), both, "rectangle, intersect");
    // Undo walks back through the four edits; redo returns.
    for expected in [&left, &union, &first] {
        h.key_press_modifiers(Modifiers::COMMAND, Key::Z);
        h.run_steps(1);
        assert_eq!(&selected(&h), expected);
    }
    h.key_press_modifiers(Modifiers::SHIFT | Modifiers::COMMAND, Key::Z);
    h.run_steps(1);
    assert_eq!(selected(&h), union, "redo");
}

#[test]
fn polygon_and_brush_match_the_reference() {
    let mut h = harness();
    let c = centre(&h);
    h.key_press(Key::P);
    h.run_steps(1);
    let corners = [
        c + egui::vec2(-50.0, -50.0),
        c + egui::vec2(40.0, -30.0),
        c + egui::vec2(10.0, 60.0),
        c + egui::vec2(-30.0, 20.0),
        c + egui::vec2(-80.0, 40.0),
    ];
    for &p in &corners {
        h.hover_at(p);
        h.run_steps(1);
        h.event(egui::Event::PointerButton {
            pos: p,
            button: egui::PointerButton::Primary,
            pressed: true,
            modifiers: Modifiers::NONE,
        });
        h.run_steps(1);
        h.event(egui::Event::PointerButton {
            pos: p,
            button: egui::PointerButton::Primary,
            pressed: false,
            modifiers: Modifiers::NONE,
        });
        h.run_steps(1);
    }
    // Backspace drops a point; put it back.
    h.key_press(Key::Backspace);
    h.run_steps(1);
    assert_eq!(h.state().viewport.tools.points.len(), corners.len() - 1);
    let last = corners[corners.len() - 1];
    h.hover_at(last);
    h.run_steps(1);
    for pressed in [true, false] {
        h.event(egui::Event::PointerButton {
            pos: last,
            button: egui::PointerButton::Primary,
            pressed,
            modifiers: Modifiers::NONE,
        });
        h.run_steps(1);
    }
    let expected = reference(&h, |o| {
        Shape::Polygon(corners.iter().map(|&p| local(o, p)).collect())
    });
    h.key_press(Key::Enter);
    h.run_steps(2);
    assert!(expected.len() > 20);
    assert_eq!(selected(&h), expected, "polygon");

    // The brush: `]` enlarges it; a stroke selects the discs along it.
    h.key_press(Key::B);
    h.run_steps(1);
    h.key_press(Key::CloseBracket);
    h.run_steps(1);
    let radius = h.state().viewport.tools.brush_radius;
    assert!(radius > 24.0);
    let path = [
        c + egui::vec2(-60.0, 0.0),
        c + egui::vec2(-30.0, 0.0),
        c + egui::vec2(0.0, 0.0),
        c + egui::vec2(30.0, 0.0),
    ];
    let brush = |h: &Harness<'_, TwinApp>, points: &[Pos2]| {
        reference(h, |o| Shape::Brush {
            centres: points.iter().map(|&p| local(o, p)).collect(),
            radius,
        })
    };
    let (most, least) = (brush(&h, &path), brush(&h, &path[1..]));
    stroke(&mut h, &path, Modifiers::NONE);
    let got = selected(&h);
    assert!(got.iter().all(|g| most.contains(g)), "beyond the stroke");
    assert!(least.iter().all(|g| got.contains(g)), "missed the stroke");
    // Esc leaves the tool: a drag orbits again and selects nothing new.
    h.key_press(Key::Escape);
    h.run_steps(1);
    assert_eq!(h.state().viewport.tools.tool, None);
}

#[test]
fn all_invert_hide_unhide_and_undo_by_keys() {
    let mut h = harness();
    let n = h.state().state.splats.as_ref().unwrap().len();
    h.key_press_modifiers(Modifiers::COMMAND, Key::A);
    h.run_steps(1);
    assert_eq!(selected(&h).len(), n);
    h.key_press_modifiers(Modifiers::COMMAND, Key::I);
    h.run_steps(1);
    assert!(selected(&h).is_empty());
    h.key_press_modifiers(Modifiers::COMMAND, Key::Z);
    h.run_steps(1);
    assert_eq!(selected(&h).len(), n);
    // Select a rectangle, hide it: hidden Gaussians are not selected by Ctrl+A.
    h.key_press(Key::R);
    h.run_steps(1);
    let c = centre(&h);
    stroke(
        &mut h,
        &[c + egui::vec2(-30.0, -30.0), c, c + egui::vec2(30.0, 30.0)],
        Modifiers::NONE,
    );
    let boxed = selected(&h);
    assert!(!boxed.is_empty() && boxed.len() < n);
    h.key_press(Key::Escape);
    h.key_press(Key::H);
    h.run_steps(1);
    let hidden = |h: &Harness<'_, TwinApp>| {
        let s = h.state().state.splats.as_ref().unwrap();
        (0..s.len() as u32)
            .filter(|&g| s.meta.state[g as usize] & HIDDEN != 0)
            .collect::<Vec<u32>>()
    };
    assert_eq!(hidden(&h), boxed);
    h.key_press_modifiers(Modifiers::COMMAND, Key::A);
    h.run_steps(1);
    // Ctrl+A selects the visible ones only.
    let all = selected(&h);
    assert_eq!(all.len(), n - boxed.len());
    assert!(all.iter().all(|g| !boxed.contains(g)));
    h.key_press_modifiers(Modifiers::SHIFT | Modifiers::COMMAND, Key::A);
    h.run_steps(1);
    assert!(selected(&h).is_empty());
    h.key_press_modifiers(Modifiers::SHIFT, Key::H);
    h.run_steps(1);
    assert!(hidden(&h).is_empty());
    // Undo: hidden again.
    h.key_press_modifiers(Modifiers::COMMAND, Key::Z);
    h.run_steps(1);
    assert_eq!(hidden(&h), boxed);
}

#[test]
fn selection_and_hidden_bits_survive_a_ply_save_and_reload() {
    let mut s = grid();
    s.meta.state[3] |= SELECTED;
    s.meta.state[7] |= SELECTED | HIDDEN;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("model.ply");
    damage_twin::splats::ply::write_splats(&path, &s).unwrap();
    let back = damage_twin::splats::ply::read_splats(&path).unwrap();
    assert_eq!(back.meta.state, s.meta.state);
}

/// Selecting by damage class and survey, then marking a class by hand: undoable, and kept in
/// the saved PLY.
#[test]
fn damage_selection_and_hand_labels_undo_and_save() {
    use damage_twin::app::commands::Command;
    use damage_twin::app::state::AppState;
    use damage_twin::damage::DamageClass;
    use damage_twin::splats::selection::{LABEL_ON, SetOp};

    let mut s = Splats::empty(0, 3);
    for g in 0..10u64 {
        s.means.push(Vec3::new(g as f32 * 0.1, 0.0, 0.0));
        s.log_scales.push(Vec3::splat(-3.0));
        s.rotations.push(Quat::IDENTITY);
        s.raw_opacities.push(2.0);
        s.sh.extend_from_slice(&[0.0; 3]);
        // Gaussians 0..4 crack (4 of them first seen in survey 2), the rest nothing.
        let crack = if g < 4 { 3.0 } else { -3.0 };
        s.raw_labels.extend_from_slice(&[crack, -3.0, -3.0]);
        s.meta.push(g, 0);
        if g < 4 {
            s.meta.damage_survey[g as usize] = u16::from(g == 3);
        }
    }
    let mut state = AppState::new(Settings::default());
    state.set_splats(Arc::new(s));
    let selected = |state: &AppState| {
        let s = state.splats.as_ref().unwrap();
        (0..s.len() as u32)
            .filter(|&g| s.meta.state[g as usize] & SELECTED != 0)
            .collect::<Vec<u32>>()
    };
    let select_crack = |survey| Command::SelectDamage {
        class: DamageClass::Crack,
        threshold: 0.5,
        survey,
        op: SetOp::Set,
    };
    state.apply(select_crack(None));
    assert_eq!(selected(&state), [0, 1, 2, 3]);
    state.apply(select_crack(Some(1)));
    assert_eq!(selected(&state), [3]);
    state.apply(select_crack(None));
    state.apply(Command::SetDamageClass {
        class: DamageClass::Spalling,
        on: true,
    });
    let spalling = |state: &AppState| {
        let s = state.splats.as_ref().unwrap();
        (0..s.len())
            .map(|g| s.labels_of(g)[1])
            .collect::<Vec<f32>>()
    };
    let marked = spalling(&state);
    assert!(marked[..4].iter().all(|&l| l == LABEL_ON) && marked[4..].iter().all(|&l| l == -3.0));
    state.apply(Command::Undo);
    assert!(
        spalling(&state).iter().all(|&l| l == -3.0),
        "undo restores the labels"
    );
    state.apply(Command::Redo);
    assert_eq!(spalling(&state), marked);
    // Cleared by hand: the crack class off on Gaussian 0..4.
    state.apply(Command::SetDamageClass {
        class: DamageClass::Crack,
        on: false,
    });
    state.apply(select_crack(None));
    assert!(selected(&state).is_empty());
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("model.ply");
    let model = state.splats.as_ref().unwrap();
    damage_twin::splats::ply::write_splats(&path, model).unwrap();
    let back = damage_twin::splats::ply::read_splats(&path).unwrap();
    assert_eq!(back.raw_labels, model.raw_labels);
}

/// The same strokes through the GPU selection pass (forced on lavapipe): a rectangle, a lasso
/// added, then a hide, after which the pass must upload the model again (hidden Gaussians are
/// never hit) while selection-only edits reuse its copy.
#[test]
fn the_gpu_selection_pass_selects_what_the_cpu_reference_does() {
    let mut h = harness();
    let ctx =
        damage_twin::gpu::GpuContext::new().expect("GPU tests need an adapter (CI uses lavapipe)");
    h.state_mut().state.select_on_gpu(&ctx).unwrap();
    let c = centre(&h);
    h.key_press(Key::R);
    h.run_steps(1);
    let (a, b) = (c + egui::vec2(-60.0, -40.0), c + egui::vec2(20.0, 30.0));
    let rect = reference(&h, |o| Shape::Rect {
        a: local(o, a),
        b: local(o, b),
    });
    stroke(&mut h, &[a, c, b], Modifiers::NONE);
    assert!(rect.len() > 20, "{}", rect.len());
    assert_eq!(selected(&h), rect, "rectangle on the GPU");
    let drawn = h.state().state.drawn_generation;
    // Hide the selection: what is drawn changes.
    h.key_press(Key::H);
    h.run_steps(1);
    assert!(
        h.state().state.drawn_generation > drawn,
        "hiding changes what is drawn"
    );
    h.key_press(Key::L);
    h.run_steps(1);
    let lasso = [
        c + egui::vec2(-90.0, -60.0),
        c + egui::vec2(60.0, -60.0),
        c + egui::vec2(60.0, 50.0),
        c + egui::vec2(-90.0, 50.0),
    ];
    let want = reference(&h, |o| {
        Shape::Polygon(lasso.iter().map(|&p| local(o, p)).collect())
    });
    let drawn = h.state().state.drawn_generation;
    stroke(&mut h, &lasso, Modifiers::NONE);
    assert!(!want.is_empty() && want.iter().all(|g| !rect.contains(g)));
    assert_eq!(selected(&h), want, "lasso on the GPU leaves the hidden out");
    assert_eq!(
        h.state().state.drawn_generation,
        drawn,
        "a selection edit keeps what is drawn"
    );
    assert!(
        h.state().state.selects_on_gpu(),
        "the GPU pass did not fall back"
    );
}
