//! Rendering only a loss region's pixels (`Rasterizer::set_active_pixels`): against the plain
//! frame of the same model, every rendered pixel is bit-identical in every channel, every other
//! pixel is background, and with pixel gradients that vanish outside the region (as a region
//! loss's do) every Gaussian's gradient is the same (a sum of the same terms, less exact
//! zeros), in whole frames and in cached focused ones; and the mask really cuts the blending.

use damage_twin::raster::{
    FrameFocus, Rasterizer, RenderOutput, RenderSettings, SplatGrads, pixel_rows, tile_grid,
};
use damage_twin::scene::Camera;
use damage_twin::splats::Splats;
use glam::Vec3;

mod frame_support;
use frame_support::{H, W, bits, camera, labelled_model, seeded_backward};

const LABELS: usize = 2;

/// A thin slanted band and a disc: hull-like shapes that cut through tiles.
fn region() -> Vec<u8> {
    let mut m = vec![0u8; (W * H) as usize];
    for y in 0..H as i32 {
        for x in 0..W as i32 {
            let band = (x - 2 * y / 3 - 20).abs() <= 2;
            let disc = (x - 110) * (x - 110) + (y - 60) * (y - 60) <= 15 * 15;
            m[(y * W as i32 + x) as usize] = u8::from(band || disc);
        }
    }
    m
}

/// The tiles holding a region pixel.
fn tiles_of(mask: &[u8]) -> Vec<bool> {
    let (tx, ty) = tile_grid(W, H);
    let mut t = vec![false; (tx * ty) as usize];
    for (p, &m) in mask.iter().enumerate() {
        let (x, y) = (p as u32 % W, p as u32 / W);
        if m != 0 {
            t[((y / 16) * tx + x / 16) as usize] = true;
        }
    }
    t
}

/// A frame and its backward, pixel gradients seeded and zero outside `mask`.
fn frame(
    r: &mut Rasterizer,
    s: &Splats,
    cam: &Camera,
    mask: &[u8],
    masked: bool,
    focus: Option<FrameFocus<'_>>,
) -> (RenderOutput, SplatGrads) {
    let settings = RenderSettings::default();
    r.set_active_tiles(Some(&tiles_of(mask)));
    let rows = pixel_rows(mask, W, H);
    r.set_active_pixels(masked.then_some(rows.as_slice()));
    r.set_focus(focus);
    let mut out = RenderOutput::default();
    r.forward(s, cam, &settings, &mut out);
    let grads = seeded_backward(r, s, cam, &settings, &out, |p| mask[p] != 0);
    (out, grads)
}

/// Masked against plain: the region's pixels bit for bit, background elsewhere, gradients
/// equal (`==`: an exact zero the plain frame adds may flip a zero's sign, nothing else).
fn assert_same(
    masked: &(RenderOutput, SplatGrads),
    plain: &(RenderOutput, SplatGrads),
    mask: &[u8],
) {
    let (mo, mg) = masked;
    let (po, pg) = plain;
    let pick = |v: &[f32], per: usize, inside: bool| -> Vec<f32> {
        v.chunks_exact(per)
            .zip(mask)
            .filter(|(_, m)| (**m != 0) == inside)
            .flat_map(|(c, _)| c.iter().copied())
            .collect()
    };
    assert_eq!(
        bits(&pick(&mo.color, 3, true)),
        bits(&pick(&po.color, 3, true))
    );
    assert_eq!(
        bits(&pick(&mo.alpha, 1, true)),
        bits(&pick(&po.alpha, 1, true))
    );
    assert_eq!(
        bits(&pick(&mo.depth, 1, true)),
        bits(&pick(&po.depth, 1, true))
    );
    assert_eq!(
        bits(&pick(&mo.labels, LABELS, true)),
        bits(&pick(&po.labels, LABELS, true))
    );
    assert!(pick(&mo.alpha, 1, false).iter().all(|&a| a == 0.0));
    assert!(
        pick(&po.alpha, 1, false).iter().any(|&a| a > 0.1),
        "the plain frame draws outside the region"
    );
    assert_eq!(mg.v_means, pg.v_means);
    assert_eq!(mg.v_log_scales, pg.v_log_scales);
    assert_eq!(mg.v_rotations, pg.v_rotations);
    assert_eq!(mg.v_raw_opacities, pg.v_raw_opacities);
    assert_eq!(mg.v_sh, pg.v_sh);
    assert_eq!(mg.v_raw_labels, pg.v_raw_labels);
    assert_eq!(mg.v_means2d_norm, pg.v_means2d_norm);
    assert_eq!(mg.visible, pg.visible);
    let moved = mg.v_means.iter().filter(|v| **v != Vec3::ZERO).count();
    assert!(moved > 50, "only {moved} Gaussians had gradients");
}

#[test]
fn masked_frames_match_plain_frames_inside_the_region() {
    let s = labelled_model(3000, 5, LABELS);
    let cam = camera(Vec3::new(0.3, -0.2, 0.0));
    let mask = region();
    let masked = frame(&mut Rasterizer::new(), &s, &cam, &mask, true, None);
    let plain = frame(&mut Rasterizer::new(), &s, &cam, &mask, false, None);
    assert_same(&masked, &plain, &mask);
}

#[test]
fn masked_focused_frames_match_plain_whole_frames() {
    let mut s = labelled_model(3000, 7, LABELS);
    let cam = camera(Vec3::new(-0.4, 0.1, 0.3));
    let mask = region();
    let trainable: Vec<u32> = (0..s.len() as u32).filter(|g| g % 6 == 0).collect();
    let focus = Some(FrameFocus {
        trainable: &trainable,
        view: 0,
        generation: 0,
    });
    let mut focused = Rasterizer::new();
    // The first frame fills the cache, the second reuses it after the trainable set moved.
    frame(&mut focused, &s, &cam, &mask, true, focus);
    for &g in &trainable {
        s.means[g as usize] += Vec3::new(0.01, -0.02, 0.015);
    }
    let masked = frame(&mut focused, &s, &cam, &mask, true, focus);
    assert!(focused.last_frame_cached());
    let plain = frame(&mut Rasterizer::new(), &s, &cam, &mask, false, None);
    let (mo, mg) = &masked;
    // The cached frame's gradients cover the trainable Gaussians only: compare those.
    let mut only_trainable = plain.1.clone();
    let k = s.sh_coeffs() * 3;
    let mut is_trainable = vec![false; s.len()];
    trainable
        .iter()
        .for_each(|&g| is_trainable[g as usize] = true);
    for (g, &t) in is_trainable.iter().enumerate() {
        if !t {
            only_trainable.v_means[g] = Vec3::ZERO;
            only_trainable.v_log_scales[g] = Vec3::ZERO;
            only_trainable.v_rotations[g] = glam::Vec4::ZERO;
            only_trainable.v_raw_opacities[g] = 0.0;
            only_trainable.v_sh[g * k..(g + 1) * k].fill(0.0);
            only_trainable.v_raw_labels[g * LABELS..(g + 1) * LABELS].fill(0.0);
            only_trainable.v_means2d_norm[g] = 0.0;
            only_trainable.visible[g] = mg.visible[g];
        }
    }
    assert_same(&(mo.clone(), mg.clone()), &(plain.0, only_trainable), &mask);
}
