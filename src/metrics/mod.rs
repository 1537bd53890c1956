//! Quality and cost measures: PSNR, damage-mask agreement (IoU, precision, recall, F1; and within
//! a distance, for thin cracks) and the process's peak memory and CPU time. Pure functions over pixel buffers;
//! no rendering here.

pub mod cpu_time;
pub mod image_quality;
pub mod mask_agreement;
pub mod memory;
pub mod near_agreement;
pub mod ssim;

pub use cpu_time::{PhaseClock, PhaseTimes, process_cpu_seconds};
pub use image_quality::{psnr, psnr_masked};
pub use mask_agreement::MaskAgreement;
pub use memory::peak_rss_mb;
pub use near_agreement::NearAgreement;
pub use ssim::{ssim, ssim_masked};
