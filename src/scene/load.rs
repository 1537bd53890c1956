//! Loading a view's pixels: decode (PNG/JPEG), composite RGBA on the dataset background,
//! undistort to the view's pinhole, resize to the requested scale with its camera and masks.
//! Also the image/mask save helpers. No dataset discovery (that is `open`), no training logic.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use crate::scene::DamageClass;
use crate::scene::atomic::write_atomic;
use crate::scene::limits::{MAX_IMAGE_SIDE, check_image_size};
use crate::scene::mask_source::MaskSource;
use crate::scene::masks::{read_ignore_mask, resize_mask};
use crate::scene::undistort::{undistort_mask, undistort_rgb};
use crate::scene::{
    Camera, Dataset, Distortion, ImageScale, LoadedView, Mask, RgbImage, SceneError, View,
};

/// Decodes an image or mask file: a regular file only, its header's size within
/// `limits::check_image_size` before any pixel buffer is allocated, and the decoder's own
/// allocation limit (the `image` crate's default, 512 MiB) kept.
pub(crate) fn decode(path: &Path) -> Result<image::DynamicImage, SceneError> {
    let file = crate::scene::files::open_regular(path)?;
    let mut reader = image::ImageReader::new(std::io::BufReader::new(file))
        .with_guessed_format()
        .map_err(|e| SceneError::io(path, e))?;
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_IMAGE_SIDE);
    limits.max_image_height = Some(MAX_IMAGE_SIDE);
    reader.limits(limits);
    let cannot =
        |e: image::ImageError| SceneError::invalid(path, format!("cannot decode image: {e}"));
    let decoder = reader.into_decoder().map_err(cannot)?;
    let (width, height) = image::ImageDecoder::dimensions(&decoder);
    check_image_size(u64::from(width), u64::from(height))
        .map_err(|m| SceneError::invalid(path, m))?;
    image::DynamicImage::from_decoder(decoder).map_err(cannot)
}

/// Loads an image as RGB in `[0, 1]`; an alpha channel is composited on `background`
/// (`rgb · a + background · (1 − a)`, as NeRF-synthetic loaders do). 16-bit images keep their
/// precision.
pub fn load_image_with_background(
    path: &Path,
    background: [f32; 3],
) -> Result<RgbImage, SceneError> {
    let img = decode(path)?;
    let (width, height) = (img.width(), img.height());
    let data = if img.color().has_alpha() {
        let rgba = img.to_rgba32f();
        let mut data = Vec::with_capacity(width as usize * height as usize * 3);
        for p in rgba.as_raw().chunks_exact(4) {
            let a = p[3];
            for (&v, &bg) in p[..3].iter().zip(&background) {
                data.push(v * a + bg * (1.0 - a));
            }
        }
        data
    } else {
        img.to_rgb32f().into_raw()
    };
    Ok(RgbImage {
        width,
        height,
        data,
    })
}

/// Loads an image as RGB in `[0, 1]`, compositing any alpha on black.
pub fn load_image(path: &Path) -> Result<RgbImage, SceneError> {
    load_image_with_background(path, [0.0; 3])
}

/// Encodes `image` as PNG in memory and writes it atomically (`atomic::write_atomic`), so a
/// failed save never leaves half a file under `path`.
fn write_png_atomic<P>(
    path: &Path,
    image: &image::ImageBuffer<P, Vec<u8>>,
) -> Result<(), SceneError>
where
    P: image::PixelWithColorType<Subpixel = u8>,
{
    let mut bytes = std::io::Cursor::new(Vec::new());
    image
        .write_to(&mut bytes, image::ImageFormat::Png)
        .map_err(|e| SceneError::invalid(path, format!("cannot write PNG: {e}")))?;
    write_atomic(path, |w| {
        use std::io::Write;
        w.write_all(bytes.get_ref())
    })
}

