//! The stability study's mask_noise axis: not trained here but read from the mask-noise study's
//! saved label-mode rows (`study mask-noise`'s study.json), one row per corruption rate.

use std::path::Path;

use serde::Deserialize;

use crate::damage::TrainMode;
use crate::scene::files::{is_present, read_regular};
use crate::scene::limits::MAX_PROJECT_JSON_BYTES;
use crate::studies::stability::row::StabilityRow;

/// The mask-noise study's rows this study reads.
#[derive(Deserialize)]
struct MaskNoiseFile {
    iterations: u32,
    rows: Vec<MaskNoiseRow>,
}

#[derive(Deserialize)]
struct MaskNoiseRow {
    mode: TrainMode,
    rate: f64,
    class: String,
    twin_iou_heldout: f64,
    gaussians: usize,
    train_seconds: f64,
    heldout_psnr: f64,
}

/// Appends the mask-noise study's label-mode rows as the mask_noise axis; returns where they
/// came from (None when the file is absent, which `log` hears).
pub fn mask_noise_rows(
    path: &Path,
    rows: &mut Vec<StabilityRow>,
    log: &mut dyn FnMut(String),
) -> Result<Option<String>, String> {
    if !is_present(path) {
        log(format!(
            "no {}: the mask_noise axis is left out",
            path.display()
        ));
        return Ok(None);
    }
    // Anything there is read like any input: a FIFO or a folder in its place is an error.
    let bytes = read_regular(path, MAX_PROJECT_JSON_BYTES).map_err(|e| e.to_string())?;
    let file: MaskNoiseFile =
        serde_json::from_slice(&bytes).map_err(|e| format!("reading {}: {e}", path.display()))?;
    let mut rates: Vec<f64> = file
        .rows
        .iter()
        .filter(|r| r.mode == TrainMode::Label)
        .map(|r| r.rate)
        .collect();
    rates.sort_by(f64::total_cmp);
    rates.dedup();
    for rate in rates {
        let of_rate: Vec<&MaskNoiseRow> = file
            .rows
            .iter()
            .filter(|r| r.mode == TrainMode::Label && r.rate == rate)
            .collect();
        let first = of_rate[0];
        rows.push(StabilityRow {
            axis: "mask_noise".into(),
            value: rate,
            psnr: first.heldout_psnr,
            ssim: None,
            iou: of_rate
                .iter()
                .map(|r| (r.class.clone(), r.twin_iou_heldout))
                .collect(),
            gaussians: first.gaussians,
            seconds: first.train_seconds,
            width: 0,
            height: 0,
        });
    }
    Ok(Some(format!(
        "{} (label mode, {} iterations each)",
        path.display(),
        file.iterations
    )))
}
