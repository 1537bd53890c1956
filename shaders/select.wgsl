// Selection test on the GPU: one thread per Gaussian, the same rule as the CPU's
// `splats::selection::hits` (screen shapes: the centre's projection in front of the camera inside
// a rectangle, an even-odd polygon or a brush stroke's circles; volumes: the centre inside a
// sphere or box; hidden and deleted Gaussians never hit) and, front-most, `damage::pick::front_hits`'
// depth rule against the renderer's last frame at the same camera: a hit counts only when the
// centre is not behind the surface drawn at its pixel (`z <= surface + 2·size + 0.02·min(surface, z)`,
// the surface being depth / alpha where alpha > 0.5). Hits are bits in `hits` (atomicOr).

struct SelectUniforms {
    rot0: vec4<f32>,
    rot1: vec4<f32>,
    rot2: vec4<f32>,
    trans: vec4<f32>,
    // Rectangle corners / box corners (xyz) / sphere centre (xyz) and radius (w of a).
    a: vec4<f32>,
    b: vec4<f32>,
    focal: vec2<f32>,
    principal: vec2<f32>,
    img_size: vec2<u32>,
    num_gaussians: u32,
    // 0 rectangle, 1 polygon, 2 brush, 3 sphere, 4 box.
    kind: u32,
    points: u32,
    front_most: u32,
    radius: f32,
    log_scales_at: u32,
}

const RECT: u32 = 0u;
const POLYGON: u32 = 1u;
const BRUSH: u32 = 2u;
const SPHERE: u32 = 3u;
const BOX: u32 = 4u;
// splats::model::state: HIDDEN (2) | DELETED (8).
const NOT_DRAWN: u32 = 10u;

@group(0) @binding(0) var<uniform> u: SelectUniforms;
// means (3C) | log_scales (3C) | ...: the renderer's geometry buffer.
@group(0) @binding(1) var<storage, read> geometry: array<f32>;
@group(0) @binding(2) var<storage, read> state: array<u32>;
@group(0) @binding(3) var<storage, read> points: array<vec2<f32>>;
// The renderer's last frame: colour + alpha, and depth (Σ z·α·T).
@group(0) @binding(4) var<storage, read> out_color: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read> out_depth: array<f32>;
@group(0) @binding(6) var<storage, read_write> hits: array<atomic<u32>>;

fn inside_polygon(p: vec2<f32>) -> bool {
    if u.points < 3u {
        return false;
    }
    var inside = false;
    var j = u.points - 1u;
    for (var i = 0u; i < u.points; i = i + 1u) {
        let a = points[i];
        let b = points[j];
        if (a.y > p.y) != (b.y > p.y) && p.x < (b.x - a.x) * (p.y - a.y) / (b.y - a.y) + a.x {
            inside = !inside;
        }
        j = i;
    }
    return inside;
}

fn inside_brush(p: vec2<f32>) -> bool {
    for (var i = 0u; i < u.points; i = i + 1u) {
        let d = points[i] - p;
        if dot(d, d) <= u.radius * u.radius {
            return true;
        }
    }
    return false;
}

@compute @workgroup_size(256)
fn select_hits(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let g = (wg.x + wg.y * nwg.x) * 256u + t;
    if g >= u.num_gaussians || (state[g] & NOT_DRAWN) != 0u {
        return;
    }
    let mean = vec3<f32>(geometry[3u * g], geometry[3u * g + 1u], geometry[3u * g + 2u]);
    var hit = false;
    if u.kind == SPHERE {
        let d = mean - u.a.xyz;
        hit = dot(d, d) <= u.radius * u.radius;
    } else if u.kind == BOX {
        let lo = min(u.a.xyz, u.b.xyz);
        let hi = max(u.a.xyz, u.b.xyz);
        hit = all(mean >= lo) && all(mean <= hi);
    } else {
        let p = vec3<f32>(dot(u.rot0.xyz, mean), dot(u.rot1.xyz, mean), dot(u.rot2.xyz, mean)) + u.trans.xyz;
        // camera::project: `!(z > 1e-6)` rejects NaN too.
        if !(p.z > 1e-6) {
            return;
        }
        let pixel = vec2<f32>(u.focal.x * p.x / p.z + u.principal.x, u.focal.y * p.y / p.z + u.principal.y);
        if u.kind == RECT {
            let lo = min(u.a.xy, u.b.xy);
            let hi = max(u.a.xy, u.b.xy);
            hit = all(pixel >= lo) && all(pixel <= hi);
        } else if u.kind == POLYGON {
            hit = inside_polygon(pixel);
        } else {
            hit = inside_brush(pixel);
        }
        if hit && u.front_most != 0u {
            let cell = floor(pixel);
            if cell.x < 0.0 || cell.y < 0.0 || cell.x >= f32(u.img_size.x) || cell.y >= f32(u.img_size.y) {
                return;
            }
            let pix = u32(cell.y) * u.img_size.x + u32(cell.x);
            let alpha = out_color[pix].w;
            var surface = 3.0e38;
            if alpha > 0.5 {
                surface = out_depth[pix] / alpha;
            }
            let s = u.log_scales_at + 3u * g;
            let size = exp(max(geometry[s], max(geometry[s + 1u], geometry[s + 2u])));
            hit = p.z <= surface + 2.0 * size + 0.02 * min(surface, p.z);
        }
    }
    if hit {
        atomicOr(&hits[g / 32u], 1u << (g % 32u));
    }
}
