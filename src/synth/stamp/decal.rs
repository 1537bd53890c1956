//! A decal: damage as a texel raster lying on a plane in 3D, each texel with its class, the
//! survey it first appears in, and its colour. Cracks are cut from real crack masks (the part
//! beyond a cut along the crack's main axis grows in by survey 2); spalls are seeded outlines
//! that grow by a factor, with exposed bars in their core. Rendering looks texels up by the
//! nearest texel, so a pixel shows a texel's colour exactly where the truth mask says it does.

use glam::DVec3;

use crate::scene::{DamageClass, RgbImage};

use super::sources::SourceCrack;

/// Per-channel mean and standard deviation of a set of colours.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct ColourStats {
    pub mean: [f32; 3],
    pub std: [f32; 3],
}

impl ColourStats {
    pub fn of(colours: impl Iterator<Item = [f32; 3]>) -> Option<ColourStats> {
        let (mut sum, mut sq, mut n) = ([0f64; 3], [0f64; 3], 0usize);
        for c in colours {
            for k in 0..3 {
                sum[k] += c[k] as f64;
                sq[k] += (c[k] as f64).powi(2);
            }
            n += 1;
        }
        if n == 0 {
            return None;
        }
        let mean = sum.map(|s| s / n as f64);
        let std = [0, 1, 2].map(|k| (sq[k] / n as f64 - mean[k].powi(2)).max(0.0).sqrt() as f32);
        Some(ColourStats {
            mean: mean.map(|m| m as f32),
            std,
        })
    }

    /// Moves a colour from these statistics to `target`'s, per channel.
    pub fn transfer(&self, colour: [f32; 3], target: &ColourStats) -> [f32; 3] {
        [0, 1, 2].map(|k| {
            let z = (colour[k] - self.mean[k]) / self.std[k].max(1e-3);
            (z * target.std[k] + target.mean[k]).clamp(0.0, 1.0)
        })
    }
}

/// One texel of a decal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Texel {
    pub class: DamageClass,
    /// The survey it first shows in (1, or 2 for growth and new damage).
    pub appears: u32,
    /// The source photo's colour before matching to the facade (rebar: its own colour).
    pub source: [f32; 3],
    /// Darkening applied after matching (a spall's depth, a bar's roundness).
    pub shade: f32,
}

#[derive(Clone, Debug)]
pub struct Decal {
    /// Region id: the same damage keeps it in both surveys.
    pub id: u32,
    /// Index of the plane it lies on.
    pub plane: usize,
    /// The 3D corner of texel (0, 0) and the unit axes along the texel columns and rows.
    pub origin: DVec3,
    pub axis_u: DVec3,
    pub axis_v: DVec3,
    /// Texel size, model units.
    pub texel: f64,
    pub width: usize,
    pub height: usize,
    pub texels: Vec<Option<Texel>>,
    /// Final colours (after `match_colours`), one per texel.
    pub colours: Vec<[f32; 3]>,
    /// The source photo's background statistics (what is moved to the facade's).
    pub source_stats: ColourStats,
    /// The facade's statistics under the decal, once matched.
    pub facade_stats: Option<ColourStats>,
    /// 1 for survey-1 damage, 2 for damage new in survey 2.
    pub first_survey: u32,
    /// The real crack photo it was cut from, when a crack.
    pub source: Option<String>,
}

impl Decal {
    /// The texel a 3D point of the decal's plane falls in, shown in `survey`.
    pub fn texel_at(&self, p: DVec3, survey: u32) -> Option<usize> {
        let d = p - self.origin;
        let a = d.dot(self.axis_u) / self.texel;
        let b = d.dot(self.axis_v) / self.texel;
        if !(a >= 0.0 && b >= 0.0) {
            return None;
        }
        let (i, j) = (a as usize, b as usize);
        if i >= self.width || j >= self.height {
            return None;
        }
        let index = j * self.width + i;
        self.texels[index]
            .filter(|t| t.appears <= survey)
            .map(|_| index)
    }

    /// The 3D centre of texel (i, j).
    pub fn texel_centre(&self, i: usize, j: usize) -> DVec3 {
        self.origin
            + self.axis_u * ((i as f64 + 0.5) * self.texel)
            + self.axis_v * ((j as f64 + 0.5) * self.texel)
    }

