//! Real crack photos with their masks, the source of every stamped crack's shape and texture:
//! crackforest's layout (`image/NNN.jpg` + `masks/NNN.png`) and the tunnel samples' (`N.png` +
//! `N_m.png` in one folder). A source crack is the largest connected crack of a mask, cropped
//! to its box with the photo's pixels under it.

use std::path::{Path, PathBuf};

use crate::scene::files::{EntryBudget, list_dir};
use crate::scene::limits::MAX_LISTED_ENTRIES;
use crate::scene::load::load_image;
use crate::scene::masks::read_binary_mask;
use crate::scene::{Mask, RgbImage};

use super::params::StampError;

/// A photo and its crack mask (same size).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SourcePair {
    pub photo: PathBuf,
    pub mask: PathBuf,
}

/// One crack cut out of a real photo: the mask of its largest connected crack and the photo's
/// pixels, both cropped to the crack's box plus a margin.
#[derive(Clone, Debug)]
pub struct SourceCrack {
    pub pair: SourcePair,
    pub photo: RgbImage,
    pub mask: Mask,
}

fn is_image(path: &Path) -> bool {
    path.is_file()
        && path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| ["png", "jpg", "jpeg"].contains(&e.to_ascii_lowercase().as_str()))
}

/// Every photo-with-mask pair in the folders, sorted; a folder with none is refused.
pub fn list_pairs(folders: &[PathBuf]) -> Result<Vec<SourcePair>, StampError> {
    let mut pairs = Vec::new();
    for folder in folders {
        let mut budget = EntryBudget::new(MAX_LISTED_ENTRIES);
        let before = pairs.len();
        let (images, masks) = (folder.join("image"), folder.join("masks"));
        if images.is_dir() && masks.is_dir() {
            // crackforest: image/NNN.jpg with masks/NNN.png.
            for photo in list_dir(&images, &mut budget)
                .into_iter()
                .filter(|p| is_image(p))
            {
                let Some(stem) = photo.file_stem().and_then(|s| s.to_str()) else {
                    continue;
                };
                let mask = masks.join(format!("{stem}.png"));
                if mask.is_file() {
                    pairs.push(SourcePair { photo, mask });
                }
            }
        } else {
            // Tunnel samples: N.png with N_m.png beside it.
            for mask in list_dir(folder, &mut budget)
                .into_iter()
                .filter(|p| is_image(p))
            {
                let Some(stem) = mask.file_stem().and_then(|s| s.to_str()) else {
                    continue;
                };
                let Some(base) = stem.strip_suffix("_m") else {
                    continue;
                };
                let photo = ["png", "jpg", "jpeg"]
                    .iter()
                    .map(|e| folder.join(format!("{base}.{e}")))
                    .find(|p| p.is_file());
                if let Some(photo) = photo {
                    pairs.push(SourcePair { photo, mask });
                }
            }
        }
        if pairs.len() == before {
            return Err(StampError::refused(
                folder,
                "no crack photos with masks here (expected image/ + masks/, or N.png + N_m.png)",
            ));
        }
    }
    pairs.sort_by(|a, b| a.photo.cmp(&b.photo));
    Ok(pairs)
}

/// Crack pixels fewer than this make no usable source crack.
const MIN_CRACK_PIXELS: usize = 40;

