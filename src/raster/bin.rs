//! Tile binning and depth sort: which 16×16 tiles each projected Gaussian touches, and per tile
//! its Gaussians front to back (gsplat's (tile, depth) key order, built by one depth sort and a
//! stable counting scatter). It must not evaluate pixels.

use glam::Vec2;

use super::{Projected, TILE_SIZE};
use crate::simd::{Arith, Fused, simd_dispatch};

const TS: usize = TILE_SIZE as usize;

/// Tiles covering a `width × height` image: `(tiles_x, tiles_y)`; tile id = `ty * tiles_x + tx`.
pub fn tile_grid(width: u32, height: u32) -> (u32, u32) {
    (width.div_ceil(TILE_SIZE), height.div_ceil(TILE_SIZE))
}

/// Tiles `[x0, x1) × [y0, y1)` (as `[x0, y0, x1, y1]`) a projected Gaussian is binned into in
/// a `width × height` image: gsplat's rectangle of `radius` around the mean, intersected with
/// the tiles holding a pixel centre of the image inside `extent` (the box where alpha can reach
/// 1/255). Dropping the other tiles changes no pixel of the image: every Gaussian there would be
/// skipped by the alpha threshold, or blend only into the edge tiles' pixels beyond the image.
pub fn tile_rect(mean2d: Vec2, radius: u32, extent: Vec2, width: u32, height: u32) -> [u32; 4] {
    // `Fused` rounds with the standard `floor` and `ceil`: the same bits as every build.
    tile_rect_in::<Fused>(mean2d, radius, extent, width, height)
}

/// [`tile_rect`] with the floor and ceil of the build it is compiled in.
#[inline(always)]
fn tile_rect_in<F: Arith>(
    mean2d: Vec2,
    radius: u32,
    extent: Vec2,
    width: u32,
    height: u32,
) -> [u32; 4] {
    // Branch-free, so that the binning's loop over every Gaussian vectorises.
    let (tiles_x, tiles_y) = tile_grid(width, height);
    let ts = TILE_SIZE as f32;
    let r = radius as f32;
    let clamp = |v: f32, hi: u32| v.max(0.0).min(hi as f32) as u32;
    // gsplat: floor / ceil of the radius rectangle in tile units.
    let gx0 = clamp(F::floor((mean2d.x - r) / ts), tiles_x);
    let gx1 = clamp(F::ceil((mean2d.x + r) / ts), tiles_x);
    let gy0 = clamp(F::floor((mean2d.y - r) / ts), tiles_y);
    let gy1 = clamp(F::ceil((mean2d.y + r) / ts), tiles_y);
    // Pixels p of the image whose centres p + 0.5 lie within extent of the mean.
    let px0 = F::ceil(mean2d.x - extent.x - 0.5).max(0.0);
    let px1 = F::floor(mean2d.x + extent.x - 0.5).min(width.saturating_sub(1) as f32);
    let py0 = F::ceil(mean2d.y - extent.y - 0.5).max(0.0);
    let py1 = F::floor(mean2d.y + extent.y - 0.5).min(height.saturating_sub(1) as f32);
    let ex0 = clamp(F::floor(px0 / ts), tiles_x);
    let ex1 = clamp(F::floor(px1 / ts) + 1.0, tiles_x);
    let ey0 = clamp(F::floor(py0 / ts), tiles_y);
    let ey1 = clamp(F::floor(py1 / ts) + 1.0, tiles_y);
    let (x0, x1) = (gx0.max(ex0), gx1.min(ex1));
    let (y0, y1) = (gy0.max(ey0), gy1.min(ey1));
    // `<=` is false for NaN, which drops it.
    let binned = (radius != 0)
        & (extent.x > 0.0)
        & (extent.y > 0.0)
        & (width != 0)
        & (height != 0)
        & (px0 <= px1)
        & (py0 <= py1)
        & (x0 < x1)
        & (y0 < y1);
    if binned {
        [x0, y0, x1, y1]
    } else {
        [0, 0, 0, 0]
    }
}

