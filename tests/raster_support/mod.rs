//! Shared by the rasterizer tests: gsplat's tensors for the 4- and 16-Gaussian scenes of brush's
//! test cases (`../shared/data/brush_gsplat_reference`, SOURCE.md: 123×82, fx = fy = 61.5,
//! camera at (0.123, 0.456, -8), identity rotation) with their loader, camera, gsplat's settings
//! and brush's comparison; random per-pixel loss weights; tensor flattening and errors.
#![allow(dead_code)]

use std::collections::HashMap;

use damage_twin::raster::{PixelGrads, RenderOutput, RenderSettings};
use damage_twin::scene::{Camera, Intrinsics};
use damage_twin::splats::Splats;
use glam::{Quat, Vec3};

pub const W: u32 = 123;
pub const H: u32 = 82;
pub const CASES: [&str; 2] = ["tiny_case.safetensors", "basic_case.safetensors"];

pub struct Case {
    tensors: HashMap<String, Vec<f32>>,
}

impl Case {
    /// The case in file `name`, or `None` (the test skips) when the reference data is missing.
    /// Test crates that use this module also declare `mod shared_data;`.
    pub fn load(name: &str) -> Option<Case> {
        let path = crate::shared_data::path(&format!("brush_gsplat_reference/{name}"))?;
        let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let st = safetensors::SafeTensors::deserialize(&bytes).expect("valid safetensors");
        let mut tensors = HashMap::new();
        for (key, view) in st.tensors() {
            assert_eq!(view.dtype(), safetensors::Dtype::F32, "{key}");
            let values = view
                .data()
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect();
            tensors.insert(key, values);
        }
        Some(Case { tensors })
    }

    pub fn get(&self, key: &str) -> &[f32] {
        &self.tensors[key]
    }

    /// The scene's raw parameters (gsplat's quaternion order w, x, y, z), with
    /// `label_channels` channels of raw labels from `labels(g, k)`.
    pub fn splats_with_labels(
        &self,
        label_channels: usize,
        mut labels: impl FnMut(usize, usize) -> f32,
    ) -> Splats {
        let means = self.get("means");
        let n = means.len() / 3;
        let mut s = Splats::empty(3, label_channels);
        for g in 0..n {
            let v3 = |key: &str| {
                let t = self.get(key);
                Vec3::new(t[g * 3], t[g * 3 + 1], t[g * 3 + 2])
            };
            let q = &self.get("quats")[g * 4..g * 4 + 4]; // w x y z
            let raw_labels: Vec<f32> = (0..label_channels).map(|k| labels(g, k)).collect();
            s.push(
                v3("means"),
                v3("scales"),
                Quat::from_xyzw(q[1], q[2], q[3], q[0]),
                self.get("opacities")[g],
                &self.get("coeffs")[g * 48..(g + 1) * 48],
                &raw_labels,
                g as u64,
                0,
            );
        }
        s
    }

    pub fn splats(&self) -> Splats {
        self.splats_with_labels(0, |_, _| 0.0)
    }

    /// `v_out_img` split into the colour and alpha gradients.
    pub fn pixel_grads(&self) -> (Vec<f32>, Vec<f32>) {
        let v_img = self.get("v_out_img");
        let pixels = (W * H) as usize;
        let mut v_color = Vec::with_capacity(pixels * 3);
        let mut v_alpha = Vec::with_capacity(pixels);
        for p in 0..pixels {
            v_color.extend_from_slice(&v_img[p * 4..p * 4 + 3]);
            v_alpha.push(v_img[p * 4 + 3]);
        }
        (v_color, v_alpha)
    }
}

pub fn camera() -> Camera {
    let k = Intrinsics {
        width: W,
        height: H,
        fx: 61.5,
        fy: 61.5,
        cx: W as f32 / 2.0,
        cy: H as f32 / 2.0,
    };
    Camera::new(k, Quat::IDENTITY, -Vec3::new(0.123, 0.456, -8.0))
}

