//! Procedural surface textures evaluated at hit points: brick, concrete, plaster, window frames,
//! glass, metal, the ground, and the exposed concrete and rebar of damage. Returns linear albedo;
//! must not light, trace rays or decide masks.

use glam::{Vec2, Vec3};

use super::geometry::{Component, Material};
use super::noise::{fbm, filtered_stripes, hash_u32, hash2, unit, value_noise};

/// Inputs of a texture lookup: texture coordinates (world metres), the pixel footprint there,
/// and a seed that varies the look per box or per facade.
#[derive(Clone, Copy, Debug)]
pub struct TexturePoint {
    pub uv: Vec2,
    pub position: Vec3,
    pub filter: f32,
    pub seed: u32,
    /// Storey index (window frames of a floor share a colour).
    pub floor: u32,
    pub facade_seed: u32,
}

/// What a glass pane shows: the interior seen through it and how much it reflects.
#[derive(Clone, Copy, Debug)]
pub struct GlassLook {
    pub interior: Vec3,
    pub reflectivity: f32,
}

pub fn albedo(material: Material, component: Component, t: &TexturePoint) -> Vec3 {
    match material {
        Material::Brick => brick(t),
        Material::Concrete => concrete(t, component),
        Material::Plaster => plaster(t),
        Material::Frame => frame(t),
        Material::Glass => glass(t).interior,
        Material::Metal => metal(t),
    }
}

/// Vertical dirt streaks and a darker splash zone near the ground: weathering in one factor.
fn weathering(t: &TexturePoint, strength: f32) -> f32 {
    let streak = fbm(
        t.facade_seed ^ 0x77,
        t.uv.x * 5.0,
        t.uv.y * 0.35,
        3,
        t.filter * 5.0,
    );
    let streak = ((streak - 0.5) * 2.5).clamp(0.0, 1.0);
    let splash = (1.0 - t.position.z / 0.8).clamp(0.0, 1.0);
    1.0 - strength * (0.3 * streak + 0.3 * splash)
}

fn brick(t: &TexturePoint) -> Vec3 {
    const COURSE: f32 = 0.077;
    const LENGTH: f32 = 0.227;
    const JOINT: f32 = 0.012;
    let (u, v) = (t.uv.x, t.uv.y);
    let row = (v / COURSE).floor() as i32;
    let u_off = u + if row & 1 == 1 { 0.5 * LENGTH } else { 0.0 };
    let col = (u_off / LENGTH).floor() as i32;
    let h = hash2(t.facade_seed, col, row);
    let palette = [
        Vec3::new(0.32, 0.11, 0.06),
        Vec3::new(0.40, 0.16, 0.09),
        Vec3::new(0.26, 0.09, 0.05),
        Vec3::new(0.44, 0.22, 0.13),
        Vec3::new(0.35, 0.13, 0.08),
    ];
    let mean = Vec3::new(0.354, 0.142, 0.082);
    let own = palette[(h % 5) as usize] * (0.85 + 0.3 * unit(hash_u32(h)));
    // Far away a brick is smaller than a pixel: blend to the mean instead of aliasing.
    let far = (t.filter / 0.06).clamp(0.0, 1.0);
    let mut c = own.lerp(mean, far);
    let grain = fbm(t.facade_seed ^ 0x11, u * 18.0, v * 18.0, 3, t.filter * 18.0);
    c *= 0.8 + 0.4 * grain;
    let joint = filtered_stripes(v, COURSE, JOINT, t.filter)
        .max(filtered_stripes(u_off, LENGTH, JOINT, t.filter) * (1.0 - far));
    let mortar = Vec3::new(0.42, 0.40, 0.36);
    c = c.lerp(mortar, joint);
    let tone = fbm(t.facade_seed ^ 0x2, u * 0.6, v * 0.6, 4, t.filter * 0.6);
    c * (0.75 + 0.5 * tone) * weathering(t, 1.0)
}

