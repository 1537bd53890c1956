//! What the trainer checks of its views and derives from them: sizes that agree, and the tiles
//! a loss region needs rendered.

use super::TrainError;
use crate::scene::Mask;
use crate::train::spec::TrainView;

/// The tiles a loss region needs rendered: every tile within the SSIM window's half width
/// (5 px for its 11×11 window) of a region pixel. The loss's value and gradient at region pixels
/// read no pixel beyond that, and its gradient reaches none, so leaving the other tiles out
/// changes nothing that is trained.
pub(super) fn region_tiles(region: &Mask) -> Vec<bool> {
    const REACH: u32 = 5;
    let ts = crate::raster::TILE_SIZE;
    let (tiles_x, tiles_y) = crate::raster::tile_grid(region.width, region.height);
    let mut tiles = vec![false; tiles_x as usize * tiles_y as usize];
    for y in 0..region.height {
        let row = &region.data[(y * region.width) as usize..((y + 1) * region.width) as usize];
        let (ty0, ty1) = (
            y.saturating_sub(REACH) / ts,
            (y + REACH).min(region.height - 1) / ts,
        );
        // Each run of region pixels in the row, widened by the reach.
        let mut x = 0;
        while x < region.width {
            if row[x as usize] == 0 {
                x += 1;
                continue;
            }
            let start = x;
            while x < region.width && row[x as usize] != 0 {
                x += 1;
            }
            let (tx0, tx1) = (
                start.saturating_sub(REACH) / ts,
                (x - 1 + REACH).min(region.width - 1) / ts,
            );
            for ty in ty0..=ty1 {
                for tx in tx0..=tx1 {
                    tiles[(ty * tiles_x + tx) as usize] = true;
                }
            }
        }
    }
    tiles
}

pub(super) fn check_view(view: &TrainView, label_channels: usize) -> Result<(), TrainError> {
    let k = &view.camera.intrinsics;
    let pixels = k.width as usize * k.height as usize;
    if view.image.data.len() != pixels * 3
        || view.image.width != k.width
        || view.image.height != k.height
    {
        return Err(TrainError::ImageSize {
            name: view.name.clone(),
            got: view.image.data.len(),
            expected: pixels * 3,
        });
    }
    let masks = view
        .labels
        .iter()
        .enumerate()
        .map(|(k, m)| (format!("label {k}"), m))
        .chain(view.region.iter().map(|m| ("region".to_string(), m)));
    for (what, mask) in masks {
        if mask.data.len() != pixels {
            return Err(TrainError::MaskSize {
                name: view.name.clone(),
                what,
                got: mask.data.len(),
                expected: pixels,
            });
        }
    }
    if !view.labels.is_empty() && view.labels.len() != label_channels {
        return Err(TrainError::MaskSize {
            name: view.name.clone(),
            what: format!(
                "{} label masks for {label_channels} channels",
                view.labels.len()
            ),
            got: view.labels.len(),
            expected: label_channels,
        });
    }
    Ok(())
}