/// gsplat's settings: alpha clamp 0.999, SH view direction detached, black background.
pub fn settings() -> RenderSettings {
    RenderSettings {
        background: Vec3::ZERO,
        sh_degree: 3,
        alpha_max: 0.999,
        alpha_threshold: 1.0 / 255.0,
        sh_direction_grad: false,
        near_plane: damage_twin::raster::NEAR_PLANE,
    }
}

/// Largest absolute error, and largest relative error among values above 1 % of the tensor's
/// largest magnitude (smaller ones are dominated by summation-order noise).
pub fn errors(got: &[f32], want: &[f32]) -> (f32, f32) {
    assert_eq!(got.len(), want.len());
    let scale = want.iter().fold(0.0f32, |m, w| m.max(w.abs()));
    let mut abs = 0.0f32;
    let mut rel = 0.0f32;
    for (g, w) in got.iter().zip(want) {
        let e = (g - w).abs();
        abs = abs.max(e);
        if w.abs() > 1e-2 * scale {
            rel = rel.max(e / w.abs());
        }
    }
    (abs, rel)
}

/// brush's own criterion: |a - b| < 1e-5 + 1e-2 |b| per value.
pub fn assert_close(what: &str, got: &[f32], want: &[f32], atol: f32, rtol: f32) {
    let (abs, rel) = errors(got, want);
    eprintln!("{what}: max abs error {abs:.3e}, max rel error {rel:.3e}");
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        assert!(
            (g - w).abs() <= atol + rtol * w.abs(),
            "{what}[{i}]: got {g}, gsplat {w} (tolerance {atol} + {rtol}·|b|)"
        );
    }
}

/// A tensor's error: its largest absolute difference relative to the tensor's largest
/// magnitude (the scale summation-order noise is relative to). NaN gives NaN.
pub fn scaled_error(got: &[f32], want: &[f32]) -> f32 {
    assert_eq!(got.len(), want.len());
    let scale = want.iter().fold(0.0f32, |m, w| m.max(w.abs()));
    let mut abs = 0.0f32;
    for (g, w) in got.iter().zip(want) {
        let e = (g - w).abs();
        if !(e <= abs) {
            abs = e;
        }
    }
    abs / scale.max(f32::MIN_POSITIVE)
}

/// Flattened tensors in gsplat's layouts (quaternions in its order w, x, y, z).
pub fn flat2(v: &[glam::Vec2]) -> Vec<f32> {
    v.iter().flat_map(|m| [m.x, m.y]).collect()
}

pub fn flat3(v: &[Vec3]) -> Vec<f32> {
    v.iter().flat_map(|m| [m.x, m.y, m.z]).collect()
}

pub fn flat_quats_wxyz(v: &[glam::Vec4]) -> Vec<f32> {
    v.iter().flat_map(|q| [q.w, q.x, q.y, q.z]).collect()
}

/// Per-pixel gradients of a loss (random weights: the loss is their dot product with the
/// outputs, so they are its gradients too).
pub struct Weights {
    pub color: Vec<f32>,
    pub alpha: Vec<f32>,
    pub depth: Vec<f32>,
    pub labels: Vec<f32>,
}

impl Weights {
    pub fn random(pixels: usize, labels: usize, seed: u64) -> Weights {
        let mut rng = fastrand::Rng::with_seed(seed);
        let mut v =
            |n: usize, scale: f32| (0..n).map(|_| scale * (2.0 * rng.f32() - 1.0)).collect();
        Weights {
            color: v(pixels * 3, 1.0),
            alpha: v(pixels, 1.0),
            depth: v(pixels, 0.2),
            labels: v(pixels * labels, 1.0),
        }
    }

    pub fn pixel_grads(&self) -> PixelGrads<'_> {
        PixelGrads {
            color: &self.color,
            alpha: Some(&self.alpha),
            depth: Some(&self.depth),
            labels: Some(&self.labels),
        }
    }

    pub fn loss(&self, out: &RenderOutput) -> f64 {
        let dot = |a: &[f32], b: &[f32]| -> f64 {
            a.iter().zip(b).map(|(x, y)| *x as f64 * *y as f64).sum()
        };
        dot(&out.color, &self.color)
            + dot(&out.alpha, &self.alpha)
            + dot(&out.depth, &self.depth)
            + dot(&out.labels, &self.labels)
    }
}
