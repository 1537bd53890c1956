//! What the trainer checks of its views and derives from them: sizes that agree, and the tiles
//! a loss region needs rendered.

use super::TrainError;
use crate::scene::Mask;
use crate::train::spec::TrainView;

/// The tiles a loss region needs rendered: those holding a region pixel. The photometric loss
/// reads the render only at region pixels (its SSIM sees `m·render + (1-m)·photo`, the photo
/// outside the region, `train::loss::photometric_loss`) and sends no gradient elsewhere, and the
/// label loss skips pixels outside the region, so the SSIM window needs no margin of rendered
/// pixels: leaving the other tiles out (background there) changes nothing that is trained.
/// (A 5-pixel margin was rendered before: 16×16 tiles around every thin hull's edge.)
pub(super) fn region_tiles(region: &Mask) -> Vec<bool> {
    let ts = crate::raster::TILE_SIZE;
    let (tiles_x, tiles_y) = crate::raster::tile_grid(region.width, region.height);
    let mut tiles = vec![false; tiles_x as usize * tiles_y as usize];
    if region.width == 0 {
        return tiles;
    }
    for (y, row) in region.data.chunks_exact(region.width as usize).enumerate() {
        let ty = y as u32 / ts;
        for (x, &m) in row.iter().enumerate() {
            if m != 0 {
                tiles[(ty * tiles_x + x as u32 / ts) as usize] = true;
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