/// Sorts `depth bits << 32 | index` keys whose indices ascend, by depth then index: a stable
/// LSD radix sort on the 32 depth bits (four byte passes, skipping a byte every key shares),
/// which is enough since the keys arrive in index order. Linear in the keys.
fn radix_sort_by_depth(keys: &mut Vec<u64>, scratch: &mut Vec<u64>) {
    scratch.clear();
    scratch.resize(keys.len(), 0);
    for pass in 0..4 {
        let shift = 32 + 8 * pass;
        let mut counts = [0usize; 256];
        for &k in keys.iter() {
            counts[((k >> shift) & 0xff) as usize] += 1;
        }
        if counts.contains(&keys.len()) {
            continue;
        }
        let mut offset = 0;
        for c in counts.iter_mut() {
            let n = *c;
            *c = offset;
            offset += n;
        }
        for &k in keys.iter() {
            let slot = &mut counts[((k >> shift) & 0xff) as usize];
            scratch[*slot] = k;
            *slot += 1;
        }
        std::mem::swap(keys, scratch);
    }
}

#[inline(always)]
fn build_bins_impl<F: Arith>(bins: &mut TileBins, projected: &Projected, width: u32, height: u32) {
    bins.build_impl::<F>(projected, width, height);
}

simd_dispatch!(
    /// [`TileBins::build`] with AVX2 (or AVX-512VL) where the CPU has it: the tile rectangles'
    /// floor and ceil become single instructions ([`Arith`]; the baseline x86-64 build uses
    /// adds and compares rather than libm calls).
    build_bins => build_bins_impl::<Arith>(
        bins: &mut TileBins,
        projected: &Projected,
        width: u32,
        height: u32,
    )
);

/// Sorted intersections of one frame, with the scratch that builds them.
#[derive(Debug, Default)]
pub(crate) struct TileBins {
    pub tiles_x: u32,
    pub tiles_y: u32,
    /// The image the tiles cover; the last tile column and row can reach past it.
    pub width: u32,
    pub height: u32,
    /// Gaussian index per intersection, ordered by (tile, depth).
    pub gaussian_ids: Vec<u32>,
    /// Per tile its `[start, end)` range in `gaussian_ids`.
    pub tile_ranges: Vec<[u32; 2]>,
    /// `depth bits << 32 | gaussian` of the binned Gaussians, sorted.
    depth_keys: Vec<u64>,
    /// Scratch of the radix sort.
    sort_scratch: Vec<u64>,
    /// Tile rectangle per Gaussian (indexed by Gaussian).
    rects: Vec<[u32; 4]>,
    cursor: Vec<u32>,
    /// `build_merged`'s moving intersections per tile (ranges, then Gaussian indices).
    moving_ranges: Vec<[u32; 2]>,
    moving_ids: Vec<u32>,
    /// Per tile: rendered or not (None: every tile). Set by `Rasterizer::set_active_tiles`;
    /// applied only when it has one entry per tile of the frame.
    pub active: Option<Vec<bool>>,
    /// Per tile its 16 rows' rendered pixels, bit `x` of entry `tile * 16 + y` for pixel
    /// `(x, y)` of the tile (None: every pixel). Set by `Rasterizer::set_active_pixels`;
    /// applied only when it has 16 entries per tile of the frame.
    pub active_pixels: Option<Vec<u16>>,
}

impl TileBins {
    /// Tiles of the grid, multiplied in `usize`: in `u32` a 4294967295² frame's 2^28 × 2^28
    /// tiles wrapped to 0.
    pub fn tile_count(&self) -> usize {
        self.tiles_x as usize * self.tiles_y as usize
    }

    /// Pixel columns and rows of `tile` inside the image, `(columns, rows)`, at most 16 each.
    pub fn tile_extent(&self, tile: usize) -> (usize, usize) {
        let tiles_x = self.tiles_x as usize;
        let (ox, oy) = ((tile % tiles_x) * TS, (tile / tiles_x) * TS);
        (
            (self.width as usize).saturating_sub(ox).min(TS),
            (self.height as usize).saturating_sub(oy).min(TS),
        )
    }

    /// The rows of `tile`'s rendered pixels (`active_pixels`), when they apply to this frame.
    pub fn tile_pixel_rows(&self, tile: usize) -> Option<&[u16]> {
        self.active_pixels
            .as_deref()
            .filter(|rows| rows.len() == self.tile_count() * TS)
            .map(|rows| &rows[tile * TS..(tile + 1) * TS])
    }

