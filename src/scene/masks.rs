//! Damage masks on disk: per-class binary PNGs `masks/<class>/<stem>.png` and QuakeCity-style
//! colour-coded masks `masks/<stem>.png`; counting, loading, decoding, nearest-neighbour resizing.
//! Knows nothing of cameras or training; never guesses a class for an uncoloured mask.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::scene::DamageClass;
use crate::scene::files::{EntryBudget, is_present, list_dir};
use crate::scene::limits::MAX_LISTED_ENTRIES;
use crate::scene::load::decode;
use crate::scene::{Mask, SceneError};

/// Largest Euclidean RGB distance at which a colour-coded pixel still counts as a palette colour.
/// 40 covers JPEG-ish noise and anti-aliased edges near a class colour while staying well below
/// the smallest palette distance (spalling (255,192,203) to rebar (255,255,50): 165).
pub const COLOUR_TOLERANCE: f32 = 40.0;

/// Pixel-count floor below which a colour-coded mask does not count a class as present (a few
/// stray anti-aliased pixels must not add a class to `count_masks`).
const MIN_PRESENT_PIXELS: usize = 1;

fn is_png(path: &Path) -> bool {
    path.is_file()
        && path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| e.eq_ignore_ascii_case("png"))
}

/// PNG files directly in `dir`, sorted, within the entry budget; an unreadable or missing folder
/// gives none.
fn png_files(dir: &Path, budget: &mut EntryBudget) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = list_dir(dir, budget)
        .into_iter()
        .filter(|p| is_png(p))
        .collect();
    files.sort();
    files
}

/// Counts mask files per class: every `masks/<class>/*.png` counts once for its class, and every
/// colour-coded `masks/*.png` counts once for each class colour present in it (so the root-level
/// masks are decoded: cost grows with their pixel count; rayon spreads it over the cores).
/// Root-level masks that cannot be decoded, or are single-channel (no class), count for nothing —
/// `load_masks` reports them as errors when a view is loaded. A missing folder counts nothing.
/// At most `limits::MAX_LISTED_ENTRIES` folder entries are looked at.
pub fn count_masks(masks_dir: &Path) -> BTreeMap<DamageClass, usize> {
    count_masks_within(masks_dir, &mut EntryBudget::new(MAX_LISTED_ENTRIES))
}

/// [`count_masks`] looking at no more folder entries than `budget` has left.
pub(crate) fn count_masks_within(
    masks_dir: &Path,
    budget: &mut EntryBudget,
) -> BTreeMap<DamageClass, usize> {
    use rayon::prelude::*;
    let mut counts = BTreeMap::new();
    for class in DamageClass::ALL {
        let n = png_files(&masks_dir.join(class.id()), budget).len();
        if n > 0 {
            counts.insert(class, n);
        }
    }
    let present: Vec<[bool; 3]> = png_files(masks_dir, budget)
        .into_iter()
        .filter(|path| !is_ignore_mask_name(path))
        .collect::<Vec<_>>()
        .par_iter()
        .filter_map(|path| read_colour_mask_classes(path).ok())
        .collect();
    for flags in present {
        for class in DamageClass::ALL {
            if flags[class.channel()] {
                *counts.entry(class).or_insert(0) += 1;
            }
        }
    }
    counts
}

/// `01.jpg.png`: an ignore mask by COLMAP's naming (an image file name plus `.png`), not a
/// colour-coded damage mask.
fn is_ignore_mask_name(path: &Path) -> bool {
    path.file_stem()
        .map(Path::new)
        .and_then(|stem| stem.extension())
        .and_then(|e| e.to_str())
        .is_some_and(|e| {
            ["jpg", "jpeg", "png", "tif", "tiff", "bmp", "webp"]
                .iter()
                .any(|x| e.eq_ignore_ascii_case(x))
        })
}

/// Which classes a colour-coded mask file contains.
fn read_colour_mask_classes(path: &Path) -> Result<[bool; 3], SceneError> {
    let masks = read_colour_mask(path, &default_palette())?;
    let mut present = [false; 3];
    for (class, mask) in masks {
        present[class.channel()] = mask.count() >= MIN_PRESENT_PIXELS;
    }
    Ok(present)
}

/// The class palette of colour-coded masks: `DamageClass::default_colour` per class.
pub fn default_palette() -> BTreeMap<DamageClass, [u8; 3]> {
    DamageClass::ALL
        .into_iter()
        .map(|c| (c, c.default_colour()))
        .collect()
}

