//! The ray tracer for one view: a centre ray per pixel gives the masks, component label and
//! depth (so they agree with the photo by construction); pixels on geometric edges get 4
//! rotated-grid samples for the colour. Rows in parallel; each pixel depends only on its coordinates.

use glam::{Vec2, Vec3};
use rayon::prelude::*;

use super::building::Building;
use super::damage::{DamageState, damage_facade};
use super::geometry::{Component, GROUND, Geometry, Material, Ray, face_normal, face_uv_axes};
use super::lighting::{AoMaps, Lighting};
use super::materials::{self, TexturePoint};
use super::noise::{self, hash3};
use crate::scene::Camera;

/// Everything a view needs to be rendered.
pub struct SceneContext<'a> {
    pub building: &'a Building,
    pub geometry: &'a Geometry,
    pub ao: &'a AoMaps,
    pub lighting: &'a Lighting,
    pub damage: &'a DamageState,
    /// The previous survey's damage, for the new-damage masks.
    pub previous: Option<&'a DamageState>,
    /// The textureless variant: flat component colours, no lighting.
    pub flat: bool,
    pub seed: u32,
}

/// One rendered view. Class bitmasks use bit `k` for `DamageClass::ALL[k]`.
pub struct ViewRender {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<u8>,
    pub classes: Vec<u8>,
    pub new_classes: Vec<u8>,
    pub components: Vec<u8>,
    /// Camera-space z (metres) of the centre sample, 0 for sky.
    pub depth: Vec<f32>,
}

#[derive(Clone, Copy, Debug, Default)]
struct Sample {
    colour: Vec3,
    key: u32,
    component: u8,
    classes: u8,
    new_classes: u8,
    z: f32,
}

const SKY_KEY: u32 = u32::MAX - 1;
/// Rotated-grid 4x supersampling offsets (within the pixel).
const SUBSAMPLES: [(f32, f32); 4] = [
    (0.375, 0.125),
    (0.875, 0.375),
    (0.125, 0.625),
    (0.625, 0.875),
];

pub fn render_view(ctx: &SceneContext, camera: &Camera) -> ViewRender {
    let k = camera.intrinsics;
    let (w, h) = (k.width as usize, k.height as usize);
    let r_t = camera.rotation_matrix().transpose();
    let eye = camera.position();
    let pixel_angle = 1.0 / k.fx.max(1e-3);
    let shade_at = |x: f32, y: f32| {
        let d = Vec3::new((x - k.cx) / k.fx, (y - k.cy) / k.fy, 1.0);
        let len = d.length();
        shade(ctx, &Ray::new(eye, r_t * (d / len)), 1.0 / len, pixel_angle)
    };
    let mut samples = vec![Sample::default(); w * h];
    samples.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, s) in row.iter_mut().enumerate() {
            *s = shade_at(x as f32 + 0.5, y as f32 + 0.5);
        }
    });
    let mut rgb = vec![0u8; w * h * 3];
    rgb.par_chunks_mut(w * 3).enumerate().for_each(|(y, row)| {
        for x in 0..w {
            let s = &samples[y * w + x];
            let edge = (x > 0 && samples[y * w + x - 1].key != s.key)
                || (x + 1 < w && samples[y * w + x + 1].key != s.key)
                || (y > 0 && samples[(y - 1) * w + x].key != s.key)
                || (y + 1 < h && samples[(y + 1) * w + x].key != s.key);
            let colour = if edge {
                let mut sum = Vec3::ZERO;
                for (ox, oy) in SUBSAMPLES {
                    sum += shade_at(x as f32 + ox, y as f32 + oy).colour;
                }
                sum * 0.25
            } else {
                s.colour
            };
            for c in 0..3 {
                row[x * 3 + c] = (colour[c].clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
            }
        }
    });
    ViewRender {
        width: k.width,
        height: k.height,
        rgb,
        classes: samples.iter().map(|s| s.classes).collect(),
        new_classes: samples.iter().map(|s| s.new_classes).collect(),
        components: samples.iter().map(|s| s.component).collect(),
        depth: samples.iter().map(|s| s.z).collect(),
    }
}

fn class_bit(class: Option<crate::scene::DamageClass>) -> u8 {
    class.map_or(0, |c| 1 << c.channel())
}

