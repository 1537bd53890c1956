//! The sizes beyond which a scene input is refused rather than read: image and camera sizes,
//! view counts, folder listings, point coordinates, text file sizes. Each number says where it
//! comes from; the readers check them before they allocate or work, so a lying header or count
//! ends in an error naming the file instead of an abort, a hang or a wrapped multiplication.

/// Largest width or height of a camera or an image. The largest survey cameras (Phase One
/// iXM-RS150F, 14 204 × 10 652) are under half of it; `u32` sizes up to 2^15 multiply without
/// overflow in any integer type the renderer uses.
pub const MAX_IMAGE_SIDE: u32 = 32_768;

/// Largest pixel count of a camera or an image: 2^28 ≈ 268 MP, about twice a 150 MP survey
/// camera. One such frame is 3.2 GB as `f32` RGB, so a lying size cannot ask for terabytes.
pub const MAX_IMAGE_PIXELS: u64 = 1 << 28;

/// Most views (registered COLMAP images, `transforms.json` frames) a dataset may list. The
/// largest public capture sets in these formats hold a few thousand to a few tens of thousands
/// of images; a million frames pointing at one image file is a broken exporter.
pub const MAX_VIEWS: usize = 100_000;

/// Most folder entries one dataset open lists (images, masks): ten times `MAX_VIEWS`. Listing
/// that many takes about a second; a link farm that would list more stops there with a warning.
pub const MAX_LISTED_ENTRIES: usize = 1_000_000;

/// Largest absolute coordinate of an SfM point kept for initialisation. Beyond 1e7 an `f32`
/// resolves no better than one model unit (a metre in a georeferenced model), so no splat placed
/// there could be trained; such points are skipped with a warning naming the file and the id.
pub const MAX_POINT_COORDINATE: f64 = 1e7;

/// Largest COLMAP model file read (`cameras`, `images`, `points3D`, binary or text).
/// `images.bin` keeps every keypoint at 24 bytes: 10 000 images of 16 000 keypoints each take
/// 3.8 GB, so 4 GiB holds large reconstructions while a sparse file claiming a terabyte is
/// refused before its bytes are read.
pub const MAX_COLMAP_BYTES: u64 = 4 << 30;

/// Largest `transforms.json` read: 100 000 frames with per-frame intrinsics, pretty-printed, take
/// about 150 MB.
pub const MAX_TRANSFORMS_BYTES: u64 = 256 << 20;

/// Largest `twin.ron` read: a project file lists paths and settings, a few KB per survey.
pub const MAX_PROJECT_BYTES: u64 = 16 << 20;

/// Largest annotation file read (COCO or LabelMe JSON). COCO's own `instances_train2017.json`
/// (118 000 images, 860 000 polygon and RLE annotations) is 448 MB; 1 GiB holds any survey's
/// annotations while a file claiming more is refused before it is read.
pub const MAX_ANNOTATION_BYTES: u64 = 1 << 30;

/// Largest JSON file of a project read (a survey's `metrics.json` and `history.json`, a
/// dataset's `truth/quantities.json`, a study's results): a training history keeps a sample per
/// logged step, a few MB for the longest runs.
pub const MAX_PROJECT_JSON_BYTES: u64 = 64 << 20;

/// Checks a camera or image size against `MAX_IMAGE_SIDE` and `MAX_IMAGE_PIXELS` (both sides at
/// least 1); the error says what is wrong, the caller adds the file.
pub fn check_image_size(width: u64, height: u64) -> Result<(), String> {
    let side = u64::from(MAX_IMAGE_SIDE);
    if width == 0 || height == 0 || width > side || height > side {
        return Err(format!(
            "image size {width}x{height} out of range (1 to {MAX_IMAGE_SIDE} pixels per side)"
        ));
    }
    // Both sides are at most 2^15 here, so the product cannot overflow.
    if width * height > MAX_IMAGE_PIXELS {
        return Err(format!(
            "image size {width}x{height} has {} pixels, more than the {MAX_IMAGE_PIXELS} allowed",
            width * height
        ));
    }
    Ok(())
}

/// Whether an SfM point's position can seed a Gaussian: finite, every coordinate within
/// `MAX_POINT_COORDINATE` (checked in `f64`, before 1e20 becomes a finite but useless `f32`).
pub fn is_usable_position(xyz: [f64; 3]) -> bool {
    // `!(|v| <= max)` is true for NaN as well.
    xyz.iter().all(|v| v.abs() <= MAX_POINT_COORDINATE)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn image_sizes_are_checked_per_side_and_in_total() {
        assert!(check_image_size(14_204, 10_652).is_ok());
        assert!(check_image_size(1, 1).is_ok());
        assert!(check_image_size(0, 10).is_err());
        assert!(check_image_size(u64::from(u32::MAX), u64::from(u32::MAX)).is_err());
        assert!(check_image_size(999_999, 999_999).is_err());
        // Each side allowed, the product not: 32768 × 16384 = 2^29 pixels.
        let err = check_image_size(32_768, 16_384).unwrap_err();
        assert!(err.contains("536870912"), "{err}");
        assert!(check_image_size(16_384, 16_384).is_ok());
    }

    #[test]
    fn positions_must_be_finite_and_within_ten_million() {
        assert!(is_usable_position([1.0, -2.0, 9_999_999.0]));
        assert!(!is_usable_position([f64::NAN, 0.0, 0.0]));
        assert!(!is_usable_position([0.0, f64::INFINITY, 0.0]));
        assert!(!is_usable_position([0.0, 0.0, -1e20]));
    }
}
