//! One photo through the model: scaled, cut into tiles (`tiles`), each tile preprocessed and
//! padded to the model's multiple, run, activated, blended back, and the probabilities resized to
//! the photo's own size. Tiles of a photo run in parallel on the caller's rayon pool.

use std::path::Path;

use rayon::prelude::*;

use crate::scene::ImageScale;
use crate::scene::RgbImage;
use crate::scene::load::resize_rgb;
use crate::segment::{Preprocess, SegmentError, SegmentModel, Tiling};

/// One output channel's probabilities over a photo, row-major, in [0, 1].
#[derive(Clone, Debug, PartialEq)]
pub struct ProbabilityMap {
    pub width: u32,
    pub height: u32,
    pub data: Vec<f32>,
}

/// How a photo is fed to the model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PhotoSettings {
    pub preprocess: Preprocess,
    /// The photo is run at this scale; its probabilities are resized back to the photo.
    pub scale: ImageScale,
    pub tiling: Tiling,
}

/// The model's input for the `width × height` window at (`x0`, `y0`) of `image`, padded to
/// `padded_w × padded_h` by repeating the edge pixels, planar (NCHW).
fn tile_input(
    image: &RgbImage,
    (x0, y0, width, height): (u32, u32, u32, u32),
    (padded_w, padded_h): (u32, u32),
    preprocess: &Preprocess,
) -> Vec<f32> {
    let plane = padded_w as usize * padded_h as usize;
    let mut data = vec![0.0f32; 3 * plane];
    for y in 0..padded_h {
        let source_y = y0 + y.min(height - 1);
        for x in 0..padded_w {
            let source_x = x0 + x.min(width - 1);
            let values = preprocess.input(image.pixel(source_x, source_y));
            let at = y as usize * padded_w as usize + x as usize;
            for (c, v) in values.into_iter().enumerate() {
                data[c * plane + at] = v;
            }
        }
    }
    data
}

/// The model's probabilities for every output channel over `image` (named `photo` in errors),
/// at the image's own size.
pub fn photo_probabilities(
    model: &SegmentModel,
    image: &RgbImage,
    photo: &Path,
    settings: &PhotoSettings,
) -> Result<Vec<ProbabilityMap>, SegmentError> {
    settings.tiling.check()?;
    settings.preprocess.check()?;
    let (width, height) = settings.scale.apply(image.width, image.height);
    let scaled;
    let source = if (width, height) == (image.width, image.height) {
        image
    } else {
        scaled = resize_rgb(image, width, height);
        &scaled
    };
    let tiling = &settings.tiling;
    let (xs, tile_w) = tiling.starts(width);
    let (ys, tile_h) = tiling.starts(height);
    let padded = (tiling.padded(tile_w), tiling.padded(tile_h));
    let tiles: Vec<(u32, u32)> = ys
        .iter()
        .flat_map(|&y| xs.iter().map(move |&x| (x, y)))
        .collect();
    let outputs: Vec<Vec<f32>> = tiles
        .par_iter()
        .map(|&(x0, y0)| {
            let input = tile_input(
                source,
                (x0, y0, tile_w, tile_h),
                padded,
                &settings.preprocess,
            );
            model.run(input, padded.0, padded.1, photo)
        })
        .collect::<Result<_, _>>()?;
    let channels = model.channels();
    let plane = width as usize * height as usize;
    let mut sums = vec![0.0f32; channels * plane];
    let mut weights = vec![0.0f32; plane];
    let padded_plane = padded.0 as usize * padded.1 as usize;
    let mut pixel = vec![0.0f32; channels];
    for (&(x0, y0), output) in tiles.iter().zip(&outputs) {
        let window_x = tiling.window(x0, tile_w, width);
        let window_y = tiling.window(y0, tile_h, height);
        for (y, weight_y) in window_y.iter().enumerate() {
            for (x, weight_x) in window_x.iter().enumerate() {
                let at_tile = y * padded.0 as usize + x;
                for (c, v) in pixel.iter_mut().enumerate() {
                    *v = output[c * padded_plane + at_tile];
                }
                settings.preprocess.activate(&mut pixel);
                let weight = weight_x * weight_y;
                let at = (y0 as usize + y) * width as usize + x0 as usize + x;
                weights[at] += weight;
                for (c, v) in pixel.iter().enumerate() {
                    sums[c * plane + at] += weight * v;
                }
            }
        }
    }
    let maps = (0..channels)
        .map(|c| {
            let data: Vec<f32> = sums[c * plane..(c + 1) * plane]
                .iter()
                .zip(&weights)
                .map(|(s, w)| (s / w).clamp(0.0, 1.0))
                .collect();
            resized(
                ProbabilityMap {
                    width,
                    height,
                    data,
                },
                image.width,
                image.height,
            )
        })
        .collect();
    Ok(maps)
}

/// `map` at `width × height`, bilinear (a no-op at its own size).
fn resized(map: ProbabilityMap, width: u32, height: u32) -> ProbabilityMap {
    if (map.width, map.height) == (width, height) {
        return map;
    }
    let (w, h) = (map.width, map.height);
    let Some(buffer) = image::ImageBuffer::<image::Luma<f32>, Vec<f32>>::from_raw(w, h, map.data)
    else {
        // Unreachable: the buffer was built with w · h values; an empty map keeps the size.
        return ProbabilityMap {
            width,
            height,
            data: vec![0.0; width as usize * height as usize],
        };
    };
    let out = image::imageops::resize(
        &buffer,
        width,
        height,
        image::imageops::FilterType::Triangle,
    );
    ProbabilityMap {
        width,
        height,
        data: out
            .into_raw()
            .into_iter()
            .map(|v| v.clamp(0.0, 1.0))
            .collect(),
    }
}