    /// `per_isect` values per intersection of `data`, split into one slice per tile (a few
    /// hundred pointers per frame; the ranges are disjoint, so tiles can fill them in parallel).
    pub fn split_by_tile<'a, T>(&self, data: &'a mut [T], per_isect: usize) -> Vec<&'a mut [T]> {
        let mut slices = Vec::with_capacity(self.tile_ranges.len());
        let mut rest = data;
        for [start, end] in &self.tile_ranges {
            let (head, tail) = rest.split_at_mut((end - start) as usize * per_isect);
            slices.push(head);
            rest = tail;
        }
        slices
    }

    pub fn build(&mut self, projected: &Projected, width: u32, height: u32) {
        build_bins(self, projected, width, height);
    }

    #[inline(always)]
    fn build_impl<F: Arith>(&mut self, projected: &Projected, width: u32, height: u32) {
        let (tiles_x, tiles_y) = tile_grid(width, height);
        self.tiles_x = tiles_x;
        self.tiles_y = tiles_y;
        // Tile ids in `usize` (`ty * tiles_x + tx` can pass `u32::MAX` on a huge frame).
        let tiles_x = tiles_x as usize;
        self.width = width;
        self.height = height;
        let n = projected.radii.len();
        let tiles = self.tile_count();
        self.rects.clear();
        self.rects.resize(n, [0; 4]);
        self.depth_keys.clear();
        self.cursor.clear();
        self.cursor.resize(tiles, 0);
        // Every rectangle first, in one loop without branches (it vectorises), then the keys
        // and counts of the binned Gaussians.
        for (((rect, &mean2d), &radius), &extent) in self
            .rects
            .iter_mut()
            .zip(&projected.means2d)
            .zip(&projected.radii)
            .zip(&projected.extents)
        {
            *rect = tile_rect_in::<F>(mean2d, radius, extent, width, height);
        }
        // Tiles left out (a refinement renders only the tiles its hulls touch) get no
        // intersections: they render as background and their backward does nothing.
        let active = self.active.as_deref().filter(|a| a.len() == tiles);
        if let Some(active) = active {
            for rect in &mut self.rects {
                if rect[2] > rect[0] && !rect_touches(rect, active, tiles_x) {
                    *rect = [0; 4];
                }
            }
        }
        for g in 0..n {
            let rect = self.rects[g];
            if rect[2] > rect[0] {
                // Depths are > NEAR_PLANE > 0, so their bit patterns sort like the values;
                // the index breaks ties deterministically.
                let key = ((projected.depths[g].to_bits() as u64) << 32) | g as u64;
                self.depth_keys.push(key);
                for_each_tile(&rect, tiles_x, active, |tile| self.cursor[tile] += 1);
            }
        }
        radix_sort_by_depth(&mut self.depth_keys, &mut self.sort_scratch);
        self.tile_ranges.clear();
        let mut start = 0u32;
        for count in self.cursor.iter_mut() {
            self.tile_ranges.push([start, start + *count]);
            *count = start;
            start = self.tile_ranges.last().map_or(0, |r| r[1]);
        }
        self.gaussian_ids.clear();
        self.gaussian_ids.resize(start as usize, 0);
        for key in &self.depth_keys {
            let g = (*key & 0xffff_ffff) as u32;
            let rect = self.rects[g as usize];
            for_each_tile(&rect, tiles_x, active, |tile| {
                let slot = &mut self.cursor[tile];
                self.gaussian_ids[*slot as usize] = g;
                *slot += 1;
            });
        }
    }
}

