//! In-memory images and masks: the pixel buffers every other module reads. Row-major, top row
//! first; colour is RGB interleaved `f32` in `[0, 1]` as stored (sRGB values, no linearisation,
//! as 3DGS trains).

use crate::scene::limits::MAX_IMAGE_SIDE;

/// An RGB image, `data[(y * width + x) * 3 + c]`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RgbImage {
    pub width: u32,
    pub height: u32,
    pub data: Vec<f32>,
}

impl RgbImage {
    /// A `width × height` image filled with one colour.
    pub fn filled(width: u32, height: u32, colour: [f32; 3]) -> RgbImage {
        let mut data = Vec::with_capacity(width as usize * height as usize * 3);
        for _ in 0..width as usize * height as usize {
            data.extend_from_slice(&colour);
        }
        RgbImage {
            width,
            height,
            data,
        }
    }

    pub fn pixel_count(&self) -> usize {
        self.width as usize * self.height as usize
    }

    pub fn pixel(&self, x: u32, y: u32) -> [f32; 3] {
        let i = (y as usize * self.width as usize + x as usize) * 3;
        [self.data[i], self.data[i + 1], self.data[i + 2]]
    }

    /// Converts to 8-bit sRGB for saving (values clamped to `[0, 1]`).
    /// The window `width × height` at `(x0, y0)`, which must lie inside the image.
    pub fn crop(&self, x0: u32, y0: u32, width: u32, height: u32) -> RgbImage {
        debug_assert!(x0 + width <= self.width && y0 + height <= self.height);
        let row = self.width as usize * 3;
        let mut data = Vec::with_capacity(width as usize * height as usize * 3);
        for y in y0..y0 + height {
            let start = y as usize * row + x0 as usize * 3;
            data.extend_from_slice(&self.data[start..start + width as usize * 3]);
        }
        RgbImage {
            width,
            height,
            data,
        }
    }

    pub fn to_rgb8(&self) -> image::RgbImage {
        let bytes = self
            .data
            .iter()
            .map(|&v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8)
            .collect();
        image::RgbImage::from_raw(self.width, self.height, bytes)
            .expect("RgbImage data length matches its size")
    }

    /// Converts an 8-bit image.
    pub fn from_rgb8(img: &image::RgbImage) -> RgbImage {
        RgbImage {
            width: img.width(),
            height: img.height(),
            data: img.as_raw().iter().map(|&v| v as f32 / 255.0).collect(),
        }
    }
}

/// A binary mask, `data[y * width + x]` is 0 or 1.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Mask {
    pub width: u32,
    pub height: u32,
    pub data: Vec<u8>,
}

impl Mask {
    pub fn empty(width: u32, height: u32) -> Mask {
        Mask {
            width,
            height,
            data: vec![0; width as usize * height as usize],
        }
    }

    pub fn get(&self, x: u32, y: u32) -> bool {
        self.data[y as usize * self.width as usize + x as usize] != 0
    }

    /// The window `width × height` at `(x0, y0)`, which must lie inside the mask.
    pub fn crop(&self, x0: u32, y0: u32, width: u32, height: u32) -> Mask {
        debug_assert!(x0 + width <= self.width && y0 + height <= self.height);
        let mut data = Vec::with_capacity(width as usize * height as usize);
        for y in y0..y0 + height {
            let start = y as usize * self.width as usize + x0 as usize;
            data.extend_from_slice(&self.data[start..start + width as usize]);
        }
        Mask {
            width,
            height,
            data,
        }
    }

    pub fn count(&self) -> usize {
        self.data.iter().filter(|&&v| v != 0).count()
    }

    pub fn iter_bool(&self) -> impl Iterator<Item = bool> + '_ {
        self.data.iter().map(|&v| v != 0)
    }
}

/// The resolution at which a dataset's images are loaded (DESIGN.md: intrinsics scale with it).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum ImageScale {
    /// Downscale by an integer factor: 1, 2, 4 or 8 (`1` is the image as stored).
    Factor(u32),
    /// Resize to this width, the height following the aspect ratio (rounded).
    Width(u32),
}

impl ImageScale {
    /// The size an image of `width × height` is loaded at; never below 1×1 and never above the
    /// image itself (a target width beyond the image's gives the image's size), so a scaled
    /// frame has no more pixels than its camera. [`ImageScale::checked_apply`] refuses instead.
    pub fn apply(self, width: u32, height: u32) -> (u32, u32) {
        match self {
            ImageScale::Factor(f) => {
                let f = f.max(1);
                ((width / f).max(1), (height / f).max(1))
            }
            ImageScale::Width(w) => {
                let w = w.clamp(1, width.max(1));
                let h = (height as f64 * w as f64 / width.max(1) as f64).round() as u32;
                (w, h.clamp(1, height.max(1)))
            }
        }
    }

