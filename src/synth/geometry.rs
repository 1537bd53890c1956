//! The scene's primitives: axis-aligned boxes tagged with a component and a material, a ground
//! plane at z = 0, analytic ray-box intersection and a small BVH over the boxes.
//! Knows nothing of textures, damage or lighting.

use glam::Vec3;

/// QuakeCity's component classes (plus sky, ground and other). The numeric id is the value
/// written in `truth/components/*.png`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Component {
    Sky = 0,
    Ground = 1,
    Wall = 2,
    Column = 3,
    Beam = 4,
    Slab = 5,
    WindowFrame = 6,
    WindowPane = 7,
    Balcony = 8,
    Other = 9,
}

impl Component {
    pub const ALL: [Component; 10] = [
        Component::Sky,
        Component::Ground,
        Component::Wall,
        Component::Column,
        Component::Beam,
        Component::Slab,
        Component::WindowFrame,
        Component::WindowPane,
        Component::Balcony,
        Component::Other,
    ];

    pub fn id(self) -> u8 {
        self as u8
    }

    pub fn name(self) -> &'static str {
        match self {
            Component::Sky => "sky",
            Component::Ground => "ground",
            Component::Wall => "wall",
            Component::Column => "column",
            Component::Beam => "beam",
            Component::Slab => "slab",
            Component::WindowFrame => "window-frame",
            Component::WindowPane => "window-pane",
            Component::Balcony => "balcony",
            Component::Other => "other",
        }
    }

    /// The flat colour of the textureless variant (linear RGB).
    pub fn flat_colour(self) -> Vec3 {
        match self {
            Component::Sky => Vec3::new(0.55, 0.7, 0.9),
            Component::Ground => Vec3::new(0.35, 0.4, 0.3),
            Component::Wall => Vec3::new(0.8, 0.6, 0.45),
            Component::Column => Vec3::new(0.6, 0.6, 0.62),
            Component::Beam => Vec3::new(0.45, 0.5, 0.6),
            Component::Slab => Vec3::new(0.7, 0.7, 0.6),
            Component::WindowFrame => Vec3::new(0.95, 0.95, 0.95),
            Component::WindowPane => Vec3::new(0.15, 0.25, 0.35),
            Component::Balcony => Vec3::new(0.6, 0.45, 0.6),
            Component::Other => Vec3::new(0.5, 0.4, 0.3),
        }
    }
}

/// Which procedural texture a box's faces get.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Material {
    Brick,
    Plaster,
    Concrete,
    Frame,
    Glass,
    Metal,
}

/// An axis-aligned box; `seed` varies its texture (pane tint, frame colour, brick hue).
#[derive(Clone, Copy, Debug)]
pub struct Prim {
    pub min: Vec3,
    pub max: Vec3,
    pub component: Component,
    pub material: Material,
    pub seed: u32,
}

impl Prim {
    pub fn new(min: Vec3, max: Vec3, component: Component, material: Material, seed: u32) -> Prim {
        Prim {
            min: min.min(max),
            max: min.max(max),
            component,
            material,
            seed,
        }
    }
}

/// Faces are numbered `axis * 2 + (normal points to +axis) as u8`.
pub fn face_normal(face: u8) -> Vec3 {
    let mut n = Vec3::ZERO;
    n[(face / 2) as usize] = if face % 2 == 1 { 1.0 } else { -1.0 };
    n
}

/// The texture axes of a face with normal along `axis`: vertical faces map (horizontal, z),
/// horizontal faces (x, y). World coordinates, so coplanar boxes continue each other's pattern.
#[inline]
pub fn face_uv_axes(axis: usize) -> (usize, usize) {
    match axis {
        0 => (1, 2),
        1 => (0, 2),
        _ => (0, 1),
    }
}

#[derive(Clone, Copy, Debug)]
pub struct Ray {
    pub origin: Vec3,
    pub dir: Vec3,
    inv_dir: Vec3,
}

impl Ray {
    pub fn new(origin: Vec3, dir: Vec3) -> Ray {
        Ray {
            origin,
            dir,
            inv_dir: Vec3::ONE / dir,
        }
    }

    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }
}

/// Hit on a box face or the ground.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f32,
    /// Index into `Geometry::prims`, or `GROUND`.
    pub prim: u32,
    pub face: u8,
}

pub const GROUND: u32 = u32::MAX;
const T_MIN: f32 = 1e-4;

/// Slab test; returns the entry distance and face. A ray starting inside a box hits it at
/// `T_MIN` (AO rays leaving a face that touches another box are occluded, as they should be).
#[inline]
fn ray_box(ray: &Ray, min: Vec3, max: Vec3, t_max: f32) -> Option<(f32, u8)> {
    let t1 = (min - ray.origin) * ray.inv_dir;
    let t2 = (max - ray.origin) * ray.inv_dir;
    let lo = t1.min(t2);
    let hi = t1.max(t2);
    let t_near = lo.max_element();
    let t_far = hi.min_element();
    // Written so that NaN (a ray parallel to a face, exactly on it) misses.
    if !(t_near <= t_far && t_far > T_MIN && t_near < t_max) {
        return None;
    }
    let axis = if lo.x >= lo.y && lo.x >= lo.z {
        0
    } else if lo.y >= lo.z {
        1
    } else {
        2
    };
    let positive = ray.dir[axis] < 0.0;
    Some((t_near.max(T_MIN), axis as u8 * 2 + positive as u8))
}

#[inline]
fn ray_aabb_entry(ray: &Ray, min: Vec3, max: Vec3, t_max: f32) -> Option<f32> {
    let t1 = (min - ray.origin) * ray.inv_dir;
    let t2 = (max - ray.origin) * ray.inv_dir;
    let t_near = t1.min(t2).max_element().max(0.0);
    let t_far = t1.max(t2).min_element().min(t_max);
    (t_near <= t_far).then_some(t_near)
}