    /// The four 3D corners of the decal's raster.
    pub fn corners(&self) -> [DVec3; 4] {
        let (w, h) = (
            self.width as f64 * self.texel,
            self.height as f64 * self.texel,
        );
        [
            self.origin,
            self.origin + self.axis_u * w,
            self.origin + self.axis_u * w + self.axis_v * h,
            self.origin + self.axis_v * h,
        ]
    }

    pub fn centre(&self) -> DVec3 {
        let [a, _, c, _] = self.corners();
        (a + c) * 0.5
    }

    /// Sets the final colours: the source colours moved to the facade's statistics, then shaded;
    /// rebar keeps its own colour, scaled to the facade's brightness.
    pub fn match_colours(&mut self, facade: ColourStats) {
        let brightness = (facade.mean.iter().sum::<f32>() / 3.0 / 0.5).clamp(0.4, 1.6);
        self.colours = self
            .texels
            .iter()
            .map(|t| match t {
                None => [0.0; 3],
                Some(t) if t.class == DamageClass::Rebar => {
                    t.source.map(|c| (c * brightness * t.shade).clamp(0.0, 1.0))
                }
                Some(t) => self
                    .source_stats
                    .transfer(t.source, &facade)
                    .map(|c| (c * t.shade).clamp(0.0, 1.0)),
            })
            .collect();
        self.facade_stats = Some(facade);
    }
}

/// The decal's frame on a plane: centred on `centre`, turned by `angle` from the plane's axes.
pub struct Placement {
    pub plane: usize,
    pub centre: DVec3,
    pub plane_u: DVec3,
    pub plane_v: DVec3,
    pub angle: f64,
    /// Model units per metre's inverse: metres per model unit.
    pub metres_per_unit: f64,
}

impl Placement {
    fn axes(&self) -> (DVec3, DVec3) {
        let (s, c) = self.angle.sin_cos();
        (
            self.plane_u * c + self.plane_v * s,
            -self.plane_u * s + self.plane_v * c,
        )
    }

    fn origin(&self, texel: f64, width: usize, height: usize) -> DVec3 {
        let (u, v) = self.axes();
        self.centre - u * (width as f64 * texel * 0.5) - v * (height as f64 * texel * 0.5)
    }
}

/// A crack decal from a real crack: `length_m` is its centre line's length in metres, widened
/// to a mean width of at least `min_width_m`; the part beyond `survey1_share` of its extent
/// along the main axis (from the end `flip` chooses) shows only from survey 2.
pub fn crack_decal(
    id: u32,
    source: &SourceCrack,
    place: &Placement,
    (length_m, min_width_m, survey1_share, flip): (f64, f64, f64, bool),
    first_survey: u32,
) -> Decal {
    let mask = &source.mask;
    let (w, h) = (mask.width as usize, mask.height as usize);
    let skeleton_px = super::quantities::skeleton_length(&mask.data, w, h).max(1.0);
    let texel = length_m / skeleton_px / place.metres_per_unit;
    // Widened to `min_width_m` by growing the real crack outwards, each new texel taking the
    // colour of the crack texel it grew from: the path stays the real one.
    let area_px = mask.data.iter().filter(|&&v| v != 0).count() as f64;
    let width_m = area_px / skeleton_px * texel * place.metres_per_unit;
    let grow_by = ((min_width_m - width_m) / (2.0 * texel * place.metres_per_unit)).ceil();
    let (crack, from) = widened(
        &mask.data,
        w,
        h,
        grow_by.clamp(0.0, MAX_WIDENING as f64) as usize,
    );
    let along = main_axis_positions(&crack, w, h);
    let texels = (0..w * h)
        .map(|i| {
            (crack[i] != 0).then(|| {
                let s = if flip { 1.0 - along[i] } else { along[i] };
                let f = from[i];
                Texel {
                    class: DamageClass::Crack,
                    appears: if first_survey == 2 || s > survey1_share {
                        2
                    } else {
                        1
                    },
                    source: source.photo.pixel((f % w) as u32, (f / w) as u32),
                    shade: 1.0,
                }
            })
        })
        .collect();
    let background = ColourStats::of(
        (0..w * h)
            .filter(|&i| mask.data[i] == 0)
            .map(|i| source.photo.pixel((i % w) as u32, (i / w) as u32)),
    );
    let (axis_u, axis_v) = place.axes();
    Decal {
        id,
        plane: place.plane,
        origin: place.origin(texel, w, h),
        axis_u,
        axis_v,
        texel,
        width: w,
        height: h,
        texels,
        colours: Vec::new(),
        source_stats: background.unwrap_or(ColourStats {
            mean: [0.5; 3],
            std: [0.1; 3],
        }),
        facade_stats: None,
        first_survey,
        source: Some(source.pair.photo.display().to_string()),
    }
}