    /// [`ImageScale::apply`] for loading an image as stored: a target width beyond the image's
    /// (an upscale) or beyond `limits::MAX_IMAGE_SIDE` is an error saying so; the caller adds the
    /// file.
    pub fn checked_apply(self, width: u32, height: u32) -> Result<(u32, u32), String> {
        match self {
            ImageScale::Width(w) if w > MAX_IMAGE_SIDE => Err(format!(
                "scale w{w} is wider than the largest image ({MAX_IMAGE_SIDE} pixels)"
            )),
            ImageScale::Width(w) if w > width => Err(format!(
                "scale w{w} would upscale the {width}×{height} image: its width is at most {width}"
            )),
            _ => Ok(self.apply(width, height)),
        }
    }

    /// The downscale factor (None for a target width).
    pub fn factor(self) -> Option<u32> {
        match self {
            ImageScale::Factor(f) => Some(f),
            ImageScale::Width(_) => None,
        }
    }

    /// A scale `ImageScale::parse` accepts (a factor 1, 2, 4 or 8, or a width from 1 to
    /// `limits::MAX_IMAGE_SIDE`): a file or a stored setting cannot ask for more than a user can.
    pub fn is_valid(self) -> bool {
        match self {
            ImageScale::Factor(f) => [1, 2, 4, 8].contains(&f),
            ImageScale::Width(w) => (1..=MAX_IMAGE_SIDE).contains(&w),
        }
    }

    /// Parses the CLI spelling: `1`, `2`, `4`, `8` (factors), `0.5`, `0.25`, `0.125`
    /// (fractions), or `w960` (a target width, 1 to `limits::MAX_IMAGE_SIDE`).
    pub fn parse(text: &str) -> Option<ImageScale> {
        if let Some(w) = text.strip_prefix('w') {
            return w
                .parse()
                .ok()
                .filter(|&w| w > 0 && w <= MAX_IMAGE_SIDE)
                .map(ImageScale::Width);
        }
        if let Ok(f) = text.parse::<u32>() {
            return [1, 2, 4, 8].contains(&f).then_some(ImageScale::Factor(f));
        }
        let frac: f64 = text.parse().ok()?;
        [1u32, 2, 4, 8]
            .into_iter()
            .find(|&f| (1.0 / f as f64 - frac).abs() < 1e-9)
            .map(ImageScale::Factor)
    }
}

/// The CLI spelling `ImageScale::parse` reads back: `4` for a factor, `w960` for a width.
impl std::fmt::Display for ImageScale {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ImageScale::Factor(factor) => write!(f, "{factor}"),
            ImageScale::Width(width) => write!(f, "w{width}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scale_prints_as_it_parses() {
        for text in ["1", "2", "4", "8", "w1", "w960"] {
            let scale = ImageScale::parse(text).expect("parses");
            assert_eq!(scale.to_string(), text);
            assert!(scale.is_valid());
        }
        assert!(!ImageScale::Factor(3).is_valid());
        assert!(!ImageScale::Width(0).is_valid());
    }

    #[test]
    fn scale_parses_factors_fractions_and_widths() {
        assert_eq!(ImageScale::parse("4"), Some(ImageScale::Factor(4)));
        assert_eq!(ImageScale::parse("0.25"), Some(ImageScale::Factor(4)));
        assert_eq!(ImageScale::parse("w960"), Some(ImageScale::Width(960)));
        assert_eq!(ImageScale::parse("3"), None);
        assert_eq!(ImageScale::parse("w0"), None);
        assert_eq!(ImageScale::parse("w32768"), Some(ImageScale::Width(32_768)));
        assert_eq!(ImageScale::parse("w999999"), None);
    }

    #[test]
    fn loading_never_upscales() {
        // The issue's `--scale w999999` on an 800 × 800 image asked for 10^12 pixels.
        let err = ImageScale::Width(999_999)
            .checked_apply(800, 800)
            .unwrap_err();
        assert!(err.contains("w999999"), "{err}");
        let err = ImageScale::Width(801).checked_apply(800, 600).unwrap_err();
        assert!(err.contains("upscale") && err.contains("800×600"), "{err}");
        assert_eq!(
            ImageScale::Width(800).checked_apply(800, 600),
            Ok((800, 600))
        );
        assert_eq!(ImageScale::Factor(8).checked_apply(800, 600), Ok((100, 75)));
        // `apply` keeps a scaled frame within its camera: a thin 1 × 32768 camera at w32768
        // would otherwise be 32768 × 2^30 pixels.
        assert_eq!(ImageScale::Width(32_768).apply(1, 32_768), (1, 32_768));
        assert_eq!(ImageScale::Width(5000).apply(800, 600), (800, 600));
    }

    #[test]
    fn scale_keeps_aspect_ratio() {
        assert_eq!(ImageScale::Factor(4).apply(800, 800), (200, 200));
        assert_eq!(ImageScale::Width(480).apply(1920, 1080), (480, 270));
    }
}