/// Reads a per-class binary mask: a pixel is damage when any colour channel is above 127 (8-bit)
/// or above 32767 (16-bit), so 0/255 and 0/1·65535 masks both work. Alpha is ignored — except that a
/// fully transparent pixel is background, so RGBA masks drawn on a transparent layer work.
/// 0/1-valued 8-bit masks are also accepted: when the maximum is 1 the threshold is 0.
pub fn read_binary_mask(path: &Path) -> Result<Mask, SceneError> {
    Ok(binary_mask(&decode(path)?))
}

/// `read_binary_mask` on a decoded image. An 8-bit grey mask (what `save_mask_png` writes and
/// what the demo's masks are) is read from its bytes, widened as the `image` crate widens u8 to
/// u16 (`v · 257`, opaque): its own `to_rgba16` takes a grey image through 32-bit float RGB and
/// cost a dense survey's update about a fifth of its CPU, reading every view's masks in each
/// phase (docs/TIMELINE.md). Every other layout goes through `to_rgba16`.
fn binary_mask(img: &image::DynamicImage) -> Mask {
    let (width, height) = (img.width(), img.height());
    let data = match img {
        image::DynamicImage::ImageLuma8(grey) => {
            let opaque_grey = |&v: &u8| {
                let wide = u16::from(v) * 257;
                [wide, wide, wide, u16::MAX]
            };
            threshold_rgba16(grey.as_raw().iter().map(opaque_grey))
        }
        _ => {
            let rgba = img.to_rgba16();
            let pixel = |p: &[u16]| [p[0], p[1], p[2], p[3]];
            threshold_rgba16(rgba.as_raw().chunks_exact(4).map(pixel))
        }
    };
    Mask {
        width,
        height,
        data,
    }
}

/// The binary mask of 16-bit RGBA pixels (`read_binary_mask`'s rule): set where opaque at all
/// and the brightest channel is above half, or above 0 when no channel exceeds 257 (a 0/1 mask).
fn threshold_rgba16(pixels: impl Iterator<Item = [u16; 4]> + Clone) -> Vec<u8> {
    let max = pixels
        .clone()
        .map(|p| p[0].max(p[1]).max(p[2]))
        .max()
        .unwrap_or(0);
    // 0/1 masks (numpy `astype(uint8)` without ×255) widen to 0/257 in 16-bit.
    let threshold = if max <= 257 { 0 } else { 32767 };
    pixels
        .map(|p| u8::from(p[3] > 0 && p[0].max(p[1]).max(p[2]) > threshold))
        .collect()
}

/// Decodes a colour-coded mask: each pixel goes to the palette colour nearest to it when within
/// `COLOUR_TOLERANCE`, else (black, anti-aliasing, other colours) to background. Returns one mask
/// per palette class (possibly empty). A single-channel (grey) image has no colours and is refused:
/// it belongs in `masks/<class>/`.
pub fn read_colour_mask(
    path: &Path,
    palette: &BTreeMap<DamageClass, [u8; 3]>,
) -> Result<BTreeMap<DamageClass, Mask>, SceneError> {
    let img = decode(path)?;
    if !img.color().has_color() {
        return Err(SceneError::invalid(
            path,
            "a grey single-channel mask directly in masks/ has no class colours; \
             put per-class binary masks in masks/<class>/",
        ));
    }
    let (width, height) = (img.width(), img.height());
    let rgba = img.to_rgba8();
    let classes: Vec<(DamageClass, [f32; 3])> = palette
        .iter()
        .map(|(&c, rgb)| (c, rgb.map(f32::from)))
        .collect();
    let mut masks: BTreeMap<DamageClass, Mask> = palette
        .keys()
        .map(|&c| (c, Mask::empty(width, height)))
        .collect();
    let tol2 = COLOUR_TOLERANCE * COLOUR_TOLERANCE;
    for (i, p) in rgba.as_raw().chunks_exact(4).enumerate() {
        if p[3] == 0 || (p[0] == 0 && p[1] == 0 && p[2] == 0) {
            continue;
        }
        let rgb = [p[0], p[1], p[2]].map(f32::from);
        let mut best: Option<(DamageClass, f32)> = None;
        for &(class, c) in &classes {
            let d2 = (rgb[0] - c[0]).powi(2) + (rgb[1] - c[1]).powi(2) + (rgb[2] - c[2]).powi(2);
            if d2 <= tol2 && best.is_none_or(|(_, b)| d2 < b) {
                best = Some((class, d2));
            }
        }
        if let Some((class, _)) = best
            && let Some(mask) = masks.get_mut(&class)
        {
            mask.data[i] = 1;
        }
    }
    Ok(masks)
}