/// Saves an image as 8-bit RGB PNG (values clamped to `[0, 1]`), atomically.
pub fn save_png(path: &Path, image: &RgbImage) -> Result<(), SceneError> {
    if image.data.len() != image.pixel_count() * 3 {
        return Err(SceneError::invalid(
            path,
            format!(
                "cannot save a {}×{} image holding {} values",
                image.width,
                image.height,
                image.data.len()
            ),
        ));
    }
    write_png_atomic(path, &image.to_rgb8())
}

/// Saves a mask as an 8-bit grey PNG, 255 where set (the per-class mask format it reads back),
/// atomically.
pub fn save_mask_png(path: &Path, mask: &Mask) -> Result<(), SceneError> {
    let bytes = mask
        .data
        .iter()
        .map(|&v| if v != 0 { 255 } else { 0 })
        .collect();
    save_grey_png(path, mask.width, mask.height, bytes)
}

/// Saves `width × height` 8-bit grey values (row-major) as a PNG, atomically.
pub fn save_grey_png(
    path: &Path,
    width: u32,
    height: u32,
    values: Vec<u8>,
) -> Result<(), SceneError> {
    let count = values.len();
    let img = image::GrayImage::from_raw(width, height, values).ok_or_else(|| {
        SceneError::invalid(
            path,
            format!("cannot save a {width}×{height} grey image holding {count} values"),
        )
    })?;
    write_png_atomic(path, &img)
}

/// Resizes an image. An exact integer downscale (both axes by the same `f`) averages each
/// `f × f` block (a box filter: exact area averaging, what downscaled 3DGS datasets amount to);
/// any other size uses a triangle (bilinear, widened when shrinking) filter.
pub fn resize_rgb(image: &RgbImage, width: u32, height: u32) -> RgbImage {
    let (sw, sh) = (image.width, image.height);
    if (sw, sh) == (width, height) {
        return image.clone();
    }
    if width > 0 && height > 0 && sw % width == 0 && sh % height == 0 && sw / width == sh / height {
        return box_downscale(image, sw / width);
    }
    let Some(buffer) =
        image::ImageBuffer::<image::Rgb<f32>, Vec<f32>>::from_raw(sw, sh, image.data.clone())
    else {
        return RgbImage::filled(width, height, [0.0; 3]);
    };
    let resized = image::imageops::resize(
        &buffer,
        width,
        height,
        image::imageops::FilterType::Triangle,
    );
    RgbImage {
        width,
        height,
        data: resized.into_raw(),
    }
}

fn box_downscale(image: &RgbImage, f: u32) -> RgbImage {
    let f = f as usize;
    let (sw, w, h) = (
        image.width as usize,
        image.width as usize / f,
        image.height as usize / f,
    );
    let mut data = vec![0.0f32; w * h * 3];
    let norm = 1.0 / (f * f) as f32;
    for y in 0..h {
        for x in 0..w {
            let mut acc = [0.0f32; 3];
            for dy in 0..f {
                let row = (y * f + dy) * sw;
                for dx in 0..f {
                    let i = (row + x * f + dx) * 3;
                    acc[0] += image.data[i];
                    acc[1] += image.data[i + 1];
                    acc[2] += image.data[i + 2];
                }
            }
            let o = (y * w + x) * 3;
            for (d, a) in data[o..o + 3].iter_mut().zip(acc) {
                *d = a * norm;
            }
        }
    }
    RgbImage {
        width: w as u32,
        height: h as u32,
        data,
    }
}

/// The integer factor by which an image of `image` size is a downscaled copy of one of `camera`
/// size (COLMAP's `images_2/4/8` folders beside a full-resolution model), within the one pixel
/// that rounding an odd size allows.
fn downscale_factor(camera: (u32, u32), image: (u32, u32)) -> Option<u32> {
    [2u32, 4, 8].into_iter().find(|&f| {
        let close = |full: u32, small: u32| {
            (i64::from(small) * i64::from(f) - i64::from(full)).abs() < i64::from(f)
        };
        close(camera.0, image.0) && close(camera.1, image.1)
    })
}