/// The mask grown by `steps` 8-neighbour dilations, and for each set texel the original texel
/// it grew from (itself when original).
fn widened(data: &[u8], w: usize, h: usize, steps: usize) -> (Vec<u8>, Vec<usize>) {
    let mut set: Vec<u8> = data.iter().map(|&v| u8::from(v != 0)).collect();
    let mut from: Vec<usize> = (0..w * h).collect();
    for _ in 0..steps {
        let before = set.clone();
        for y in 0..h {
            for x in 0..w {
                if before[y * w + x] != 0 {
                    continue;
                }
                let neighbour = (y.saturating_sub(1)..=(y + 1).min(h - 1))
                    .flat_map(|yy| {
                        (x.saturating_sub(1)..=(x + 1).min(w - 1)).map(move |xx| yy * w + xx)
                    })
                    .find(|&j| before[j] != 0);
                if let Some(j) = neighbour {
                    set[y * w + x] = 1;
                    from[y * w + x] = from[j];
                }
            }
        }
    }
    (set, from)
}

/// Each set pixel's position along the set pixels' main axis, 0 at one end and 1 at the other.
fn main_axis_positions(data: &[u8], w: usize, _h: usize) -> Vec<f64> {
    let set: Vec<(f64, f64)> = (0..data.len())
        .filter(|&i| data[i] != 0)
        .map(|i| ((i % w) as f64, (i / w) as f64))
        .collect();
    let n = set.len().max(1) as f64;
    let (mx, my) = set
        .iter()
        .fold((0.0, 0.0), |acc, p| (acc.0 + p.0 / n, acc.1 + p.1 / n));
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for (x, y) in &set {
        sxx += (x - mx).powi(2);
        sxy += (x - mx) * (y - my);
        syy += (y - my).powi(2);
    }
    let angle = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    let (s, c) = angle.sin_cos();
    let project = |i: usize| ((i % w) as f64 - mx) * c + ((i / w) as f64 - my) * s;
    let lo = set
        .iter()
        .map(|p| (p.0 - mx) * c + (p.1 - my) * s)
        .fold(f64::INFINITY, f64::min);
    let hi = set
        .iter()
        .map(|p| (p.0 - mx) * c + (p.1 - my) * s)
        .fold(f64::NEG_INFINITY, f64::max);
    (0..data.len())
        .map(|i| ((project(i) - lo) / (hi - lo).max(1e-9)).clamp(0.0, 1.0))
        .collect()
}

/// A spall's seeded outline: radius `r(θ) = radius·(1 + Σ a_k cos(kθ + φ_k))`, k = 2…5.
#[derive(Clone, Debug, PartialEq)]
pub struct SpallShape {
    pub radius_m: f64,
    pub harmonics: Vec<(f64, f64)>,
    /// Survey 2's outline is this factor larger.
    pub growth: f64,
    /// Exposed bars in the core.
    pub rebar: bool,
    /// Main bars' spacing, diameter, and the tie's offset along the bars (metres).
    pub bar_spacing_m: f64,
    pub bar_diameter_m: f64,
    pub tie_offset_m: f64,
}

impl SpallShape {
    pub fn seeded(radius_m: f64, growth: f64, rebar: bool, rng: &mut fastrand::Rng) -> SpallShape {
        let harmonics = (2..=5)
            .map(|k| {
                (
                    0.3 * rng.f64() / (k as f64 - 1.0) / 2.09,
                    rng.f64() * std::f64::consts::TAU,
                )
            })
            .collect();
        SpallShape {
            radius_m,
            harmonics,
            growth,
            rebar,
            bar_spacing_m: radius_m * (0.45 + 0.2 * rng.f64()),
            bar_diameter_m: 0.016 + 0.008 * rng.f64(),
            tie_offset_m: radius_m * (rng.f64() - 0.5) * 0.6,
        }
    }

    /// The survey-1 outline's radius towards `theta`, metres.
    pub fn outline(&self, theta: f64) -> f64 {
        let wobble: f64 = self
            .harmonics
            .iter()
            .enumerate()
            .map(|(k, (a, phase))| a * ((k as f64 + 2.0) * theta + phase).cos())
            .sum();
        self.radius_m * (1.0 + wobble)
    }
}

