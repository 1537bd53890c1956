//! COCO's run-length encoding of a binary mask (pycocotools `maskApi.c`): the pixels in
//! column-major order (down the first column, then the next), runs alternating background and
//! mask starting with background (a mask starting on a set pixel begins with a zero run). The
//! counts are written either as a JSON list ("uncompressed", what CVAT exports with
//! `iscrowd: 1`) or as COCO's compact string (`rleToString`: each count, after the first two a
//! difference from the count two before, in 5-bit groups of a signed LEB128 with `0x20` as the
//! continuation bit, each group plus 48 as one ASCII character).

use crate::scene::Mask;

/// The mask that `counts` encode for a `width × height` image; an error (for the caller to
/// name its file) when the runs do not add up to the pixel count.
pub fn mask_from_counts(counts: &[u64], width: u32, height: u32) -> Result<Mask, String> {
    let (w, h) = (width as usize, height as usize);
    let pixels = w * h;
    let total = counts
        .iter()
        .try_fold(0u64, |sum, &c| sum.checked_add(c))
        .unwrap_or(u64::MAX);
    if total != pixels as u64 {
        return Err(format!(
            "RLE runs add up to {total} pixels but the image is {width}×{height} = {pixels}"
        ));
    }
    let mut mask = Mask::empty(width, height);
    let mut at = 0usize;
    for (k, &run) in counts.iter().enumerate() {
        // `total == pixels` bounds every run and their sum by the pixel count.
        let run = run as usize;
        if k % 2 == 1 {
            for i in at..at + run {
                // Column-major index i is pixel (i / h, i % h).
                let (x, y) = (i / h, i % h);
                mask.data[y * w + x] = 1;
            }
        }
        at += run;
    }
    Ok(mask)
}

/// The runs of `mask` in COCO's order (column-major, background first).
pub fn counts_of_mask(mask: &Mask) -> Vec<u64> {
    let (w, h) = (mask.width as usize, mask.height as usize);
    let mut counts = Vec::new();
    let mut current = 0u8;
    let mut run = 0u64;
    for x in 0..w {
        for y in 0..h {
            let v = u8::from(mask.data[y * w + x] != 0);
            if v != current {
                counts.push(run);
                run = 0;
                current = v;
            }
            run += 1;
        }
    }
    counts.push(run);
    counts
}

/// COCO's compact string of `counts` (`rleToString`).
pub fn counts_to_string(counts: &[u64]) -> String {
    let mut out = String::new();
    for (i, &count) in counts.iter().enumerate() {
        // Counts are pixel counts (at most 2^28, limits::MAX_IMAGE_PIXELS), so `i64` holds them
        // and their differences.
        let mut x = count as i64;
        if i > 2 {
            x -= counts[i - 2] as i64;
        }
        loop {
            let mut c = (x & 0x1f) as u8;
            x >>= 5;
            let more = if c & 0x10 != 0 { x != -1 } else { x != 0 };
            if more {
                c |= 0x20;
            }
            out.push(char::from(c + 48));
            if !more {
                break;
            }
        }
    }
    out
}

/// The counts of COCO's compact string (`rleFrString`); an error when a character is outside
/// its alphabet, a number does not end, or a count comes out negative.
pub fn counts_from_string(text: &str) -> Result<Vec<u64>, String> {
    let bytes = text.as_bytes();
    let mut counts: Vec<u64> = Vec::new();
    let mut p = 0usize;
    while p < bytes.len() {
        let mut x: i64 = 0;
        let mut k = 0u32;
        loop {
            let Some(&b) = bytes.get(p) else {
                return Err(format!(
                    "RLE string ends inside a number (count {})",
                    counts.len() + 1
                ));
            };
            if !(48..48 + 64).contains(&b) {
                return Err(format!(
                    "RLE string has {:?} at character {}: not a COCO RLE character",
                    char::from(b),
                    p + 1
                ));
            }
            // 12 groups of 5 bits fill 60 of an i64's bits; a longer number is no pixel count.
            if k >= 12 {
                return Err(format!(
                    "RLE string has a number too long at character {}",
                    p + 1
                ));
            }
            let c = i64::from(b - 48);
            x |= (c & 0x1f) << (5 * k);
            p += 1;
            k += 1;
            if c & 0x20 == 0 {
                if c & 0x10 != 0 {
                    x |= -1i64 << (5 * k);
                }
                break;
            }
        }
        let m = counts.len();
        if m > 2 {
            x += counts[m - 2] as i64;
        }
        if x < 0 {
            return Err(format!("RLE string gives count {} a negative value", m + 1));
        }
        counts.push(x as u64);
    }
    Ok(counts)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_are_column_major_and_start_with_background() {
        // 3 wide, 2 high:  row 0: 1 0 0 / row 1: 1 1 0 → columns: (1,1), (0,1), (0,0).
        let mask = Mask {
            width: 3,
            height: 2,
            data: vec![1, 0, 0, 1, 1, 0],
        };
        let counts = counts_of_mask(&mask);
        assert_eq!(counts, [0, 2, 1, 1, 2]);
        assert_eq!(mask_from_counts(&counts, 3, 2).unwrap(), mask);
        let err = mask_from_counts(&[0, 2, 1], 3, 2).unwrap_err();
        assert!(err.contains("add up to 3") && err.contains("6"), "{err}");
    }

    #[test]
    fn compact_strings_round_trip_large_and_negative_differences() {
        let counts = vec![0, 5, 1_000_000, 3, 17, 400_000, 1, 0];
        let text = counts_to_string(&counts);
        assert_eq!(counts_from_string(&text).unwrap(), counts);
        assert!(counts_from_string("ab~").is_err());
        assert!(counts_from_string("0\u{7f}").is_err());
        // A continuation bit on the last character: the number never ends.
        assert!(counts_from_string("P").is_err());
    }
}