fn scale_distortion(d: &Distortion, sx: f32, sy: f32) -> Distortion {
    Distortion {
        fx: d.fx * sx,
        fy: d.fy * sy,
        cx: d.cx * sx,
        cy: d.cy * sy,
        ..*d
    }
}

impl Dataset {
    /// Loads view `index` at `scale`: pixels (alpha composited on `self.background`),
    /// undistorted when the view has a distortion, resized, with the camera resized to match and
    /// the view's damage masks (a downscaled pixel is damage when any pixel under it is). An image
    /// whose size disagrees with its camera is an error naming the file — unless it is the
    /// camera's size divided by 2, 4 or 8 (a pre-downscaled copy), in which case the intrinsics
    /// are scaled to the image.
    ///
    /// With `keep_loaded_views` the view is read once per scale and a copy of the kept view
    /// returned.
    pub fn load_view(&self, index: usize, scale: ImageScale) -> Result<LoadedView, SceneError> {
        let Some(cache) = &self.view_cache else {
            return self.read_view(index, scale);
        };
        if let Some(kept) = cache.view(index, scale) {
            return Ok(kept.as_ref().clone());
        }
        let loaded = self.read_view(index, scale)?;
        cache.keep_view(index, scale, Arc::new(loaded.clone()));
        Ok(loaded)
    }

    /// `load_view` from the files.
    fn read_view(&self, index: usize, scale: ImageScale) -> Result<LoadedView, SceneError> {
        let view = self.view(index)?;
        let mut image = load_image_with_background(&view.image_path, self.background)?;
        let stored = (image.width, image.height);
        let (camera, distortion) = stored_geometry(view, stored)?;
        if let Some(d) = &distortion {
            image = undistort_rgb(&image, d, &camera.intrinsics);
        }
        let (width, height) = loaded_size(view, scale, stored)?;
        let masks = match &self.masks {
            Some(source) => read_masks_at(
                source.as_ref(),
                view,
                stored,
                &camera,
                distortion.as_ref(),
                (width, height),
            )?,
            None => Default::default(),
        };
        let ignore = self
            .read_ignore(view, stored)?
            .map(|mask| prepared_mask(mask, &camera, distortion.as_ref(), (width, height)));
        Ok(LoadedView {
            name: view.name.clone(),
            camera: Camera::resized(&camera, width, height),
            image: resize_rgb(&image, width, height),
            masks,
            ignore,
        })
    }

    /// The damage masks of view `index` read from `source` (the dataset's own `masks`, or
    /// another source such as a synthetic survey's clean `truth/masks/`), prepared exactly as
    /// `load_view` prepares the dataset's own: checked against the stored image size,
    /// undistorted, resized to `scale`. Reads only the image's header, not its pixels. Returns
    /// the camera at `scale` with them. With `keep_loaded_views`, the dataset's own masks are
    /// read once per scale (or taken from the view loaded whole at that scale).
    pub fn load_view_masks(
        &self,
        index: usize,
        source: &dyn MaskSource,
        scale: ImageScale,
    ) -> Result<(Camera, BTreeMap<DamageClass, Mask>), SceneError> {
        let cache = self
            .view_cache
            .as_ref()
            .filter(|_| self.is_own_mask_source(source));
        let Some(cache) = cache else {
            return self.read_view_masks(index, source, scale);
        };
        if let Some(kept) = cache.masks(index, scale) {
            return Ok(kept);
        }
        let read = self.read_view_masks(index, source, scale)?;
        cache.keep_masks(index, scale, read.clone());
        Ok(read)
    }

    /// Whether `source` is the dataset's own mask source (`masks`), the one `load_view` reads.
    fn is_own_mask_source(&self, source: &dyn MaskSource) -> bool {
        self.masks
            .as_ref()
            .is_some_and(|own| std::ptr::addr_eq(Arc::as_ptr(own), source))
    }

