//! The loss on the GPU (`gpu::loss`) against the trainer's CPU loss
//! (`train::loss::photometric_loss` + `train::label_loss`): L1 + D-SSIM and the label cross-entropy, their
//! value and their gradients with respect to the render, on a random image with and without a
//! loss region, with supervised and unsupervised label channels. On lavapipe in CI.

mod gpu_support;

use damage_twin::gpu::loss::{GpuLoss, LossTarget, LossWeights};
use damage_twin::train::label_loss::{LabelLossParams, label_loss};
use damage_twin::train::loss::{LossWorkspace, photometric_loss};
use damage_twin::train::ssim::gaussian_window;

const W: u32 = 53;
const H: u32 = 37;

fn random(n: usize, seed: u64) -> Vec<f32> {
    let mut rng = fastrand::Rng::with_seed(seed);
    (0..n).map(|_| rng.f32()).collect()
}

/// Largest difference relative to the CPU tensor's largest magnitude.
fn scaled_error(got: &[f32], want: &[f32]) -> f32 {
    assert_eq!(got.len(), want.len());
    let scale = want.iter().fold(0.0f32, |m, w| m.max(w.abs()));
    let err = got
        .iter()
        .zip(want)
        .fold(0.0f32, |m, (g, w)| m.max((g - w).abs()));
    err / scale.max(f32::MIN_POSITIVE)
}

#[test]
fn gpu_loss_matches_the_cpu_loss_with_and_without_a_region() {
    let n = (W * H) as usize;
    let labels = 3;
    let photo = random(n * 3, 1);
    // A render near the photo (SSIM's gradient matters there) with some pixels equal to it
    // (L1's sign is 0 there, on both sides).
    let mut rendered: Vec<f32> = photo
        .iter()
        .zip(random(n * 3, 2))
        .map(|(p, r)| (p + 0.2 * (r - 0.5)).clamp(0.0, 1.0))
        .collect();
    rendered[..30].copy_from_slice(&photo[..30]);
    let rendered_labels = random(n * labels, 3);
    let mask_a: Vec<u8> = random(n, 4).iter().map(|&v| u8::from(v > 0.7)).collect();
    let mask_c: Vec<u8> = random(n, 5).iter().map(|&v| u8::from(v > 0.9)).collect();
    // Channel 1 unsupervised in this view.
    let masks: [Option<&[u8]>; 3] = [Some(&mask_a), None, Some(&mask_c)];
    let region: Vec<f32> = (0..n)
        .map(|p| f32::from(u8::from((p % W as usize) > 10 && (p / W as usize) < 30)))
        .collect();
    let weights = LossWeights {
        ssim_lambda: 0.2,
        rgb_weight: 1.0,
        label_weight: 0.7,
        pos_weight: 4.0,
        eps: 1e-4,
        window: gaussian_window(),
    };
    let ctx = gpu_support::context();
    let mut gpu = GpuLoss::new(&ctx.device);
    for region in [None, Some(region.as_slice())] {
        let mut ws = LossWorkspace::new();
        let mut v_color = vec![0.0; n * 3];
        let photometric = photometric_loss(
            &mut ws,
            &rendered,
            &photo,
            W,
            H,
            region,
            weights.ssim_lambda,
            &mut v_color,
        );
        let mut v_labels = vec![0.0; n * labels];
        let params = LabelLossParams {
            pos_weight: weights.pos_weight,
            eps: weights.eps,
        };
        let label = label_loss(
            &rendered_labels,
            labels,
            &masks,
            region,
            &params,
            &mut v_labels,
        );
        v_labels.iter_mut().for_each(|v| *v *= weights.label_weight);
        let cpu_loss = photometric.loss + weights.label_weight * label;

        let target = LossTarget {
            photo: &photo,
            region,
            labels: &masks,
        };
        let (loss, gpu_color, gpu_labels) = gpu
            .evaluate(&ctx, W, H, &rendered, &rendered_labels, &target, &weights)
            .unwrap();
        let (e_color, e_labels) = (
            scaled_error(&gpu_color, &v_color),
            scaled_error(&gpu_labels, &v_labels),
        );
        eprintln!(
            "region {}: loss GPU {loss:.6} CPU {cpu_loss:.6}; gradient errors colour {e_color:.2e}, \
             labels {e_labels:.2e}",
            region.is_some()
        );
        assert!(
            (loss - cpu_loss).abs() <= 1e-5 * cpu_loss.abs().max(1.0),
            "loss {loss} vs {cpu_loss}"
        );
        assert!(e_color < 2e-5, "colour gradient error {e_color:.3e}");
        assert!(e_labels < 1e-6, "label gradient error {e_labels:.3e}");
        assert!(
            gpu_labels.chunks(3).all(|v| v[1] == 0.0),
            "an unsupervised channel has no gradient"
        );
    }
}
