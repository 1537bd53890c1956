//! The stability study's rows as CSV and a Markdown table.

use crate::studies::stability::row::StabilityRow;

fn iou(row: &StabilityRow, class: &str) -> String {
    row.iou
        .get(class)
        .map(|v| format!("{v:.3}"))
        .unwrap_or_else(|| "–".into())
}

/// The rows as CSV (empty cells where a figure is absent).
pub fn stability_csv(rows: &[StabilityRow]) -> String {
    let mut out = String::from(
        "axis,value,psnr,ssim,iou_crack,iou_spalling,iou_rebar,gaussians,seconds,width,height\n",
    );
    for r in rows {
        out.push_str(&format!(
            "{},{},{:.3},{},{},{},{},{},{:.1},{},{}\n",
            r.axis,
            r.value,
            r.psnr,
            r.ssim.map(|s| format!("{s:.4}")).unwrap_or_default(),
            iou(r, "crack"),
            iou(r, "spalling"),
            iou(r, "rebar"),
            r.gaussians,
            r.seconds,
            r.width,
            r.height
        ));
    }
    out.replace('–', "")
}

/// The rows as a Markdown table (for docs/).
pub fn stability_table(rows: &[StabilityRow]) -> String {
    let mut out = String::from(
        "| axis | value | held-out PSNR | SSIM | IoU crack / spalling / rebar | Gaussians | seconds |\n\
         |---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        out.push_str(&format!(
            "| {} | {} | {:.2} dB | {} | {} / {} / {} | {} | {:.0} |\n",
            r.axis,
            r.value,
            r.psnr,
            r.ssim
                .map(|s| format!("{s:.3}"))
                .unwrap_or_else(|| "–".into()),
            iou(r, "crack"),
            iou(r, "spalling"),
            iou(r, "rebar"),
            r.gaussians,
            r.seconds
        ));
    }
    out
}