    /// `load_view_masks` from the files.
    fn read_view_masks(
        &self,
        index: usize,
        source: &dyn MaskSource,
        scale: ImageScale,
    ) -> Result<(Camera, BTreeMap<DamageClass, Mask>), SceneError> {
        let view = self.view(index)?;
        let stored = crate::scene::files::image_size(&view.image_path)?;
        let (camera, distortion) = stored_geometry(view, stored)?;
        let (width, height) = loaded_size(view, scale, stored)?;
        let masks = read_masks_at(
            source,
            view,
            stored,
            &camera,
            distortion.as_ref(),
            (width, height),
        )?;
        Ok((Camera::resized(&camera, width, height), masks))
    }

    /// View `index`'s ignore mask at `scale`, prepared as `load_view` prepares it (None when
    /// the view has none). Reads only the image's header besides the mask.
    pub fn load_view_ignore(
        &self,
        index: usize,
        scale: ImageScale,
    ) -> Result<Option<Mask>, SceneError> {
        let view = self.view(index)?;
        if !self.has_ignore_mask(view) {
            return Ok(None);
        }
        if let Some(kept) = self.view_cache.as_ref().and_then(|c| c.view(index, scale)) {
            return Ok(kept.ignore.clone());
        }
        let stored = crate::scene::files::image_size(&view.image_path)?;
        let (camera, distortion) = stored_geometry(view, stored)?;
        let size = loaded_size(view, scale, stored)?;
        Ok(self
            .read_ignore(view, stored)?
            .map(|mask| prepared_mask(mask, &camera, distortion.as_ref(), size)))
    }

    /// View `view`'s ignore mask at its stored size `stored`: the file the dataset names for it,
    /// else the mask source's.
    fn read_ignore(&self, view: &View, stored: (u32, u32)) -> Result<Option<Mask>, SceneError> {
        match (&view.ignore_mask, &self.masks) {
            (Some(path), _) => read_ignore_mask(path, &view.image_path, stored).map(Some),
            (None, Some(source)) => source.ignore_mask(view, stored),
            (None, None) => Ok(None),
        }
    }

    /// View `index`'s camera at `scale`, as `load_view` would give it, from the image's header
    /// alone (no pixels, no masks).
    pub fn view_camera(&self, index: usize, scale: ImageScale) -> Result<Camera, SceneError> {
        let view = self.view(index)?;
        let stored = crate::scene::files::image_size(&view.image_path)?;
        let (camera, _) = stored_geometry(view, stored)?;
        let (width, height) = loaded_size(view, scale, stored)?;
        Ok(Camera::resized(&camera, width, height))
    }

    fn view(&self, index: usize) -> Result<&View, SceneError> {
        self.views.get(index).ok_or_else(|| {
            SceneError::invalid(
                &self.root,
                format!("view {index} does not exist ({} views)", self.views.len()),
            )
        })
    }
}

/// The size a view's image is loaded at: `scale` applied to the stored size, refused (naming the
/// image) when it would upscale the image or exceed the size limits.
fn loaded_size(
    view: &View,
    scale: ImageScale,
    stored: (u32, u32),
) -> Result<(u32, u32), SceneError> {
    scale
        .checked_apply(stored.0, stored.1)
        .map_err(|m| SceneError::invalid(&view.image_path, m))
}

/// The view's camera and distortion for its image as stored (`stored` = width, height): as given
/// when the sizes agree, scaled for a copy pre-downscaled by 2, 4 or 8, else an error naming the
/// image.
pub(crate) fn stored_geometry(
    view: &View,
    stored: (u32, u32),
) -> Result<(Camera, Option<Distortion>), SceneError> {
    let k = view.camera.intrinsics;
    if stored == (k.width, k.height) {
        return Ok((view.camera, view.distortion));
    }
    if downscale_factor((k.width, k.height), stored).is_none() {
        return Err(SceneError::invalid(
            &view.image_path,
            format!(
                "image is {}×{} but its camera is {}×{}",
                stored.0, stored.1, k.width, k.height
            ),
        ));
    }
    let (sx, sy) = (
        stored.0 as f32 / k.width as f32,
        stored.1 as f32 / k.height as f32,
    );
    Ok((
        view.camera.resized(stored.0, stored.1),
        view.distortion.map(|d| scale_distortion(&d, sx, sy)),
    ))
}

