//! Polygons filled into a mask by the pixel-centre rule: pixel (x, y) is inside when its centre
//! (x + 0.5, y + 0.5) is inside the polygon by the even-odd rule, a centre exactly on a left or
//! top edge counting in and on a right or bottom edge out (so two polygons sharing an edge never
//! both take a pixel). pycocotools (`rleFrPoly`) follows the same rule on vertices rounded to a
//! fifth of a pixel, so the two agree except at pixel centres within 0.2 px of an edge; a polygon
//! traced along pixel edges (what an exporter writes from a mask) fills exactly its pixels.
//! Several polygons of one annotation are OR-ed, as pycocotools merges them.

use crate::scene::Mask;

/// How far outside the image (in pixels) a vertex may lie: within half a pixel of an edge there
/// is no pixel centre, so such a vertex fills nothing outside the image; annotation tools write
/// `-0.3` or `width + 0.2` when a click lands on the border.
pub const EDGE_TOLERANCE: f64 = 0.5;

/// The first vertex of `points` farther than `EDGE_TOLERANCE` outside a `width × height` image,
/// or not finite.
pub fn vertex_outside(points: &[[f64; 2]], width: u32, height: u32) -> Option<[f64; 2]> {
    let (w, h) = (f64::from(width), f64::from(height));
    points.iter().copied().find(|&[x, y]| {
        !(x >= -EDGE_TOLERANCE
            && x <= w + EDGE_TOLERANCE
            && y >= -EDGE_TOLERANCE
            && y <= h + EDGE_TOLERANCE)
    })
}

/// Sets the pixels of `mask` whose centres are inside the polygon `points` (at least three
/// vertices; fewer fill nothing). Vertices outside the mask are clipped by the fill.
pub fn fill_polygon(mask: &mut Mask, points: &[[f64; 2]]) {
    if points.len() < 3 {
        return;
    }
    let (w, h) = (mask.width as usize, mask.height as usize);
    let mut crossings: Vec<f64> = Vec::new();
    for y in 0..h {
        let yc = y as f64 + 0.5;
        crossings.clear();
        for (i, &[x0, y0]) in points.iter().enumerate() {
            let [x1, y1] = points[(i + 1) % points.len()];
            // Half-open in y: a vertex on the scan line counts for one of its two edges only.
            if (y0 <= yc) != (y1 <= yc) {
                crossings.push(x0 + (yc - y0) * (x1 - x0) / (y1 - y0));
            }
        }
        crossings.sort_by(f64::total_cmp);
        let row = &mut mask.data[y * w..(y + 1) * w];
        for pair in crossings.chunks_exact(2) {
            // Centres x + 0.5 in [a, b): x from ceil(a − 0.5) to ceil(b − 0.5) − 1.
            let first = (pair[0] - 0.5).ceil().max(0.0);
            let end = (pair[1] - 0.5).ceil().min(w as f64);
            if end > first {
                row[first as usize..end as usize].fill(1);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_rectangle_on_pixel_edges_fills_exactly_its_pixels() {
        let mut mask = Mask::empty(6, 5);
        fill_polygon(&mut mask, &[[1.0, 1.0], [4.0, 1.0], [4.0, 3.0], [1.0, 3.0]]);
        for y in 0..5 {
            for x in 0..6 {
                let inside = (1..4).contains(&x) && (1..3).contains(&y);
                assert_eq!(mask.get(x, y), inside, "pixel {x},{y}");
            }
        }
        // The whole image as one polygon fills every pixel; a vertex past the edge is clipped.
        let mut all = Mask::empty(6, 5);
        fill_polygon(
            &mut all,
            &[[-3.0, -1.0], [6.0, 0.0], [6.0, 5.0], [0.0, 5.0]],
        );
        assert_eq!(all.count(), 30);
    }

    #[test]
    fn vertices_beyond_half_a_pixel_outside_are_found() {
        assert_eq!(vertex_outside(&[[-0.4, 0.0], [10.5, 8.0]], 10, 8), None);
        assert_eq!(
            vertex_outside(&[[0.0, 0.0], [10.6, 8.0]], 10, 8),
            Some([10.6, 8.0])
        );
        assert!(vertex_outside(&[[f64::NAN, 0.0]], 10, 8).is_some());
    }
}
