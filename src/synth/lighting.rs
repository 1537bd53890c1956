//! Light for the synthetic photos: a sun, a sky dome (gradient, sun glow, thin clouds) that
//! also lights surfaces as ambient, per-survey variations, tone mapping, and ambient occlusion
//! baked once per scene on a world-space texel grid (view-consistent and cheap per pixel).

use glam::{Vec2, Vec3};
use rayon::prelude::*;

use super::building::Building;
use super::geometry::{GROUND, Geometry, Hit, Ray, face_uv_axes};
use super::noise::{fbm, hash_u32, unit};

#[derive(Clone, Debug, serde::Serialize, serde::Deserialize, PartialEq)]
pub struct Lighting {
    /// Unit vector towards the sun.
    pub sun_direction: [f32; 3],
    pub sun_colour: [f32; 3],
    pub sky_zenith: [f32; 3],
    pub sky_horizon: [f32; 3],
    pub ambient: [f32; 3],
    pub exposure: f32,
    /// The camera's per-channel gains on linear radiance before the tone curve (its white
    /// balance); 1 for survey 1.
    #[serde(default = "unit_gains")]
    pub white_balance: [f32; 3],
}

fn unit_gains() -> [f32; 3] {
    [1.0; 3]
}

impl Lighting {
    /// The light of survey `survey` (1-based): the sun moves and the sky warms between dates,
    /// and the camera exposes and white-balances survey 2 differently, as on another day's
    /// flight. Sun and sky alone changed the facades' mean brightness by -5.7 % and their
    /// white balance (B/G) by -3.0 %, at the edge of what an appearance model would notice;
    /// with exposure 0.82 and these gains, -11.5 % and -8.0 % (tests/synth_lighting.rs).
    pub fn for_survey(survey: u32) -> Lighting {
        let (azimuth, elevation, warm, exposure, white_balance) = if survey <= 1 {
            (-2.2f32, 0.85f32, 0.0, 1.0, [1.0; 3])
        } else {
            (-1.75, 0.7, 0.08, 0.82, [1.06, 1.0, 0.88])
        };
        let dir = Vec3::new(
            elevation.cos() * azimuth.cos(),
            elevation.cos() * azimuth.sin(),
            elevation.sin(),
        );
        Lighting {
            sun_direction: dir.to_array(),
            sun_colour: [2.7, 2.45 - warm, 2.15 - 2.0 * warm],
            sky_zenith: [0.22, 0.36, 0.68],
            sky_horizon: [0.62 + warm, 0.72, 0.84 - warm],
            ambient: [0.42 + 0.5 * warm, 0.5, 0.62 - warm],
            exposure,
            white_balance,
        }
    }

    pub fn sun(&self) -> Vec3 {
        Vec3::from_array(self.sun_direction)
    }

    /// Sky radiance in direction `dir`; below the horizon a dim ground colour (for reflections).
    pub fn sky(&self, dir: Vec3, seed: u32) -> Vec3 {
        let horizon = Vec3::from_array(self.sky_horizon);
        if dir.z < 0.0 {
            return Vec3::new(0.12, 0.12, 0.1)
                .lerp(horizon * 0.8, (1.0 + dir.z * 6.0).clamp(0.0, 1.0));
        }
        let zenith = Vec3::from_array(self.sky_zenith);
        let mut c = horizon.lerp(zenith, dir.z.sqrt());
        let p = Vec2::new(dir.x, dir.y) / (dir.z + 0.15);
        let cloud = fbm(seed ^ 0xc10d, p.x * 1.6, p.y * 1.6, 5, 0.01);
        let cloud = ((cloud - 0.52) * 3.0).clamp(0.0, 1.0) * (dir.z * 4.0).clamp(0.0, 1.0);
        c = c.lerp(Vec3::new(0.85, 0.86, 0.88), 0.8 * cloud);
        let glow = dir.dot(self.sun()).max(0.0).powi(200);
        c + Vec3::from_array(self.sun_colour) * 0.6 * glow
    }

    /// Linear radiance to display sRGB-ish values in `[0, 1]`: exponential tone curve + gamma.
    pub fn tonemap(&self, c: Vec3) -> Vec3 {
        // Unit gains multiply exactly, so survey 1's pixels are what they were before the gains.
        let gains = Vec3::from_array(self.white_balance);
        let m = Vec3::ONE - (-c * gains * self.exposure * 1.1).exp();
        m.powf(1.0 / 2.2)
    }
}

#[derive(Clone, Copy, Debug)]
struct FaceMap {
    offset: u32,
    nu: u32,
    nv: u32,
    u0: f32,
    v0: f32,
}

/// Baked ambient occlusion for every box face and a patch of ground around the building.
pub struct AoMaps {
    faces: Vec<FaceMap>,
    data: Vec<f32>,
    ground: FaceMap,
}

const TEXEL: f32 = 0.12;
const GROUND_TEXEL: f32 = 0.2;
const AO_RAYS: u32 = 16;
const AO_DISTANCE: f32 = 1.6;

