//! PLY files: Gaussian splats in the standard 3DGS layout (plus damage-twin's extras) and
//! coloured point clouds. Conversions between files and `Splats`/`PointCloud` only; no
//! activation, filtering or rendering decisions.
//!
//! # The splat format damage-twin writes
//!
//! Binary little-endian, one `vertex` element, every property `float` (f32) except `id`:
//!
//! ```text
//! ply
//! format binary_little_endian 1.0
//! element vertex N
//! property float x            ─┐
//! property float y             │ position
//! property float z            ─┘
//! property float nx           ─┐
//! property float ny            │ always 0 (3DGS writes zeros)
//! property float nz           ─┘
//! property float f_dc_0..2       SH DC per channel R, G, B
//! property float f_rest_0..M-1   M = 3·((deg+1)²−1): 0, 9, 24, 45; channel-major:
//!                                f_rest_{c·(K−1) + (k−1)} = SH coefficient k ≥ 1 of channel c
//! property float opacity         logit (raw_opacity)
//! property float scale_0..2      natural-log standard deviations (log_scale)
//! property float rot_0..3        quaternion (w, x, y, z), not normalised
//! property float label_crack     ─┐ damage-twin extras, only when the model has label
//! property float label_spalling   │ channels: raw logits, channel k = DamageClass::ALL[k]
//! property float label_rebar     ─┘ (channels beyond the three known are `label_<k>`)
//! property float survey          survey of first appearance, an integer 0..=65535
//! property double id             stable Gaussian id, an integer < 2^53
//! property float damage_survey   survey the Gaussian was first seen as damage (65535: never)
//! property uchar state           bits: selected 1, hidden 2, locked 4, deleted 8, refined 16
//! end_header
//! ```
//!
//! Everything up to `rot_3`, header text included, is byte-identical to what the original
//! 3DGS `GaussianModel.save_ply` (numpy `f4` fields through `plyfile`) writes for the same
//! values; the extras come after, so SuperSplat, Brush and the 3DGS loader, which look
//! properties up by name, ignore them. `survey` is a float because some viewers assume float
//! properties; every u16 is exact in f32. `id` needs more than f32's 24 bits, hence `double`.
//! The `frozen` flag is training state and is not saved.
//!
//! Reading accepts binary (either endianness) and ASCII, any property order and any numeric
//! property type, SH degree 0..3 from the `f_rest` count, and missing extras (survey 0, id =
//! vertex index, no labels, damage_survey never, state 0). It refuses missing required
//! properties, NaN/Inf (naming the vertex and property), all-zero rotations, counts the file
//! cannot hold and truncated data.

mod header;
mod points;
mod splats;

pub use points::{read_point_cloud, read_point_cloud_skipping, write_point_cloud};
pub use splats::{
    label_property, read_splats, splat_header, splats_file_bytes, standard_properties, write_splats,
};
