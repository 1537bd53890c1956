//! NaN/Inf guards of the training loop: cheap scans of gradients and parameters that decide
//! whether a step is skipped or the model restored. Reads only; never repairs anything itself.

use crate::raster::SplatGrads;
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

pub(crate) fn first_non_finite_grad(grads: &SplatGrads, splats: &Splats) -> Option<&'static str> {
    let _ = splats;
    if !all_finite(bytemuck::cast_slice(&grads.v_means)) {
        return Some("means");
    }
    if !all_finite(bytemuck::cast_slice(&grads.v_log_scales)) {
        return Some("log_scales");
    }
    if !all_finite(bytemuck::cast_slice(&grads.v_rotations)) {
        return Some("rotations");
    }
    if !all_finite(&grads.v_raw_opacities) {
        return Some("raw_opacities");
    }
    if !all_finite(&grads.v_sh) {
        return Some("sh");
    }
    if !all_finite(&grads.v_raw_labels) {
        return Some("raw_labels");
    }
    None
}

/// The first parameter array holding NaN/Inf, looking only at `visible` Gaussians when given
/// (the only ones an update with visible-only Adam can have changed).
pub(crate) fn first_non_finite_param(
    splats: &Splats,
    visible: Option<&[bool]>,
) -> Option<&'static str> {
    match visible {
        None => {
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
        Some(visible) => {
            let k3 = splats.sh_coeffs() * 3;
            let c = splats.label_channels;
            for (g, _) in visible.iter().enumerate().filter(|(_, v)| **v) {
                let finite = splats.means[g].is_finite()
                    && splats.log_scales[g].is_finite()
                    && splats.rotations[g].is_finite()
                    && splats.raw_opacities[g].is_finite();
                if !finite {
                    return Some("geometry or opacity");
                }
                if !all_finite(&splats.sh[g * k3..(g + 1) * k3]) {
                    return Some("sh");
                }
                if !all_finite(&splats.raw_labels[g * c..(g + 1) * c]) {
                    return Some("raw_labels");
                }
            }
            None
        }
    }
}