fn concrete(t: &TexturePoint, component: Component) -> Vec3 {
    let (u, v) = (t.uv.x, t.uv.y);
    let base = if component == Component::Slab {
        Vec3::new(0.40, 0.39, 0.37)
    } else {
        Vec3::new(0.46, 0.45, 0.42)
    };
    let tone = fbm(t.facade_seed ^ 0x3, u * 1.5, v * 1.5, 6, t.filter * 1.5);
    let pores = fbm(t.facade_seed ^ 0x44, u * 45.0, v * 45.0, 2, t.filter * 45.0);
    let pores = 1.0 - 0.35 * ((pores - 0.62) * 6.0).clamp(0.0, 1.0);
    // Faint horizontal formwork joints every 0.6 m.
    let joint = 1.0 - 0.2 * filtered_stripes(v + 0.1, 0.6, 0.01, t.filter);
    base * (0.72 + 0.56 * tone) * pores * joint * weathering(t, 0.9)
}

fn plaster(t: &TexturePoint) -> Vec3 {
    let (u, v) = (t.uv.x, t.uv.y);
    let tints = [
        Vec3::new(0.62, 0.52, 0.36),
        Vec3::new(0.55, 0.55, 0.50),
        Vec3::new(0.60, 0.42, 0.30),
    ];
    let base = tints[(t.facade_seed % 3) as usize];
    let tone = fbm(t.facade_seed ^ 0x5, u * 2.0, v * 2.0, 6, t.filter * 2.0);
    let patches = fbm(t.facade_seed ^ 0x6, u * 0.5, v * 0.5, 3, t.filter * 0.5);
    let patch = ((patches - 0.6) * 5.0).clamp(0.0, 1.0);
    let fine = fbm(t.facade_seed ^ 0x77, u * 30.0, v * 30.0, 2, t.filter * 30.0);
    let c = base * (0.8 + 0.4 * tone) * (0.92 + 0.16 * fine);
    c.lerp(base * 0.65, 0.6 * patch) * weathering(t, 1.2)
}

fn frame(t: &TexturePoint) -> Vec3 {
    let colours = [
        Vec3::new(0.75, 0.75, 0.72),
        Vec3::new(0.10, 0.10, 0.11),
        Vec3::new(0.22, 0.12, 0.06),
    ];
    let c = colours[(hash2(t.facade_seed, t.floor as i32, 9) % 3) as usize];
    let n = value_noise(t.seed, t.uv.x * 8.0, t.uv.y * 8.0);
    c * (0.9 + 0.2 * n)
}

/// Pane looks vary per pane: dark glass, tinted glass, curtains, blinds, a broken pane.
pub fn glass(t: &TexturePoint) -> GlassLook {
    let h = hash_u32(t.seed);
    let (u, v) = (t.uv.x, t.uv.y);
    let kind = h % 10;
    let interior = match kind {
        0..=3 => Vec3::new(0.03, 0.04, 0.05),
        4 | 5 => Vec3::new(0.03, 0.06, 0.05),
        6 | 7 => {
            let fold = 0.75 + 0.25 * (u * 25.0 + 3.0 * value_noise(h, u * 3.0, v)).sin();
            Vec3::new(0.45, 0.38, 0.26) * fold
        }
        8 => {
            let slat = filtered_stripes(v, 0.05, 0.012, t.filter);
            Vec3::new(0.5, 0.5, 0.48).lerp(Vec3::splat(0.15), slat)
        }
        _ => Vec3::splat(0.01),
    };
    let reflectivity = match kind {
        9 => 0.0,
        6..=8 => 0.12,
        _ => 0.3,
    };
    GlassLook {
        interior,
        reflectivity,
    }
}

