//! The picture a person checks a refinement's hulls by: the photo dimmed outside the hulls, the
//! hulls' edges in green (`refine` writes one per view into `hulls/`).

use crate::scene::{Mask, RgbImage};

/// The photo dimmed outside the hulls, with the hulls' edges in green: what a person checks.
pub fn hull_picture(photo: &RgbImage, inside: &Mask) -> RgbImage {
    let (w, h) = (photo.width, photo.height);
    let mut image = photo.clone();
    for y in 0..h {
        for x in 0..w {
            let p = (y * w + x) as usize;
            let rgb = &mut image.data[p * 3..p * 3 + 3];
            if !inside.get(x, y) {
                rgb.iter_mut().for_each(|v| *v *= 0.35);
                continue;
            }
            let edge = [(-1i32, 0i32), (1, 0), (0, -1), (0, 1)]
                .iter()
                .any(|(dx, dy)| {
                    let (nx, ny) = (x as i32 + dx, y as i32 + dy);
                    nx < 0
                        || ny < 0
                        || nx >= w as i32
                        || ny >= h as i32
                        || !inside.get(nx as u32, ny as u32)
                });
            if edge {
                rgb.copy_from_slice(&[0.0, 1.0, 0.0]);
            }
        }
    }
    image
}