/// Shades one camera ray: colour after tone mapping, plus the truth of what it hit.
fn shade(ctx: &SceneContext, ray: &Ray, z_per_t: f32, pixel_angle: f32) -> Sample {
    let light = ctx.lighting;
    let Some(hit) = ctx.geometry.intersect(ray, 1e4) else {
        let colour = if ctx.flat {
            Component::Sky.flat_colour()
        } else {
            light.sky(ray.dir, ctx.seed)
        };
        return Sample {
            colour: light.tonemap(colour).min(Vec3::ONE),
            key: SKY_KEY,
            ..Sample::default()
        };
    };
    let p = ray.at(hit.t);
    let (normal, component, material, prim_seed) = if hit.prim == GROUND {
        (Vec3::Z, Component::Ground, None, 0)
    } else {
        let prim = &ctx.geometry.prims[hit.prim as usize];
        (
            face_normal(hit.face),
            prim.component,
            Some(prim.material),
            prim.seed,
        )
    };
    let cos = normal.dot(ray.dir).abs();
    // Pixel footprint on the surface: the geometric mean of its two axes.
    let filter = hit.t * pixel_angle / cos.max(0.15).sqrt();
    let (ua, va) = face_uv_axes((hit.face / 2) as usize);
    let tex = TexturePoint {
        uv: Vec2::new(p[ua], p[va]),
        position: p,
        filter,
        seed: prim_seed,
        floor: (p.z / ctx.building.spec.storey).max(0.0) as u32,
        facade_seed: hash3(ctx.seed, hit.face as u32, 41, 0),
    };
    let mut albedo = match material {
        None => {
            let b = ctx.building;
            let lo = Vec2::new(b.min.x, b.min.y);
            let hi = Vec2::new(b.max.x, b.max.y);
            materials::ground(Vec2::new(p.x, p.y), lo, hi, filter, ctx.seed)
        }
        Some(m) => materials::albedo(m, component, &tex),
    };
    if ctx.flat {
        albedo = component.flat_colour();
    }

    let mut sample = Sample {
        // Coplanar boxes of one material (wall pieces around a window) share a key, so only
        // real edges get supersampled.
        key: if hit.prim == GROUND {
            GROUND
        } else {
            let prim = &ctx.geometry.prims[hit.prim as usize];
            let axis = (hit.face / 2) as usize;
            let plane = if hit.face % 2 == 1 {
                prim.max[axis]
            } else {
                prim.min[axis]
            };
            noise::hash3(
                (plane * 1000.0).round() as i32 as u32,
                hit.face as u32,
                prim.material as u32,
                prim.component as u32,
            ) & 0x7fff_ffff
        },
        component: component.id(),
        z: hit.t * z_per_t,
        ..Sample::default()
    };
    let mut cavity = 0.0;
    if hit.prim != GROUND {
        let prim = &ctx.geometry.prims[hit.prim as usize];
        if let Some((f, uv)) = damage_facade(ctx.building, prim, hit.face, p) {
            let d = ctx.damage.eval(f, uv, filter);
            sample.classes = class_bit(d.class);
            if let (Some(prev), Some(_)) = (ctx.previous, d.class)
                && prev.eval(f, uv, filter).class != d.class
            {
                sample.new_classes = sample.classes;
            }
            let (spall, rebar, crack) = if ctx.flat {
                (
                    Vec3::splat(0.25),
                    Vec3::new(0.4, 0.15, 0.04),
                    Vec3::splat(0.03),
                )
            } else {
                (
                    materials::spalled(&tex, d.spall_depth),
                    materials::rebar(&tex),
                    albedo * 0.06,
                )
            };
            albedo = albedo.lerp(spall, d.spall);
            albedo = albedo.lerp(rebar, d.rebar);
            albedo = albedo.lerp(crack, d.crack);
            cavity = d.spall * (0.3 + 0.4 * d.spall_depth) * (1.0 - d.rebar);
        }
    }
    if ctx.flat {
        sample.colour = light.tonemap(albedo * 1.6).min(Vec3::ONE);
        return sample;
    }

    let sun = light.sun();
    let ndl = normal.dot(sun);
    let mut direct = 0.0;
    if ndl > 0.0 {
        let shadow = Ray::new(p + normal * 2e-3, sun);
        if !ctx.geometry.occluded(&shadow, 500.0) {
            direct = ndl * (1.0 - 0.4 * cavity);
        }
    }
    let ao = ctx.ao.at(&hit, p) * (1.0 - 0.6 * cavity);
    let ambient = Vec3::from_array(light.ambient) * ao * (0.6 + 0.4 * normal.z);
    let bounce = Vec3::new(0.16, 0.15, 0.12) * ao * (0.5 - 0.5 * normal.z);
    let mut radiance = albedo * (Vec3::from_array(light.sun_colour) * direct + ambient + bounce);
    if material == Some(Material::Glass) {
        let look = materials::glass(&tex);
        let reflected = ray.dir - 2.0 * ray.dir.dot(normal) * normal;
        let fresnel = look.reflectivity * (0.35 + 0.65 * (1.0 - cos).powi(4));
        radiance = look.interior * 1.2 * (1.0 - fresnel) + light.sky(reflected, ctx.seed) * fresnel;
    }
    let haze = 1.0 - (-hit.t / 400.0).exp();
    radiance = radiance.lerp(Vec3::from_array(light.sky_horizon), haze);
    sample.colour = light.tonemap(radiance).min(Vec3::ONE);
    sample
}
