//! A loss region as runs of its pixels: per image row, the `[x0, x1)` stretches where the
//! region's weight is non-zero. A hull region holds a tenth of a crop's pixels, so the losses
//! visit only these runs (the others carry no weight and get no gradient) instead of passing
//! over the whole crop, and the region SSIM plans its pieces from them.

/// The runs of a `width × height` region, row by row, each row's runs left to right.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RegionRuns {
    width: usize,
    height: usize,
    /// `runs[row_start[y]..row_start[y + 1]]` are row `y`'s runs (`height + 1` entries).
    row_start: Vec<usize>,
    /// `[x0, x1)` of every run.
    runs: Vec<[usize; 2]>,
}

impl RegionRuns {
    pub fn new() -> RegionRuns {
        RegionRuns::default()
    }

    /// The runs of `region` (`width·height` weights), keeping the allocations.
    pub fn rebuild(&mut self, region: &[f32], width: usize, height: usize) {
        assert_eq!(region.len(), width * height, "region runs: region size");
        self.width = width;
        self.height = height;
        self.row_start.clear();
        self.runs.clear();
        for row in region.chunks_exact(width.max(1)).take(height) {
            self.row_start.push(self.runs.len());
            let mut x = 0;
            while x < width {
                if row[x] == 0.0 {
                    x += 1;
                    continue;
                }
                let x0 = x;
                while x < width && row[x] != 0.0 {
                    x += 1;
                }
                self.runs.push([x0, x]);
            }
        }
        // A zero-width region has rows but no pixels: one start per row all the same.
        self.row_start.resize(height, self.runs.len());
        self.row_start.push(self.runs.len());
    }

    /// The runs of `region`, freshly allocated.
    pub fn of(region: &[f32], width: usize, height: usize) -> RegionRuns {
        let mut runs = RegionRuns::new();
        runs.rebuild(region, width, height);
        runs
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn height(&self) -> usize {
        self.height
    }

    /// Row `y`'s runs, left to right.
    pub fn row(&self, y: usize) -> &[[usize; 2]] {
        &self.runs[self.row_start[y]..self.row_start[y + 1]]
    }

    /// Every run with its row, top to bottom, left to right.
    pub fn iter(&self) -> impl Iterator<Item = (usize, [usize; 2])> + '_ {
        (0..self.height).flat_map(move |y| self.row(y).iter().map(move |&r| (y, r)))
    }

    /// The region's pixel indices (`y·width + x`) in image order.
    pub fn pixels(&self) -> impl Iterator<Item = usize> + '_ {
        self.iter()
            .flat_map(move |(y, [x0, x1])| (x0..x1).map(move |x| y * self.width + x))
    }

    /// The sum of `region`'s weights in image order, as f64: the same value as summing every
    /// pixel's, since the pixels skipped add exact zeros.
    pub fn mass(&self, region: &[f32]) -> f64 {
        self.pixels().map(|p| region[p] as f64).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_hold_exactly_the_non_zero_pixels_in_order() {
        let (w, h) = (13usize, 6usize);
        let mut rng = fastrand::Rng::with_seed(3);
        let mut m: Vec<f32> = (0..w * h)
            .map(|_| if rng.u8(0..3) == 0 { 0.5 } else { 0.0 })
            .collect();
        // A full row, an empty row, a run reaching each edge.
        m[2 * w..3 * w].fill(1.0);
        m[4 * w..5 * w].fill(0.0);
        m[5 * w] = 1.0;
        m[6 * w - 1] = 1.0;
        let runs = RegionRuns::of(&m, w, h);
        let expected: Vec<usize> = (0..w * h).filter(|&p| m[p] != 0.0).collect();
        assert_eq!(runs.pixels().collect::<Vec<_>>(), expected);
        assert_eq!(runs.row(2), &[[0, w]]);
        assert!(runs.row(4).is_empty());
        let all: f64 = m.iter().map(|&v| v as f64).sum();
        assert_eq!(runs.mass(&m).to_bits(), all.to_bits());
        // Rebuilt for another size, nothing of the first is left.
        let mut again = runs.clone();
        again.rebuild(&[0.0, 2.0, 2.0, 0.0], 2, 2);
        assert_eq!(
            again.iter().collect::<Vec<_>>(),
            vec![(0, [1, 2]), (1, [0, 1])]
        );
    }
}
