//! Where a photo is cut into the model's tiles and how overlapping tiles blend: tiles of a fixed
//! size step by `tile − overlap` and the last one is moved back to end at the photo's edge (every
//! tile the same size, so one optimised plan serves them all); each tile's output is weighted by
//! a window that ramps linearly over the overlap inside the photo (not at the photo's own edges),
//! so seams vanish and the weights sum to one after normalising.

use serde::{Deserialize, Serialize};

use crate::segment::SegmentError;

/// Weight never below this inside a tile, so a pixel covered only by ramps still normalises.
const MIN_WEIGHT: f32 = 1e-3;

/// Tile size and overlap in pixels of the (scaled) photo, and the multiple the model needs its
/// input sides to be.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Tiling {
    pub tile: u32,
    pub overlap: u32,
    /// Input sides are padded (edge pixels repeated) up to a multiple of this; 16 for the crack
    /// model (four stride-2 levels).
    pub multiple: u32,
}

impl Default for Tiling {
    fn default() -> Self {
        Tiling {
            tile: 512,
            overlap: 64,
            multiple: 16,
        }
    }
}

impl Tiling {
    /// A tile that is a multiple of `multiple` and larger than twice its overlap.
    pub fn check(&self) -> Result<(), SegmentError> {
        if self.multiple == 0 || self.tile == 0 || !self.tile.is_multiple_of(self.multiple) {
            return Err(SegmentError::Settings(format!(
                "tile {} must be a positive multiple of {} (the model's input multiple)",
                self.tile, self.multiple
            )));
        }
        if self.overlap.saturating_mul(2) >= self.tile {
            return Err(SegmentError::Settings(format!(
                "overlap {} must be less than half the tile ({})",
                self.overlap, self.tile
            )));
        }
        Ok(())
    }

    /// The tiles' starts along a side of `length` pixels, and the tile's length there (the side
    /// itself when shorter than a tile).
    pub fn starts(&self, length: u32) -> (Vec<u32>, u32) {
        if length <= self.tile {
            return (vec![0], length);
        }
        let stride = self.tile - self.overlap;
        let last = length - self.tile;
        let mut starts: Vec<u32> = (0..)
            .map(|i| i * stride)
            .take_while(|&s| s < last)
            .collect();
        starts.push(last);
        (starts, self.tile)
    }

    /// The side padded to the model's multiple.
    pub fn padded(&self, length: u32) -> u32 {
        length.div_ceil(self.multiple) * self.multiple
    }

    /// The blending weight of each pixel along one side of a tile of `size` starting at `start`
    /// on a side of `length`: a linear ramp over the overlap toward neighbouring tiles, 1 toward
    /// the photo's edge.
    pub fn window(&self, start: u32, size: u32, length: u32) -> Vec<f32> {
        let ramp = self.overlap.max(1) as f32;
        let at_start = start == 0;
        let at_end = start + size >= length;
        (0..size)
            .map(|i| {
                let from_start = if at_start {
                    1.0
                } else {
                    (i as f32 + 0.5) / ramp
                };
                let from_end = if at_end {
                    1.0
                } else {
                    ((size - i) as f32 - 0.5) / ramp
                };
                from_start.min(from_end).clamp(MIN_WEIGHT, 1.0)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_cover_the_side_and_end_at_its_edge() {
        let tiling = Tiling {
            tile: 256,
            overlap: 32,
            multiple: 16,
        };
        let (starts, size) = tiling.starts(1000);
        assert_eq!(size, 256);
        assert_eq!(starts.first(), Some(&0));
        assert_eq!(starts.last().map(|s| s + size), Some(1000));
        for pair in starts.windows(2) {
            // Neighbours overlap by at least the overlap, and step forward.
            assert!(pair[1] > pair[0] && pair[0] + size >= pair[1] + 32);
        }
        assert_eq!(tiling.starts(200), (vec![0], 200));
        assert_eq!(tiling.starts(256), (vec![0], 256));
    }

    #[test]
    fn overlapping_windows_sum_to_about_one_inside_and_are_one_at_the_edges() {
        let tiling = Tiling {
            tile: 64,
            overlap: 16,
            multiple: 16,
        };
        let length = 150;
        let (starts, size) = tiling.starts(length);
        let mut sum = vec![0.0f32; length as usize];
        for &s in &starts {
            for (i, w) in tiling.window(s, size, length).into_iter().enumerate() {
                sum[s as usize + i] += w;
            }
        }
        assert_eq!(sum[0], 1.0);
        assert_eq!(sum[length as usize - 1], 1.0);
        // Where two ramps meet they add to one; where the last tile was moved back over more
        // than the overlap, a full-weight interior adds to a ramp: never zero, never above 2.
        assert!(sum.iter().all(|&v| (0.99..=2.0).contains(&v)), "{sum:?}");
    }

    #[test]
    fn a_tile_off_the_models_multiple_or_with_too_much_overlap_is_refused() {
        let bad = |tile, overlap| {
            Tiling {
                tile,
                overlap,
                multiple: 16,
            }
            .check()
            .is_err()
        };
        assert!(bad(500, 32) && bad(256, 128) && bad(0, 0));
        assert!(!bad(256, 64));
        assert_eq!(Tiling::default().padded(321), 336);
    }
}