impl TileBins {
    /// [`TileBins::build`] of a frame in which only `moving` (ascending Gaussian indices) were
    /// projected: those are binned and sorted here, and merged per tile with `frozen`, the
    /// other Gaussians' intersections as an earlier `build` of the same view sorted them (per
    /// tile its range in `frozen.ids`, by depth then index). The merge keeps the (depth, index)
    /// order, so the bins are those `build` makes of the whole frame.
    pub fn build_merged(
        &mut self,
        projected: &Projected,
        width: u32,
        height: u32,
        moving: &[u32],
        frozen: FrozenTiles<'_>,
    ) {
        let (tiles_x, tiles_y) = tile_grid(width, height);
        self.tiles_x = tiles_x;
        self.tiles_y = tiles_y;
        self.width = width;
        self.height = height;
        let tiles_x = tiles_x as usize;
        let tiles = self.tile_count();
        assert_eq!(
            frozen.ranges.len(),
            tiles,
            "frozen tile lists of another grid"
        );
        let active = self.active.as_deref().filter(|a| a.len() == tiles);
        self.rects.clear();
        self.depth_keys.clear();
        self.cursor.clear();
        self.cursor.resize(tiles, 0);
        // The moving Gaussians' rectangles (by position in `moving`), keys and counts.
        for (j, &g) in moving.iter().enumerate() {
            let g = g as usize;
            let mut rect = tile_rect(
                projected.means2d[g],
                projected.radii[g],
                projected.extents[g],
                width,
                height,
            );
            if rect[2] > rect[0] && active.is_some_and(|a| !rect_touches(&rect, a, tiles_x)) {
                rect = [0; 4];
            }
            self.rects.push(rect);
            if rect[2] > rect[0] {
                let key = ((projected.depths[g].to_bits() as u64) << 32) | j as u64;
                self.depth_keys.push(key);
                for_each_tile(&rect, tiles_x, active, |tile| self.cursor[tile] += 1);
            }
        }
        // Positions in `moving` ascend with the Gaussian index, so sorting by (depth,
        // position) sorts by (depth, index).
        radix_sort_by_depth(&mut self.depth_keys, &mut self.sort_scratch);
        // The moving intersections per tile, sorted (`moving_ids`), then each tile's two
        // sorted lists merged.
        let mut moving_ranges = std::mem::take(&mut self.moving_ranges);
        moving_ranges.clear();
        let mut start = 0u32;
        for count in self.cursor.iter_mut() {
            moving_ranges.push([start, start + *count]);
            *count = start;
            start += moving_ranges.last().map_or(0, |r| r[1] - r[0]);
        }
        self.moving_ids.clear();
        self.moving_ids.resize(start as usize, 0);
        for key in &self.depth_keys {
            let j = (*key & 0xffff_ffff) as usize;
            let rect = self.rects[j];
            for_each_tile(&rect, tiles_x, active, |tile| {
                let slot = &mut self.cursor[tile];
                self.moving_ids[*slot as usize] = moving[j];
                *slot += 1;
            });
        }
        self.tile_ranges.clear();
        let mut start = 0u32;
        for (m, f) in moving_ranges.iter().zip(frozen.ranges) {
            let end = start + (m[1] - m[0]) + (f[1] - f[0]);
            self.tile_ranges.push([start, end]);
            start = end;
        }
        self.gaussian_ids.clear();
        self.gaussian_ids.resize(start as usize, 0);
        let key = |g: u32| ((projected.depths[g as usize].to_bits() as u64) << 32) | g as u64;
        for ((out, m), f) in self
            .tile_ranges
            .iter()
            .zip(&moving_ranges)
            .zip(frozen.ranges)
        {
            let out = &mut self.gaussian_ids[out[0] as usize..out[1] as usize];
            let a = &self.moving_ids[m[0] as usize..m[1] as usize];
            let b = &frozen.ids[f[0] as usize..f[1] as usize];
            let (mut i, mut k) = (0, 0);
            for slot in out.iter_mut() {
                let take_a = k == b.len() || (i < a.len() && key(a[i]) < key(b[k]));
                if take_a {
                    *slot = a[i];
                    i += 1;
                } else {
                    *slot = b[k];
                    k += 1;
                }
            }
        }
        self.moving_ranges = moving_ranges;
    }
}

/// A view's frozen intersections for [`TileBins::build_merged`]: per tile its `[start, end)`
/// range in `ids`, each range ordered by depth then index.
#[derive(Clone, Copy, Debug)]
pub struct FrozenTiles<'a> {
    pub ranges: &'a [[u32; 2]],
    pub ids: &'a [u32],
}

/// Whether the tile rectangle `[x0, y0, x1, y1]` holds an active tile.
/// Calls `f` with each tile of `rect` (row by row) that `active` leaves in (all when `None`).
fn for_each_tile(
    rect: &[u32; 4],
    tiles_x: usize,
    active: Option<&[bool]>,
    mut f: impl FnMut(usize),
) {
    for ty in rect[1] as usize..rect[3] as usize {
        for tx in rect[0] as usize..rect[2] as usize {
            let tile = ty * tiles_x + tx;
            if active.is_none_or(|a| a[tile]) {
                f(tile);
            }
        }
    }
}