#[derive(Clone, Copy, Debug)]
struct Node {
    min: Vec3,
    max: Vec3,
    /// Leaf: first index into `order`; interior: index of the right child (left is next).
    start_or_right: u32,
    /// 0 for interior nodes.
    count: u32,
}

/// The boxes, their BVH and the ground plane.
pub struct Geometry {
    pub prims: Vec<Prim>,
    nodes: Vec<Node>,
    order: Vec<u32>,
}

const LEAF_SIZE: usize = 2;

impl Geometry {
    pub fn new(prims: Vec<Prim>) -> Geometry {
        let mut order: Vec<u32> = (0..prims.len() as u32).collect();
        let mut nodes = Vec::with_capacity(prims.len() * 2);
        if !prims.is_empty() {
            build(&prims, &mut order, 0, prims.len(), &mut nodes);
        }
        Geometry {
            prims,
            nodes,
            order,
        }
    }

    /// The closest hit (boxes and ground) before `t_max`.
    pub fn intersect(&self, ray: &Ray, t_max: f32) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut t_best = t_max;
        if ray.dir.z < 0.0 {
            let t = -ray.origin.z / ray.dir.z;
            if t > T_MIN && t < t_best {
                t_best = t;
                best = Some(Hit {
                    t,
                    prim: GROUND,
                    face: 5,
                });
            }
        }
        self.traverse(ray, &mut t_best, &mut best, false);
        best
    }

    /// Whether anything (ground included) lies on the ray before `t_max`.
    pub fn occluded(&self, ray: &Ray, t_max: f32) -> bool {
        if ray.dir.z < 0.0 && -ray.origin.z / ray.dir.z < t_max {
            return true;
        }
        let mut t_best = t_max;
        let mut best = None;
        self.traverse(ray, &mut t_best, &mut best, true)
    }

    fn traverse(&self, ray: &Ray, t_best: &mut f32, best: &mut Option<Hit>, any: bool) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        // Front-to-back: children are pushed far first, and a node entered beyond the best hit
        // so far is skipped.
        let mut stack = [(0u32, 0.0f32); 64];
        let mut sp = 0;
        if let Some(t) = ray_aabb_entry(ray, self.nodes[0].min, self.nodes[0].max, *t_best) {
            stack[0] = (0, t);
            sp = 1;
        }
        while sp > 0 {
            sp -= 1;
            let (node_index, t_entry) = stack[sp];
            if !(t_entry < *t_best) {
                continue;
            }
            let node = &self.nodes[node_index as usize];
            if node.count > 0 {
                let first = node.start_or_right as usize;
                for &p in &self.order[first..first + node.count as usize] {
                    let prim = &self.prims[p as usize];
                    if let Some((t, face)) = ray_box(ray, prim.min, prim.max, *t_best) {
                        if any {
                            return true;
                        }
                        *t_best = t;
                        *best = Some(Hit { t, prim: p, face });
                    }
                }
            } else if sp + 2 <= stack.len() {
                // Depth-first layout: the left child follows its parent.
                let (l, r) = (node_index + 1, node.start_or_right);
                let tl = ray_aabb_entry(
                    ray,
                    self.nodes[l as usize].min,
                    self.nodes[l as usize].max,
                    *t_best,
                );
                let tr = ray_aabb_entry(
                    ray,
                    self.nodes[r as usize].min,
                    self.nodes[r as usize].max,
                    *t_best,
                );
                match (tl, tr) {
                    (Some(a), Some(b)) => {
                        let (near, far) = if a <= b {
                            ((l, a), (r, b))
                        } else {
                            ((r, b), (l, a))
                        };
                        stack[sp] = far;
                        stack[sp + 1] = near;
                        sp += 2;
                    }
                    (Some(a), None) => {
                        stack[sp] = (l, a);
                        sp += 1;
                    }
                    (None, Some(b)) => {
                        stack[sp] = (r, b);
                        sp += 1;
                    }
                    (None, None) => {}
                }
            }
        }
        false
    }
}

fn build(prims: &[Prim], order: &mut [u32], lo: usize, hi: usize, nodes: &mut Vec<Node>) -> u32 {
    let mut min = Vec3::splat(f32::INFINITY);
    let mut max = Vec3::splat(f32::NEG_INFINITY);
    for &p in &order[lo..hi] {
        min = min.min(prims[p as usize].min);
        max = max.max(prims[p as usize].max);
    }
    let index = nodes.len() as u32;
    nodes.push(Node {
        min,
        max,
        start_or_right: lo as u32,
        count: (hi - lo) as u32,
    });
    if hi - lo <= LEAF_SIZE {
        return index;
    }
    let mut cmin = Vec3::splat(f32::INFINITY);
    let mut cmax = Vec3::splat(f32::NEG_INFINITY);
    for &p in &order[lo..hi] {
        let c = prims[p as usize].min + prims[p as usize].max;
        cmin = cmin.min(c);
        cmax = cmax.max(c);
    }
    let axis = (cmax - cmin).max_position();
    let mid = (lo + hi) / 2;
    // Ties broken by index: the build is deterministic.
    order[lo..hi].sort_unstable_by(|&a, &b| {
        let ca = prims[a as usize].min[axis] + prims[a as usize].max[axis];
        let cb = prims[b as usize].min[axis] + prims[b as usize].max[axis];
        ca.total_cmp(&cb).then(a.cmp(&b))
    });
    build(prims, order, lo, mid, nodes);
    let right = build(prims, order, mid, hi, nodes);
    nodes[index as usize].start_or_right = right;
    nodes[index as usize].count = 0;
    index
}