/// Texels a crack grows by at most to reach its minimum width.
pub const MAX_WIDENING: usize = 20;

/// The share of a spall's outline its exposed core takes.
const CORE_SHARE: f64 = 0.72;
/// Spall texels are this many metres.
const SPALL_TEXEL_M: f64 = 0.004;
/// A rust colour for exposed bars (before the facade's brightness and shading).
const RUST: [f32; 3] = [0.45, 0.26, 0.15];

/// A spall decal: concrete texture from a real photo (`texture`'s pixels, tiled by mirroring)
/// moved to the facade's colours and darkened with depth; bars of rust in the core.
pub fn spall_decal(
    id: u32,
    shape: &SpallShape,
    texture: &RgbImage,
    place: &Placement,
    first_survey: u32,
) -> Decal {
    let texel = SPALL_TEXEL_M / place.metres_per_unit;
    let half_m = shape.radius_m * shape.growth * 1.35;
    let side = (2.0 * half_m / SPALL_TEXEL_M).ceil() as usize;
    let mut texels = Vec::with_capacity(side * side);
    for j in 0..side {
        for i in 0..side {
            let x = (i as f64 + 0.5) * SPALL_TEXEL_M - half_m;
            let y = (j as f64 + 0.5) * SPALL_TEXEL_M - half_m;
            let rho = x.hypot(y);
            let r1 = shape.outline(y.atan2(x));
            let r2 = r1 * shape.growth;
            let appears = |r: f64| if first_survey == 2 || rho > r { 2 } else { 1 };
            let source = mirrored(texture, i, j);
            let texel = if shape.rebar && rho <= CORE_SHARE * r2 && on_bar(shape, x, y).is_some() {
                let d = on_bar(shape, x, y).unwrap_or(0.0);
                let grain = 0.85 + 0.3 * source.iter().sum::<f32>() / 3.0;
                Some(Texel {
                    class: DamageClass::Rebar,
                    appears: appears(CORE_SHARE * r1),
                    source: RUST.map(|c| c * grain),
                    shade: (0.55 + 0.45 * (1.0 - d * d).max(0.0).sqrt()) as f32,
                })
            } else if rho <= r2 {
                Some(Texel {
                    class: DamageClass::Spalling,
                    appears: appears(r1),
                    source,
                    shade: (0.58 + 0.22 * rho / r2) as f32,
                })
            } else {
                None
            };
            texels.push(texel);
        }
    }
    let stats = ColourStats::of(texture.data.chunks_exact(3).map(|c| [c[0], c[1], c[2]]));
    let (axis_u, axis_v) = place.axes();
    Decal {
        id,
        plane: place.plane,
        origin: place.origin(texel, side, side),
        axis_u,
        axis_v,
        texel,
        width: side,
        height: side,
        texels,
        colours: Vec::new(),
        source_stats: stats.unwrap_or(ColourStats {
            mean: [0.5; 3],
            std: [0.1; 3],
        }),
        facade_stats: None,
        first_survey,
        source: None,
    }
}

/// Where (x, y) metres from a spall's centre lies on a bar: its distance from the bar's axis
/// over the bar's radius, in [0, 1]. Two main bars run along u, one tie along v.
fn on_bar(shape: &SpallShape, x: f64, y: f64) -> Option<f64> {
    let radius = shape.bar_diameter_m * 0.5;
    let main = [-0.5, 0.5]
        .iter()
        .map(|k| (y - k * shape.bar_spacing_m).abs())
        .fold(f64::INFINITY, f64::min);
    let tie_radius = radius * 0.7;
    let tie = (x - shape.tie_offset_m).abs();
    if main <= radius {
        Some(main / radius)
    } else if tie <= tie_radius {
        Some(tie / tie_radius)
    } else {
        None
    }
}

/// The texture pixel for texel (i, j), the texture tiled by mirroring.
fn mirrored(texture: &RgbImage, i: usize, j: usize) -> [f32; 3] {
    let fold = |k: usize, n: u32| {
        let n = n.max(1) as usize;
        let m = k % (2 * n);
        (if m < n { m } else { 2 * n - 1 - m }) as u32
    };
    texture.pixel(fold(i, texture.width), fold(j, texture.height))
}