impl AoMaps {
    pub fn bake(geometry: &Geometry, building: &Building) -> AoMaps {
        let mut faces = Vec::with_capacity(geometry.prims.len() * 6);
        let mut total = 0u32;
        for prim in &geometry.prims {
            for face in 0..6u8 {
                let (ua, va) = face_uv_axes((face / 2) as usize);
                let nu = ((prim.max[ua] - prim.min[ua]) / TEXEL).ceil() as u32 + 1;
                let nv = ((prim.max[va] - prim.min[va]) / TEXEL).ceil() as u32 + 1;
                faces.push(FaceMap {
                    offset: total,
                    nu,
                    nv,
                    u0: prim.min[ua],
                    v0: prim.min[va],
                });
                total += nu * nv;
            }
        }
        let gmin = building.min - Vec3::splat(6.0);
        let gmax = building.max + Vec3::splat(6.0);
        let ground = FaceMap {
            offset: total,
            nu: ((gmax.x - gmin.x) / GROUND_TEXEL).ceil() as u32 + 1,
            nv: ((gmax.y - gmin.y) / GROUND_TEXEL).ceil() as u32 + 1,
            u0: gmin.x,
            v0: gmin.y,
        };
        total += ground.nu * ground.nv;
        // One entry per texel: (prim or GROUND, face, i, j); evaluated in parallel, in order.
        let mut jobs = Vec::with_capacity(total as usize);
        for (fi, m) in faces.iter().enumerate() {
            for j in 0..m.nv {
                for i in 0..m.nu {
                    jobs.push((fi as u32, i, j));
                }
            }
        }
        for j in 0..ground.nv {
            for i in 0..ground.nu {
                jobs.push((u32::MAX, i, j));
            }
        }
        let data = jobs
            .par_iter()
            .map(|&(fi, i, j)| {
                if fi == u32::MAX {
                    let p = Vec3::new(
                        ground.u0 + i as f32 * GROUND_TEXEL,
                        ground.v0 + j as f32 * GROUND_TEXEL,
                        0.0,
                    );
                    return occlusion(geometry, p, Vec3::Z, hash_u32(i ^ (j << 16) ^ 0xabc));
                }
                let prim = &geometry.prims[(fi / 6) as usize];
                let face = (fi % 6) as u8;
                let axis = (face / 2) as usize;
                let (ua, va) = face_uv_axes(axis);
                let m = &faces[fi as usize];
                let mut p = Vec3::ZERO;
                p[axis] = if face % 2 == 1 {
                    prim.max[axis]
                } else {
                    prim.min[axis]
                };
                p[ua] = (m.u0 + i as f32 * TEXEL).min(prim.max[ua]);
                p[va] = (m.v0 + j as f32 * TEXEL).min(prim.max[va]);
                let n = super::geometry::face_normal(face);
                occlusion(geometry, p, n, hash_u32(fi ^ (i << 12) ^ (j << 22)))
            })
            .collect();
        AoMaps {
            faces,
            data,
            ground,
        }
    }

    /// Ambient visibility in `[0, 1]` at a hit, bilinear between texels.
    pub fn at(&self, hit: &Hit, p: Vec3) -> f32 {
        if hit.prim == GROUND {
            let g = &self.ground;
            let (x, y) = ((p.x - g.u0) / GROUND_TEXEL, (p.y - g.v0) / GROUND_TEXEL);
            if !(x >= 0.0 && y >= 0.0 && x < (g.nu - 1) as f32 && y < (g.nv - 1) as f32) {
                return 1.0;
            }
            return self.bilinear(g, x, y);
        }
        let fi = hit.prim as usize * 6 + hit.face as usize;
        let Some(m) = self.faces.get(fi) else {
            return 1.0;
        };
        let (ua, va) = face_uv_axes((hit.face / 2) as usize);
        let x = ((p[ua] - m.u0) / TEXEL).clamp(0.0, (m.nu - 1) as f32);
        let y = ((p[va] - m.v0) / TEXEL).clamp(0.0, (m.nv - 1) as f32);
        self.bilinear(m, x, y)
    }

    fn bilinear(&self, m: &FaceMap, x: f32, y: f32) -> f32 {
        let (i, j) = (x.floor() as u32, y.floor() as u32);
        let (i1, j1) = ((i + 1).min(m.nu - 1), (j + 1).min(m.nv - 1));
        let (fx, fy) = (x - i as f32, y - j as f32);
        let at = |a: u32, b: u32| self.data[(m.offset + b * m.nu + a) as usize];
        let top = at(i, j) + (at(i1, j) - at(i, j)) * fx;
        let bottom = at(i, j1) + (at(i1, j1) - at(i, j1)) * fx;
        top + (bottom - top) * fy
    }
}

/// Fraction of cosine-weighted hemisphere rays that escape within `AO_DISTANCE`.
fn occlusion(geometry: &Geometry, p: Vec3, n: Vec3, rotation: u32) -> f32 {
    let (t, b) = n.any_orthonormal_pair();
    let phi0 = unit(rotation) * std::f32::consts::TAU;
    let origin = p + n * 2e-3;
    let mut open = 0u32;
    for k in 0..AO_RAYS {
        // 4 x 4 stratified cosine-weighted directions, rotated per texel.
        let (a, c) = (k % 4, k / 4);
        let r = ((a as f32 + 0.5) / 4.0).sqrt();
        let phi = phi0 + (c as f32 + 0.5) / 4.0 * std::f32::consts::TAU + a as f32 * 0.7;
        let d = t * (r * phi.cos()) + b * (r * phi.sin()) + n * (1.0 - r * r).max(0.0).sqrt();
        if !geometry.occluded(&Ray::new(origin, d.normalize()), AO_DISTANCE) {
            open += 1;
        }
    }
    open as f32 / AO_RAYS as f32
}