/// Where an image's ignore mask is by COLMAP's convention (OpenSfM writes the same):
/// `masks/<image file name>.png`, beside the damage masks' class folders (for `images/a/01.jpg`,
/// stem `a/01`: `masks/a/01.jpg.png`). None when there is none.
pub fn ignore_mask_path(masks_dir: &Path, stem: &str, image_path: &Path) -> Option<PathBuf> {
    let file = image_path.file_name()?.to_str()?;
    let folder = Path::new(stem).parent().unwrap_or(Path::new(""));
    let path = masks_dir.join(folder).join(format!("{file}.png"));
    // Anything there is the mask: a folder or a pipe in its place is refused when it is read.
    is_present(&path).then_some(path)
}

/// An image's ignore mask at `path` (1 = use the pixel, 0 = ignore it: a pedestrian, a car, the
/// sky); refused when its size is not the image's.
pub fn read_ignore_mask(
    path: &Path,
    image_path: &Path,
    image_size: (u32, u32),
) -> Result<Mask, SceneError> {
    let mask = read_binary_mask(path)?;
    if (mask.width, mask.height) != image_size {
        return Err(SceneError::invalid(
            path,
            format!(
                "ignore mask is {}×{} but its image {} is {}×{}",
                mask.width,
                mask.height,
                image_path.display(),
                image_size.0,
                image_size.1
            ),
        ));
    }
    Ok(mask)
}

/// The masks of the view whose image file stem is `stem`, at the stored image size: per-class
/// `masks_dir/<class>/<stem>.png` and, OR-ed into them, a colour-coded `masks_dir/<stem>.png`.
/// Classes without a mask file are absent from the map. A mask whose size differs from the
/// image's (`image_size`, before any scaling) is an error naming both files. `ignore_mask`, the
/// view's ignore mask when the dataset names one (nerfstudio keeps them as `masks/<stem>.png`),
/// is not read as a colour-coded damage mask.
pub fn read_view_masks(
    masks_dir: &Path,
    stem: &str,
    image_path: &Path,
    image_size: (u32, u32),
    ignore_mask: Option<&Path>,
) -> Result<BTreeMap<DamageClass, Mask>, SceneError> {
    let file = format!("{stem}.png");
    let check = |path: &Path, mask: &Mask| -> Result<(), SceneError> {
        if (mask.width, mask.height) != image_size {
            return Err(SceneError::invalid(
                path,
                format!(
                    "mask is {}×{} but its image {} is {}×{}",
                    mask.width,
                    mask.height,
                    image_path.display(),
                    image_size.0,
                    image_size.1
                ),
            ));
        }
        Ok(())
    };
    let mut masks = BTreeMap::new();
    for class in DamageClass::ALL {
        let path = masks_dir.join(class.id()).join(&file);
        // Anything there is the mask (`read_binary_mask` refuses a folder, a FIFO or a dangling
        // link naming it); only nothing at all means the view has no mask of this class.
        if is_present(&path) {
            let mask = read_binary_mask(&path)?;
            check(&path, &mask)?;
            masks.insert(class, mask);
        }
    }
    let coded = masks_dir.join(&file);
    if is_present(&coded) && ignore_mask != Some(coded.as_path()) {
        for (class, mask) in read_colour_mask(&coded, &default_palette())? {
            check(&coded, &mask)?;
            match masks.get_mut(&class) {
                Some(existing) => {
                    for (a, b) in existing.data.iter_mut().zip(&mask.data) {
                        *a |= *b;
                    }
                }
                None => {
                    masks.insert(class, mask);
                }
            }
        }
    }
    Ok(masks)
}

