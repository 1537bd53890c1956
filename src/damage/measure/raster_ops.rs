//! Binary-image operations the measurement needs: dilation, 8-connected components, Zhang–Suen
//! thinning and the length of a skeleton (the weight of a minimum spanning tree over its
//! 8-neighbour links, so that a diagonal step counts √2 and the small triangles a thinned line
//! leaves at its corners count once).

/// A row-major binary image.
#[derive(Clone, Debug, PartialEq)]
pub struct Bitmap {
    pub width: usize,
    pub height: usize,
    pub data: Vec<bool>,
}

impl Bitmap {
    pub fn new(width: usize, height: usize) -> Bitmap {
        Bitmap {
            width,
            height,
            data: vec![false; width * height],
        }
    }

    pub fn get(&self, x: i64, y: i64) -> bool {
        x >= 0
            && y >= 0
            && (x as usize) < self.width
            && (y as usize) < self.height
            && self.data[y as usize * self.width + x as usize]
    }

    pub fn count(&self) -> usize {
        self.data.iter().filter(|&&b| b).count()
    }

    /// Dilation by a square of half-width `radius` (separable: rows, then columns).
    pub fn dilated(&self, radius: usize) -> Bitmap {
        if radius == 0 {
            return self.clone();
        }
        let (w, h) = (self.width, self.height);
        let mut rows = Bitmap::new(w, h);
        for y in 0..h {
            for x in 0..w {
                if self.data[y * w + x] {
                    let (a, b) = (x.saturating_sub(radius), (x + radius).min(w - 1));
                    rows.data[y * w + a..=y * w + b].fill(true);
                }
            }
        }
        let mut out = Bitmap::new(w, h);
        for y in 0..h {
            for x in 0..w {
                if rows.data[y * w + x] {
                    for yy in y.saturating_sub(radius)..=(y + radius).min(h - 1) {
                        out.data[yy * w + x] = true;
                    }
                }
            }
        }
        out
    }
}

/// 8-connected components: per pixel its component (0 = background, 1.. components), and the
/// number of components.
pub fn components(image: &Bitmap) -> (Vec<u32>, u32) {
    let (w, h) = (image.width, image.height);
    let mut label = vec![0u32; w * h];
    let mut next = 0;
    let mut stack = Vec::new();
    for start in 0..w * h {
        if !image.data[start] || label[start] != 0 {
            continue;
        }
        next += 1;
        label[start] = next;
        stack.push(start);
        while let Some(p) = stack.pop() {
            let (x, y) = ((p % w) as i64, (p / w) as i64);
            for (dx, dy) in NEIGHBOURS {
                let (nx, ny) = (x + dx, y + dy);
                if image.get(nx, ny) {
                    let q = ny as usize * w + nx as usize;
                    if label[q] == 0 {
                        label[q] = next;
                        stack.push(q);
                    }
                }
            }
        }
    }
    (label, next)
}

const NEIGHBOURS: [(i64, i64); 8] = [
    (-1, -1),
    (0, -1),
    (1, -1),
    (-1, 0),
    (1, 0),
    (-1, 1),
    (0, 1),
    (1, 1),
];

/// Zhang–Suen thinning to a one-pixel-wide skeleton.
pub fn thinned(image: &Bitmap) -> Bitmap {
    let mut out = image.clone();
    let (w, h) = (out.width as i64, out.height as i64);
    let mut remove = Vec::new();
    loop {
        let mut changed = false;
        for pass in 0..2 {
            remove.clear();
            for y in 0..h {
                for x in 0..w {
                    if !out.get(x, y) {
                        continue;
                    }
                    // P2..P9 clockwise from north.
                    let p = [
                        out.get(x, y - 1),
                        out.get(x + 1, y - 1),
                        out.get(x + 1, y),
                        out.get(x + 1, y + 1),
                        out.get(x, y + 1),
                        out.get(x - 1, y + 1),
                        out.get(x - 1, y),
                        out.get(x - 1, y - 1),
                    ];
                    let b = p.iter().filter(|&&v| v).count();
                    if !(2..=6).contains(&b) {
                        continue;
                    }
                    let a = (0..8).filter(|&i| !p[i] && p[(i + 1) % 8]).count();
                    if a != 1 {
                        continue;
                    }
                    let (c1, c2) = if pass == 0 {
                        (p[0] && p[2] && p[4], p[2] && p[4] && p[6])
                    } else {
                        (p[0] && p[2] && p[6], p[0] && p[4] && p[6])
                    };
                    if !c1 && !c2 {
                        remove.push((y * w + x) as usize);
                    }
                }
            }
            for &i in &remove {
                out.data[i] = false;
            }
            changed |= !remove.is_empty();
        }
        if !changed {
            return out;
        }
    }
}

