//! The true quantities of stamped damage, measured on the decals' texels in metres: crack length
//! along the thinned centre line, crack width as area over length, spalled and rebar areas as
//! texel counts, rebar length as its area over the bar diameter. Measured on the whole decal,
//! seen by the photos or not (as `synth` measures its building).

use glam::DVec3;
use serde::Serialize;

use crate::scene::DamageClass;

use super::decal::Decal;

/// One region of one survey (the `synth` layout, with `plane` for the facade).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Region {
    pub id: u32,
    pub class: DamageClass,
    pub plane: usize,
    /// Model frame (the twin's frame when the capture is trained as it is).
    pub centroid: [f64; 3],
    #[serde(skip_serializing_if = "Option::is_none")]
    pub length_m: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub width_m: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub area_m2: Option<f64>,
    /// The spall region a rebar region lies in.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub spall: Option<u32>,
    pub first_survey: u32,
    pub new: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub source: Option<String>,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Totals {
    pub crack_length_m: f64,
    pub spalling_area_m2: f64,
    pub rebar_length_m: f64,
    pub rebar_area_m2: f64,
    pub cracks: usize,
    pub spalls: usize,
    pub rebar: usize,
    pub new_regions: usize,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Quantities {
    pub survey: u32,
    pub frame: String,
    pub metres_per_unit: f64,
    pub spalling_area_includes_rebar: bool,
    pub totals: Totals,
    pub regions: Vec<Region>,
}

/// Rebar region ids are the spall's id plus this.
pub const REBAR_ID_OFFSET: u32 = 10_000;

/// The quantities of `survey`'s state of the decals.
pub fn measure(decals: &[Decal], survey: u32, metres_per_unit: f64) -> Quantities {
    let mut regions = Vec::new();
    for decal in decals.iter().filter(|d| d.first_survey <= survey) {
        let texel_m = decal.texel * metres_per_unit;
        for class in DamageClass::ALL {
            let cells: Vec<usize> = (0..decal.texels.len())
                .filter(|&i| {
                    decal.texels[i].is_some_and(|t| t.class == class && t.appears <= survey)
                })
                .collect();
            if cells.is_empty() {
                continue;
            }
            let area = cells.len() as f64 * texel_m * texel_m;
            let centroid = cells
                .iter()
                .map(|&i| decal.texel_centre(i % decal.width, i / decal.width))
                .sum::<DVec3>()
                / cells.len() as f64;
            let (length, width) = match class {
                DamageClass::Crack => {
                    let mut grid = vec![0u8; decal.texels.len()];
                    for &i in &cells {
                        grid[i] = 1;
                    }
                    let length = skeleton_length(&grid, decal.width, decal.height) * texel_m;
                    (Some(length), Some(area / length.max(1e-9)))
                }
                DamageClass::Rebar => {
                    let diameter = bar_diameter(decal, texel_m);
                    (Some(area / diameter), Some(diameter))
                }
                DamageClass::Spalling => (None, None),
            };
            let is_rebar = class == DamageClass::Rebar;
            regions.push(Region {
                id: if is_rebar {
                    decal.id + REBAR_ID_OFFSET
                } else {
                    decal.id
                },
                class,
                plane: decal.plane,
                centroid: centroid.to_array(),
                length_m: length,
                width_m: width,
                area_m2: (class != DamageClass::Crack).then_some(area),
                spall: is_rebar.then_some(decal.id),
                first_survey: decal.first_survey,
                new: decal.first_survey == survey && survey > 1,
                source: decal.source.clone(),
            });
        }
    }
    let sum = |class: DamageClass, f: fn(&Region) -> Option<f64>| -> f64 {
        regions
            .iter()
            .filter(|r| r.class == class)
            .filter_map(f)
            .sum()
    };
    let count = |class: DamageClass| regions.iter().filter(|r| r.class == class).count();
    Quantities {
        survey,
        frame: "the capture's model frame (its units; metres = units × metres_per_unit)".into(),
        metres_per_unit,
        spalling_area_includes_rebar: false,
        totals: Totals {
            crack_length_m: sum(DamageClass::Crack, |r| r.length_m),
            spalling_area_m2: sum(DamageClass::Spalling, |r| r.area_m2),
            rebar_length_m: sum(DamageClass::Rebar, |r| r.length_m),
            rebar_area_m2: sum(DamageClass::Rebar, |r| r.area_m2),
            cracks: count(DamageClass::Crack),
            spalls: count(DamageClass::Spalling),
            rebar: count(DamageClass::Rebar),
            new_regions: regions.iter().filter(|r| r.new).count(),
        },
        regions,
    }
}

/// A bar's diameter in metres: the median over the decal's columns of the longest run of rebar
/// texels down the column. Main bars run across the columns, so most columns cross them; the
/// few through the tie, which runs down them, are outvoted.
fn bar_diameter(decal: &Decal, texel_m: f64) -> f64 {
    let is_bar = |i: usize, j: usize| {
        decal.texels[j * decal.width + i].is_some_and(|t| t.class == DamageClass::Rebar)
    };
    let mut runs: Vec<usize> = (0..decal.width)
        .map(|i| {
            let (mut run, mut longest) = (0usize, 0usize);
            for j in 0..decal.height {
                run = if is_bar(i, j) { run + 1 } else { 0 };
                longest = longest.max(run);
            }
            longest
        })
        .filter(|&r| r > 0)
        .collect();
    runs.sort_unstable();
    (runs.get(runs.len() / 2).copied().unwrap_or(1) as f64) * texel_m
}

/// Length of a binary shape's centre line in texels: Guo–Hall thinning, then each pair of
/// neighbouring skeleton texels counted once, 1 straight and √2 diagonal (a diagonal step is
/// not counted where the two texels also share a straight neighbour, the corner of an L).
pub fn skeleton_length(data: &[u8], width: usize, height: usize) -> f64 {
    let skeleton = thin(data, width, height);
    let at = |x: i64, y: i64| {
        x >= 0
            && y >= 0
            && (x as usize) < width
            && (y as usize) < height
            && skeleton[y as usize * width + x as usize] != 0
    };
    let mut length = 0.0;
    for y in 0..height as i64 {
        for x in 0..width as i64 {
            if !at(x, y) {
                continue;
            }
            // Right and down: straight pairs; down-right and down-left: diagonal pairs.
            length += f64::from(u8::from(at(x + 1, y))) + f64::from(u8::from(at(x, y + 1)));
            for dx in [-1i64, 1] {
                if at(x + dx, y + 1) && !at(x + dx, y) && !at(x, y + 1) {
                    length += std::f64::consts::SQRT_2;
                }
            }
        }
    }
    length
}

/// Guo–Hall thinning to a one-texel-wide 8-connected skeleton. (Zhang–Suen, tried first,
/// erases two-texel-thick diagonal runs entirely, and real crack masks have them.)
fn thin(data: &[u8], width: usize, height: usize) -> Vec<u8> {
    let mut img: Vec<u8> = data.iter().map(|&v| u8::from(v != 0)).collect();
    let get = |img: &[u8], x: usize, y: usize, dx: i64, dy: i64| -> u8 {
        let (nx, ny) = (x as i64 + dx, y as i64 + dy);
        if nx < 0 || ny < 0 || nx as usize >= width || ny as usize >= height {
            0
        } else {
            img[ny as usize * width + nx as usize]
        }
    };
    loop {
        let mut changed = false;
        for pass in 0..2 {
            let mut remove = Vec::new();
            for y in 0..height {
                for x in 0..width {
                    if img[y * width + x] == 0 {
                        continue;
                    }
                    // p2 north, then clockwise to p9 north-west.
                    let p2 = get(&img, x, y, 0, -1);
                    let p3 = get(&img, x, y, 1, -1);
                    let p4 = get(&img, x, y, 1, 0);
                    let p5 = get(&img, x, y, 1, 1);
                    let p6 = get(&img, x, y, 0, 1);
                    let p7 = get(&img, x, y, -1, 1);
                    let p8 = get(&img, x, y, -1, 0);
                    let p9 = get(&img, x, y, -1, -1);
                    let c = ((1 - p2) & (p3 | p4))
                        + ((1 - p4) & (p5 | p6))
                        + ((1 - p6) & (p7 | p8))
                        + ((1 - p8) & (p9 | p2));
                    let n1 = (p9 | p2) + (p3 | p4) + (p5 | p6) + (p7 | p8);
                    let n2 = (p2 | p3) + (p4 | p5) + (p6 | p7) + (p8 | p9);
                    let n = n1.min(n2);
                    let m = if pass == 0 {
                        (p6 | p7 | (1 - p9)) & p8
                    } else {
                        (p2 | p3 | (1 - p5)) & p4
                    };
                    if c == 1 && (2..=3).contains(&n) && m == 0 {
                        remove.push(y * width + x);
                    }
                }
            }
            changed |= !remove.is_empty();
            for i in remove {
                img[i] = 0;
            }
        }
        if !changed {
            return img;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_thick_straight_line_measures_its_length() {
        let (w, h) = (60, 9);
        let mut data = vec![0u8; w * h];
        for y in 3..6 {
            for x in 5..55 {
                data[y * w + x] = 1;
            }
        }
        let length = skeleton_length(&data, w, h);
        assert!((length - 49.0).abs() <= 3.0, "{length}");
    }

    #[test]
    fn a_diagonal_line_counts_root_two_per_step() {
        let (w, h) = (40, 40);
        let mut data = vec![0u8; w * h];
        for k in 5..35 {
            data[k * w + k] = 1;
            data[k * w + k + 1] = 1;
        }
        let length = skeleton_length(&data, w, h);
        let expected = 29.0 * std::f64::consts::SQRT_2;
        assert!(
            (length - expected).abs() < 0.1 * expected,
            "{length} vs {expected}"
        );
    }
}
