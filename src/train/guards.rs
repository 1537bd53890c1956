//! NaN/Inf guards of the training loop: a scan of every parameter, run on the input model,
//! before each checkpoint and on a rollback. Each step's own check is fused into Adam
//! (`adam::NonFinite`), which reads the gradients and writes the parameters anyway. Reads only;
//! never repairs anything itself.

use crate::splats::Splats;

/// True when any value is NaN or ±Inf: `x * 0` is 0 for finite `x` and NaN otherwise, and
/// the sums of eight lanes vectorise.
pub(crate) fn all_finite(values: &[f32]) -> bool {
    let mut acc = [0.0f32; 8];
    let chunks = values.chunks_exact(8);
    let rest = chunks.remainder();
    for c in chunks {
        for i in 0..8 {
            acc[i] += c[i] * 0.0;
        }
    }
    let tail: f32 = rest.iter().map(|&v| v * 0.0).sum();
    acc.iter().sum::<f32>() + tail == 0.0
}

/// The first parameter array holding NaN/Inf.
pub(crate) fn first_non_finite_param(splats: &Splats) -> Option<&'static str> {
    if !all_finite(bytemuck::cast_slice(&splats.means)) {
        return Some("means");
    }
    if !all_finite(bytemuck::cast_slice(&splats.log_scales)) {
        return Some("log_scales");
    }
    if !all_finite(bytemuck::cast_slice(&splats.rotations)) {
        return Some("rotations");
    }
    if !all_finite(&splats.raw_opacities) {
        return Some("raw_opacities");
    }
    if !all_finite(&splats.sh) {
        return Some("sh");
    }
    if !all_finite(&splats.raw_labels) {
        return Some("raw_labels");
    }
    None
}