/// Resizes a 0/1 mask for training and evaluation at a lower resolution: a downscaled pixel is
/// damage when any source pixel under its footprint is, so a 1-pixel crack stays a connected
/// 1-pixel line at half size instead of breaking into dashes (nearest-neighbour keeps or drops
/// whole rows and columns). Upscaling (and the same size) is nearest-neighbour.
pub fn resize_mask(mask: &Mask, width: u32, height: u32) -> Mask {
    let (sw, sh) = (mask.width as usize, mask.height as usize);
    let (w, h) = (width as usize, height as usize);
    if w >= sw || h >= sh || w == 0 || h == 0 {
        return resize_mask_nearest(mask, width, height);
    }
    // Footprint of output pixel i: source [floor(i·s/w), ceil((i+1)·s/w)).
    let span = |i: usize, source: usize, target: usize| {
        let start = i * source / target;
        let end = ((i + 1) * source).div_ceil(target).clamp(start + 1, source);
        start..end
    };
    let mut out = Mask::empty(width, height);
    let mut row = vec![0u8; w];
    for y in 0..h {
        row.fill(0);
        for sy in span(y, sh, h) {
            let src = &mask.data[sy * sw..(sy + 1) * sw];
            for (x, r) in row.iter_mut().enumerate() {
                if *r == 0 && span(x, sw, w).any(|sx| src[sx] != 0) {
                    *r = 1;
                }
            }
        }
        out.data[y * w..(y + 1) * w].copy_from_slice(&row);
    }
    out
}