/// Loads a pair and cuts out its largest connected crack; `None` when the mask has too little
/// crack.
pub fn load_crack(pair: &SourcePair) -> Result<Option<SourceCrack>, StampError> {
    let photo = load_image(&pair.photo)?;
    let mask = read_binary_mask(&pair.mask)?;
    if (mask.width, mask.height) != (photo.width, photo.height) {
        return Err(StampError::refused(
            &pair.mask,
            format!(
                "mask is {}×{} but its photo {} is {}×{}",
                mask.width,
                mask.height,
                pair.photo.display(),
                photo.width,
                photo.height
            ),
        ));
    }
    let component = largest_component(&mask);
    if component.len() < MIN_CRACK_PIXELS {
        return Ok(None);
    }
    // Room for widening (`decal::widened` grows at most `MAX_WIDENING` texels).
    let margin = super::decal::MAX_WIDENING as u32 + 2;
    let x0 = component
        .iter()
        .map(|p| p.0)
        .min()
        .unwrap_or(0)
        .saturating_sub(margin);
    let y0 = component
        .iter()
        .map(|p| p.1)
        .min()
        .unwrap_or(0)
        .saturating_sub(margin);
    let x1 = (component.iter().map(|p| p.0).max().unwrap_or(0) + margin + 1).min(mask.width);
    let y1 = (component.iter().map(|p| p.1).max().unwrap_or(0) + margin + 1).min(mask.height);
    let mut crack = Mask::empty(x1 - x0, y1 - y0);
    for (x, y) in component {
        crack.data[((y - y0) * crack.width + (x - x0)) as usize] = 1;
    }
    Ok(Some(SourceCrack {
        pair: pair.clone(),
        photo: photo.crop(x0, y0, x1 - x0, y1 - y0),
        mask: crack,
    }))
}

/// A concrete texture from a crack photo: its pixels with the crack (grown by two pixels)
/// replaced by the nearest crack-free pixel to its left in the row (or right, at the edge), so
/// a spall made from it carries no crack.
pub fn load_texture(pair: &SourcePair) -> Result<RgbImage, StampError> {
    let mut photo = load_image(&pair.photo)?;
    let mask = read_binary_mask(&pair.mask)?;
    if (mask.width, mask.height) != (photo.width, photo.height) {
        return Ok(photo);
    }
    let (w, h) = (mask.width as usize, mask.height as usize);
    let near_crack = |x: usize, y: usize| {
        (y.saturating_sub(2)..=(y + 2).min(h - 1)).any(|yy| {
            (x.saturating_sub(2)..=(x + 2).min(w - 1)).any(|xx| mask.data[yy * w + xx] != 0)
        })
    };
    for y in 0..h {
        let row: Vec<bool> = (0..w).map(|x| near_crack(x, y)).collect();
        for x in 0..w {
            if !row[x] {
                continue;
            }
            let from = (0..x)
                .rev()
                .find(|&k| !row[k])
                .or_else(|| (x + 1..w).find(|&k| !row[k]));
            if let Some(k) = from {
                let (src, dst) = ((y * w + k) * 3, (y * w + x) * 3);
                for c in 0..3 {
                    photo.data[dst + c] = photo.data[src + c];
                }
            }
        }
    }
    Ok(photo)
}

/// The pixels of the mask's largest 8-connected component.
fn largest_component(mask: &Mask) -> Vec<(u32, u32)> {
    let (w, h) = (mask.width as usize, mask.height as usize);
    let mut seen = vec![false; w * h];
    let mut best = Vec::new();
    for start in 0..w * h {
        if seen[start] || mask.data[start] == 0 {
            continue;
        }
        seen[start] = true;
        let mut stack = vec![start];
        let mut component = Vec::new();
        while let Some(i) = stack.pop() {
            let (x, y) = (i % w, i / w);
            component.push((x as u32, y as u32));
            for ny in y.saturating_sub(1)..=(y + 1).min(h - 1) {
                for nx in x.saturating_sub(1)..=(x + 1).min(w - 1) {
                    let j = ny * w + nx;
                    if !seen[j] && mask.data[j] != 0 {
                        seen[j] = true;
                        stack.push(j);
                    }
                }
            }
        }
        if component.len() > best.len() {
            best = component;
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_largest_component_wins_and_diagonals_connect() {
        let mut mask = Mask::empty(8, 6);
        for (x, y) in [(0, 0), (1, 1), (2, 2), (3, 3), (7, 0), (7, 1)] {
            mask.data[y * 8 + x] = 1;
        }
        let c = largest_component(&mask);
        assert_eq!(c.len(), 4);
        assert!(c.contains(&(3, 3)));
    }
}