/// Length of a skeleton in pixels: the minimum spanning forest over its 8-neighbour links
/// (orthogonal links weigh 1, diagonal √2), then over straight links of at most `bridge` pixels
/// between the pieces left apart, shortest first (a crack's centre line runs on through the
/// few cells where the twin's label dips under the threshold). A lone pixel counts 1.
pub fn skeleton_length(skeleton: &Bitmap, bridge: f64) -> f64 {
    let (w, h) = (skeleton.width, skeleton.height);
    let mut parent: Vec<usize> = (0..w * h).collect();
    fn find(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    let mut length = 0.0;
    // Kruskal: every orthogonal link before any diagonal one.
    for (links, weight) in [
        (&[(1i64, 0i64), (0, 1)][..], 1.0),
        (&[(1, 1), (-1, 1)][..], std::f64::consts::SQRT_2),
    ] {
        for y in 0..h as i64 {
            for x in 0..w as i64 {
                if !skeleton.get(x, y) {
                    continue;
                }
                for &(dx, dy) in links {
                    if skeleton.get(x + dx, y + dy) {
                        let a = find(&mut parent, y as usize * w + x as usize);
                        let b = find(&mut parent, (y + dy) as usize * w + (x + dx) as usize);
                        if a != b {
                            parent[a] = b;
                            length += weight;
                        }
                    }
                }
            }
        }
    }
    // Bridges between pieces, each pair of pixels once (the later pixel in raster order).
    let reach = bridge.floor() as i64;
    if reach >= 2 {
        let mut bridges = Vec::new();
        for y in 0..h as i64 {
            for x in 0..w as i64 {
                if !skeleton.get(x, y) {
                    continue;
                }
                let a = find(&mut parent, y as usize * w + x as usize);
                for dy in 0..=reach {
                    for dx in -reach..=reach {
                        if (dy == 0 && dx <= 0) || !skeleton.get(x + dx, y + dy) {
                            continue;
                        }
                        let d = ((dx * dx + dy * dy) as f64).sqrt();
                        let q = (y + dy) as usize * w + (x + dx) as usize;
                        if d <= bridge && find(&mut parent, q) != a {
                            bridges.push((d, y as usize * w + x as usize, q));
                        }
                    }
                }
            }
        }
        bridges.sort_by(|p, q| p.0.total_cmp(&q.0));
        for (d, p, q) in bridges {
            let (a, b) = (find(&mut parent, p), find(&mut parent, q));
            if a != b {
                parent[a] = b;
                length += d;
            }
        }
    }
    let trees = (0..w * h)
        .filter(|&i| skeleton.data[i] && find(&mut parent, i) == i)
        .count();
    // A tree of n pixels spans n - 1 links but covers n pixel lengths: one more per tree.
    length + trees as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    fn draw_line(image: &mut Bitmap, from: (f64, f64), to: (f64, f64), half_width: f64) {
        for y in 0..image.height {
            for x in 0..image.width {
                let p = (x as f64 + 0.5, y as f64 + 0.5);
                let d = (to.0 - from.0, to.1 - from.1);
                let t = (((p.0 - from.0) * d.0 + (p.1 - from.1) * d.1) / (d.0 * d.0 + d.1 * d.1))
                    .clamp(0.0, 1.0);
                let q = (from.0 + t * d.0 - p.0, from.1 + t * d.1 - p.1);
                if (q.0 * q.0 + q.1 * q.1).sqrt() <= half_width {
                    image.data[y * image.width + x] = true;
                }
            }
        }
    }

    #[test]
    fn a_thick_straight_line_thins_to_its_length() {
        for (to, expected) in [
            ((190.0, 10.0), 180.0),
            ((150.0, 150.0), 140.0 * 2f64.sqrt()),
        ] {
            let mut image = Bitmap::new(200, 200);
            draw_line(&mut image, (10.0, 10.0), to, 3.0);
            let length = skeleton_length(&thinned(&image), 0.0);
            // The skeleton stops about a half-width short of each rounded end.
            assert!(
                (length - expected).abs() < 0.05 * expected,
                "{length} vs {expected}"
            );
        }
    }

    #[test]
    fn a_branch_adds_its_length_and_components_are_separate() {
        let mut image = Bitmap::new(200, 120);
        draw_line(&mut image, (10.0, 60.0), (190.0, 60.0), 2.0);
        draw_line(&mut image, (100.0, 60.0), (100.0, 10.0), 2.0);
        let length = skeleton_length(&thinned(&image), 0.0);
        assert!((length - 230.0).abs() < 12.0, "{length}");
        let mut two = Bitmap::new(50, 10);
        draw_line(&mut two, (2.0, 5.0), (20.0, 5.0), 1.0);
        draw_line(&mut two, (30.0, 5.0), (48.0, 5.0), 1.0);
        assert_eq!(components(&two).1, 2);
        assert_eq!(components(&two.dilated(6)).1, 1);
    }

    #[test]
    fn bridges_span_short_gaps_along_a_line_and_only_those() {
        // A one-pixel line over x = 10..=186: dashes of 17 pixels, 3-pixel gaps.
        let mut dashed = Bitmap::new(200, 40);
        for x in 10..190 {
            if (x - 10) % 20 < 17 {
                dashed.data[20 * 200 + x] = true;
            }
        }
        let pieces = skeleton_length(&dashed, 0.0);
        assert!((pieces - 153.0).abs() < 1e-9, "{pieces}");
        let bridged = skeleton_length(&dashed, 5.0);
        assert!((bridged - 177.0).abs() < 1e-9, "{bridged}");
        // Gaps wider than the bridge stay open.
        assert!((skeleton_length(&dashed, 3.5) - pieces).abs() < 1e-9);

        // Two parallel lines 10 pixels apart: a 5-pixel bridge joins neither.
        let mut parallel = Bitmap::new(100, 40);
        draw_line(&mut parallel, (10.0, 10.0), (90.0, 10.0), 1.0);
        draw_line(&mut parallel, (10.0, 20.0), (90.0, 20.0), 1.0);
        let skeleton = thinned(&parallel);
        assert_eq!(
            skeleton_length(&skeleton, 5.0),
            skeleton_length(&skeleton, 0.0)
        );
    }
}