/// Nearest-neighbour resize (pixel centres at +0.5, as in image resamplers), keeping 0/1 labels.
pub fn resize_mask_nearest(mask: &Mask, width: u32, height: u32) -> Mask {
    if (mask.width, mask.height) == (width, height) {
        return mask.clone();
    }
    let (sw, sh) = (mask.width as usize, mask.height as usize);
    let mut out = Mask::empty(width, height);
    if sw == 0 || sh == 0 {
        return out;
    }
    let xs: Vec<usize> = (0..width as usize)
        .map(|x| (((x as f64 + 0.5) * sw as f64 / width as f64) as usize).min(sw - 1))
        .collect();
    for y in 0..height as usize {
        let sy = (((y as f64 + 0.5) * sh as f64 / height as f64) as usize).min(sh - 1);
        let src = &mask.data[sy * sw..(sy + 1) * sw];
        let dst = &mut out.data[y * width as usize..(y + 1) * width as usize];
        for (d, &sx) in dst.iter_mut().zip(&xs) {
            *d = src[sx];
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The grey fast path against `to_rgba16`'s (the plain path): every grey level, in a 0..255
    /// mask and in a 0/1 mask.
    #[test]
    fn grey_masks_read_as_the_plain_path_reads_them() {
        let plain = |img: &image::DynamicImage| {
            let rgba = image::DynamicImage::ImageRgba16(img.to_rgba16());
            binary_mask(&rgba)
        };
        let levels: Vec<u8> = (0..=255).collect();
        let grey = image::GrayImage::from_raw(16, 16, levels).expect("16×16 levels");
        let grey = image::DynamicImage::ImageLuma8(grey);
        let fast = binary_mask(&grey);
        assert_eq!(fast, plain(&grey));
        assert_eq!(fast.data.iter().filter(|&&v| v != 0).count(), 128);
        let ones = image::GrayImage::from_raw(2, 2, vec![0, 1, 1, 0]).expect("2×2");
        let ones = image::DynamicImage::ImageLuma8(ones);
        assert_eq!(binary_mask(&ones), plain(&ones));
        assert_eq!(binary_mask(&ones).data, vec![0, 1, 1, 0]);
    }

    #[test]
    fn downscaled_masks_keep_thin_lines_connected() {
        // A 1-pixel diagonal at even positions: nearest-neighbour at half size samples the odd
        // pixels (centres at +0.5) only and loses it completely.
        let mut mask = Mask::empty(8, 8);
        for i in 0..4 {
            mask.data[2 * i * 8 + 2 * i] = 1;
        }
        assert!(
            resize_mask_nearest(&mask, 4, 4)
                .data
                .iter()
                .all(|&v| v == 0)
        );
        let half = resize_mask(&mask, 4, 4);
        for y in 0..4 {
            for x in 0..4 {
                assert_eq!(half.data[y * 4 + x], u8::from(x == y), "pixel {x},{y}");
            }
        }
        // Non-integer factors cover every source pixel; upscaling is nearest-neighbour.
        let odd = resize_mask(&mask, 3, 3);
        assert!((0..3).all(|i| odd.data[i * 3 + i] != 0));
        assert_eq!(resize_mask(&half, 8, 8), resize_mask_nearest(&half, 8, 8));
    }

    fn write_rgb(path: &Path, w: u32, h: u32, f: impl Fn(u32, u32) -> [u8; 3]) {
        let img = image::RgbImage::from_fn(w, h, |x, y| image::Rgb(f(x, y)));
        img.save(path).unwrap();
    }

    #[test]
    fn colour_coded_mask_decodes_each_palette_class_and_ignores_black() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.png");
        // Columns: black, crack red, spalling pink (slightly off), rebar yellow, grey (no class).
        write_rgb(&path, 5, 2, |x, _| match x {
            0 => [0, 0, 0],
            1 => [255, 0, 0],
            2 => [250, 190, 200],
            3 => [255, 255, 50],
            _ => [128, 128, 128],
        });
        let masks = read_colour_mask(&path, &default_palette()).unwrap();
        assert_eq!(
            masks[&DamageClass::Crack].data,
            [0, 1, 0, 0, 0, 0, 1, 0, 0, 0]
        );
        assert_eq!(
            masks[&DamageClass::Spalling].data,
            [0, 0, 1, 0, 0, 0, 0, 1, 0, 0]
        );
        assert_eq!(
            masks[&DamageClass::Rebar].data,
            [0, 0, 0, 1, 0, 0, 0, 0, 1, 0]
        );
    }

    #[test]
    fn binary_masks_threshold_grey_and_accept_zero_one_values() {
        let dir = tempfile::tempdir().unwrap();
        let grey = dir.path().join("g.png");
        image::GrayImage::from_raw(3, 1, vec![0, 127, 200])
            .unwrap()
            .save(&grey)
            .unwrap();
        assert_eq!(read_binary_mask(&grey).unwrap().data, [0, 0, 1]);
        let ones = dir.path().join("o.png");
        image::GrayImage::from_raw(3, 1, vec![0, 1, 1])
            .unwrap()
            .save(&ones)
            .unwrap();
        assert_eq!(read_binary_mask(&ones).unwrap().data, [0, 1, 1]);
    }

    #[test]
    fn count_masks_counts_class_folders_and_colour_coded_files() {
        let dir = tempfile::tempdir().unwrap();
        let masks = dir.path();
        std::fs::create_dir_all(masks.join("crack")).unwrap();
        std::fs::create_dir_all(masks.join("rebar")).unwrap();
        for stem in ["a", "b"] {
            image::GrayImage::new(4, 4)
                .save(masks.join("crack").join(format!("{stem}.png")))
                .unwrap();
        }
        image::GrayImage::new(4, 4)
            .save(masks.join("rebar/a.png"))
            .unwrap();
        // One colour-coded mask with spalling and crack pixels.
        write_rgb(&masks.join("c.png"), 4, 4, |x, _| match x {
            0 => [255, 192, 203],
            1 => [255, 0, 0],
            _ => [0, 0, 0],
        });
        std::fs::write(masks.join("notes.txt"), "not a mask").unwrap();
        let counts = count_masks(masks);
        assert_eq!(counts.get(&DamageClass::Crack), Some(&3));
        assert_eq!(counts.get(&DamageClass::Spalling), Some(&1));
        assert_eq!(counts.get(&DamageClass::Rebar), Some(&1));
        assert!(count_masks(&masks.join("missing")).is_empty());
    }

    #[test]
    fn wrong_size_mask_names_both_files() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(dir.path().join("crack")).unwrap();
        image::GrayImage::new(4, 3)
            .save(dir.path().join("crack/v.png"))
            .unwrap();
        let image = Path::new("/data/images/v.jpg");
        let err = read_view_masks(dir.path(), "v", image, (8, 6), None)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("crack/v.png") && err.contains("/data/images/v.jpg"),
            "{err}"
        );
        let ok = read_view_masks(dir.path(), "v", image, (4, 3), None).unwrap();
        assert_eq!(ok.len(), 1);
    }

    #[test]
    fn nearest_resize_picks_source_pixels() {
        let mask = Mask {
            width: 4,
            height: 2,
            data: vec![1, 0, 0, 1, 0, 1, 1, 0],
        };
        let half = resize_mask_nearest(&mask, 2, 1);
        // Centres of output pixels map to source x = 1 and 3 (row 1).
        assert_eq!(half.data, [1, 0]);
        let up = resize_mask_nearest(&mask, 8, 4);
        assert_eq!(up.count(), mask.count() * 4);
    }
}