/// The view's masks from `source` at the stored image size, undistorted with the stored-size
/// camera, then resized to `size`.
fn read_masks_at(
    source: &dyn MaskSource,
    view: &View,
    stored: (u32, u32),
    camera: &Camera,
    distortion: Option<&Distortion>,
    size: (u32, u32),
) -> Result<BTreeMap<DamageClass, Mask>, SceneError> {
    let masks = source.damage_masks(view, stored)?;
    Ok(masks
        .into_iter()
        .map(|(class, mask)| (class, prepared_mask(mask, camera, distortion, size)))
        .collect())
}

/// A mask at the stored image size made ready to pair with its loaded image: undistorted with
/// the image, then resized to `size`.
fn prepared_mask(
    mask: Mask,
    camera: &Camera,
    distortion: Option<&Distortion>,
    size: (u32, u32),
) -> Mask {
    let mask = match distortion {
        Some(d) => undistort_mask(&mask, d, &camera.intrinsics),
        None => mask,
    };
    resize_mask(&mask, size.0, size.1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_filter_averages_blocks_and_triangle_handles_other_sizes() {
        let img = RgbImage {
            width: 4,
            height: 2,
            data: (0..24).map(|v| v as f32).collect(),
        };
        let half = resize_rgb(&img, 2, 1);
        // Block (0,0): pixels 0, 1, 4, 5 → channel 0 values 0, 3, 12, 15 → mean 7.5.
        assert_eq!(half.pixel(0, 0), [7.5, 8.5, 9.5]);
        assert_eq!(half.pixel(1, 0), [13.5, 14.5, 15.5]);
        let odd = resize_rgb(&img, 3, 2);
        assert_eq!((odd.width, odd.height, odd.data.len()), (3, 2, 18));
    }

    #[test]
    fn downscaled_copies_are_recognised_within_rounding() {
        assert_eq!(downscale_factor((1297, 840), (649, 420)), Some(2));
        assert_eq!(downscale_factor((1297, 840), (162, 105)), Some(8));
        assert_eq!(downscale_factor((1297, 840), (600, 420)), None);
    }

    #[test]
    fn a_header_claiming_too_many_pixels_is_refused_before_decoding() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("lie.png");
        image::RgbImage::new(1, 1).save(&path).unwrap();
        let mut bytes = std::fs::read(&path).unwrap();
        // IHDR: 20000 × 20000 (each side allowed, 4·10^8 pixels not), checksum fixed so the
        // decoder believes it.
        bytes[16..20].copy_from_slice(&20_000u32.to_be_bytes());
        bytes[20..24].copy_from_slice(&20_000u32.to_be_bytes());
        let crc = bytes[12..29].iter().fold(!0u32, |mut crc, &b| {
            crc ^= u32::from(b);
            for _ in 0..8 {
                crc = (crc >> 1) ^ (0xEDB8_8320 & 0u32.wrapping_sub(crc & 1));
            }
            crc
        });
        bytes[29..33].copy_from_slice(&(!crc).to_be_bytes());
        std::fs::write(&path, bytes).unwrap();
        let err = load_image(&path).unwrap_err().to_string();
        assert!(
            err.contains("lie.png") && err.contains("400000000 pixels"),
            "{err}"
        );
    }

    #[test]
    fn rgba_is_composited_on_the_background() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.png");
        image::RgbaImage::from_raw(2, 1, vec![255, 0, 0, 255, 255, 0, 0, 0])
            .unwrap()
            .save(&path)
            .unwrap();
        let img = load_image_with_background(&path, [1.0, 1.0, 1.0]).unwrap();
        assert_eq!(img.pixel(0, 0), [1.0, 0.0, 0.0]);
        assert_eq!(img.pixel(1, 0), [1.0, 1.0, 1.0]);
    }
}