fn rect_touches(rect: &[u32; 4], active: &[bool], tiles_x: usize) -> bool {
    (rect[1] as usize..rect[3] as usize).any(|ty| {
        active[ty * tiles_x + rect[0] as usize..ty * tiles_x + rect[2] as usize]
            .iter()
            .any(|&a| a)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tile_rect_follows_radius_and_clips_to_the_image() {
        let r = tile_rect(Vec2::new(20.0, 20.0), 5, Vec2::splat(100.0), 64, 64);
        assert_eq!(r, [0, 0, 2, 2]);
        let r = tile_rect(Vec2::new(-3.0, 20.0), 5, Vec2::splat(100.0), 64, 64);
        assert_eq!(r, [0, 0, 1, 2]);
    }

    #[test]
    fn tile_rect_drops_edge_tiles_whose_reached_pixels_lie_beyond_the_image() {
        // A 40 × 40 image: the third tile column holds pixels 32..40 of the image, 40..48 past it.
        let beyond = tile_rect(Vec2::new(44.0, 8.0), 6, Vec2::splat(3.0), 40, 40);
        assert_eq!(beyond, [0, 0, 0, 0]);
        let reaching = tile_rect(Vec2::new(42.0, 8.0), 6, Vec2::splat(3.0), 40, 40);
        assert_eq!(reaching, [2, 0, 3, 1]);
        // Below the last row.
        let below = tile_rect(Vec2::new(8.0, 44.0), 6, Vec2::splat(3.0), 40, 40);
        assert_eq!(below, [0, 0, 0, 0]);
        // An extent too small to hold any pixel centre.
        let between = tile_rect(Vec2::new(8.0, 8.0), 1, Vec2::splat(0.2), 40, 40);
        assert_eq!(between, [0, 0, 0, 0]);
    }

    #[test]
    fn tile_rect_drops_tiles_no_pixel_centre_of_the_extent_reaches() {
        // Radius rectangle spans tiles 0..2 in x, but the 1/255 box ends at x = 15.4.
        let r = tile_rect(Vec2::new(12.0, 8.0), 10, Vec2::new(3.4, 3.0), 64, 64);
        assert_eq!(r, [0, 0, 1, 1]);
        // Extent reaching the centre 16.5 of the first pixel of tile 1.
        let r = tile_rect(Vec2::new(12.0, 8.0), 10, Vec2::new(4.6, 3.0), 64, 64);
        assert_eq!(r, [0, 0, 2, 1]);
    }

    #[test]
    fn tile_counts_of_huge_frames_do_not_wrap() {
        // The 4294967295 × 4294967295 camera: 2^28 tiles a side, 2^56 in all (the u32
        // product was 0). The scene readers refuse such a camera long before it gets here.
        let (tiles_x, tiles_y) = tile_grid(u32::MAX, u32::MAX);
        assert_eq!((tiles_x, tiles_y), (1 << 28, 1 << 28));
        let bins = TileBins {
            tiles_x,
            tiles_y,
            ..TileBins::default()
        };
        assert_eq!(bins.tile_count(), 1usize << 56);
    }

    #[test]
    fn radix_sort_orders_like_a_comparison_sort() {
        let mut rng = fastrand::Rng::with_seed(3);
        // Few distinct depths (ties broken by index), and full-range ones.
        for distinct in [3u32, u32::MAX] {
            let mut keys: Vec<u64> = (0..5000u64)
                .map(|g| {
                    let depth =
                        (0.01 + rng.u32(0..distinct.min(1 << 20)) as f32 * 0.37).to_bits() as u64;
                    (depth << 32) | g
                })
                .collect();
            let mut want = keys.clone();
            want.sort_unstable();
            let mut scratch = Vec::new();
            radix_sort_by_depth(&mut keys, &mut scratch);
            assert_eq!(keys, want);
        }
    }

    #[test]
    fn bins_are_sorted_by_tile_then_depth() {
        let mut p = Projected::default();
        for (x, depth) in [(8.0, 3.0), (8.0, 1.0), (24.0, 2.0)] {
            p.means2d.push(Vec2::new(x, 8.0));
            p.radii.push(4);
            p.extents.push(Vec2::splat(4.0));
            p.depths.push(depth);
        }
        let mut bins = TileBins::default();
        bins.build(&p, 32, 16);
        assert_eq!(bins.tile_ranges, vec![[0, 2], [2, 3]]);
        assert_eq!(bins.gaussian_ids, vec![1, 0, 2]);
    }
}
