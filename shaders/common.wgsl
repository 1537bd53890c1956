// Shared by the splat stages (prepended to project, emit_intersections, tile_ranges, rasterize
// by the host; prefix_sum and radix_sort are generic and stand alone). The layouts here mirror
// `FrameUniforms` and `ProjectedSplat` in src/gpu/project.rs byte for byte.

const TILE_SIZE: f32 = 16.0;
const TILE_WIDTH: u32 = 16u;
const MAX_LABELS: u32 = 8u;

struct Uniforms {
    // Rows of the world-to-camera rotation, then its translation (w unused).
    rot0: vec4<f32>,
    rot1: vec4<f32>,
    rot2: vec4<f32>,
    trans: vec4<f32>,
    cam_pos: vec4<f32>,
    background: vec4<f32>,
    focal: vec2<f32>,
    principal: vec2<f32>,
    img_size: vec2<u32>,
    tile_bounds: vec2<u32>,
    num_gaussians: u32,
    sh_degree: u32,
    sh_coeffs: u32,
    label_channels: u32,
    near: f32,
    // Offsets (in f32s) of the parameter sections inside the geometry buffer.
    log_scales_at: u32,
    rotations_at: u32,
    opacities_at: u32,
    // Room for tile/Gaussian intersections this frame; emission beyond it is dropped.
    isect_capacity: u32,
    // alpha = min(alpha_max, opacity · exp(-power)): 0.99 (3DGS), 0.999 (gsplat).
    alpha_max: f32,
    // Backward only: whether colour gradients flow through the SH view direction to the means.
    sh_direction_grad: u32,
    pad2: u32,
}

struct ProjectedSplat {
    xy: vec2<f32>,
    depth: f32,
    opacity: f32,
    conic: vec3<f32>,
    radius: u32,
    color: vec3<f32>,
    tiles: u32,
    // Tile rectangle [min, max) packed as min | max << 16, for x and y.
    rect_x: u32,
    rect_y: u32,
    pad0: u32,
    pad1: u32,
}

// WGSL lets compilers assume floats are finite, so comparisons cannot be trusted to catch NaN:
// test the exponent bits instead.
fn is_finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) != 0x7f800000u;
}