fn metal(t: &TexturePoint) -> Vec3 {
    let n = fbm(t.seed, t.uv.x * 3.0, t.uv.y * 3.0, 4, t.filter * 3.0);
    let rust = fbm(t.seed ^ 0x8, t.uv.x * 6.0, t.uv.y * 6.0, 3, t.filter * 6.0);
    let rust = ((rust - 0.6) * 4.0).clamp(0.0, 1.0);
    Vec3::new(0.33, 0.35, 0.36).lerp(Vec3::new(0.25, 0.1, 0.04), rust) * (0.8 + 0.4 * n)
}

/// The ground at world `(x, y)`: paving around the building, grass, and a road in front.
pub fn ground(p: Vec2, footprint_min: Vec2, footprint_max: Vec2, filter: f32, seed: u32) -> Vec3 {
    let dx = (footprint_min.x - p.x).max(p.x - footprint_max.x).max(0.0);
    let dy = (footprint_min.y - p.y).max(p.y - footprint_max.y).max(0.0);
    let dist = (dx * dx + dy * dy).sqrt();
    let tone = fbm(seed ^ 0x9, p.x * 0.8, p.y * 0.8, 5, filter * 0.8);
    let fine = fbm(seed ^ 0xa, p.x * 12.0, p.y * 12.0, 3, filter * 12.0);
    let road = p.y < footprint_min.y - 11.0 && p.y > footprint_min.y - 17.0;
    if road {
        let dash = filtered_stripes(p.y - (footprint_min.y - 14.0), 1e3, 0.12, filter)
            * filtered_stripes(p.x, 3.0, 1.5, filter);
        let asphalt = Vec3::new(0.07, 0.07, 0.075) * (0.8 + 0.4 * fine) * (0.85 + 0.3 * tone);
        return asphalt.lerp(Vec3::splat(0.6), dash);
    }
    if dist < 2.4 {
        let joints = filtered_stripes(p.x, 0.6, 0.015, filter)
            .max(filtered_stripes(p.y, 0.6, 0.015, filter));
        let tile = hash2(seed, (p.x / 0.6).floor() as i32, (p.y / 0.6).floor() as i32);
        let c = Vec3::new(0.33, 0.32, 0.30) * (0.85 + 0.3 * unit(tile)) * (0.8 + 0.4 * fine);
        let dust = Vec3::new(0.38, 0.35, 0.30);
        return c
            .lerp(Vec3::splat(0.12), joints)
            .lerp(dust, 0.4 * ((tone - 0.5) * 3.0).clamp(0.0, 1.0));
    }
    let grass = Vec3::new(0.10, 0.16, 0.05) * (0.7 + 0.6 * fine);
    let dirt = Vec3::new(0.22, 0.18, 0.12) * (0.8 + 0.4 * fine);
    grass.lerp(dirt, ((tone - 0.55) * 4.0).clamp(0.0, 1.0)) * (0.8 + 0.4 * tone)
}

/// Exposed concrete in a spall: rough, darker, with aggregate, deeper towards the centre.
pub fn spalled(t: &TexturePoint, depth: f32) -> Vec3 {
    let (u, v) = (t.uv.x, t.uv.y);
    let rough = fbm(t.facade_seed ^ 0xb, u * 22.0, v * 22.0, 4, t.filter * 22.0);
    let aggregate = fbm(t.facade_seed ^ 0xc, u * 60.0, v * 60.0, 2, t.filter * 60.0);
    let stones = ((aggregate - 0.6) * 5.0).clamp(0.0, 1.0);
    let c = Vec3::new(0.27, 0.26, 0.24) * (0.55 + 0.9 * rough);
    c.lerp(Vec3::new(0.38, 0.36, 0.33), 0.5 * stones) * (1.0 - 0.35 * depth)
}

/// Rusty reinforcing steel.
pub fn rebar(t: &TexturePoint) -> Vec3 {
    let n = fbm(
        t.facade_seed ^ 0xd,
        t.uv.x * 40.0,
        t.uv.y * 40.0,
        3,
        t.filter * 40.0,
    );
    Vec3::new(0.30, 0.12, 0.05) * (0.6 + 0.8 * n)
}
