//! `Splats` to and from the 3DGS PLY layout, on `scene`'s PLY header reader and atomic writes.
//! Reading finds properties by name, so other tools' property orders work; it never trusts a
//! count the file cannot hold and refuses NaN/Inf, naming the vertex.
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

use std::io::Write;
use std::path::Path;

use glam::{Quat, Vec3};

use crate::scene::DamageClass;
use crate::scene::SceneError;
use crate::scene::atomic::write_atomic;
use crate::scene::ply::header::RowReader;
use crate::splats::model::{NO_SURVEY, OverlayColours, sh_coeffs_for_degree};
use crate::splats::{MAX_LABEL_CHANNELS, Splats};

/// Largest id stored exactly in the `double id` property (2^53).
const MAX_EXACT_ID: u64 = 1 << 53;

/// The PLY property name of label channel `k`: `label_<class>` for the known classes.
pub fn label_property(k: usize) -> String {
    match DamageClass::ALL.get(k) {
        Some(class) => format!("label_{}", class.id()),
        None => format!("label_{k}"),
    }
}

/// The standard 3DGS property names, in the order the original `save_ply` writes them.
pub fn standard_properties(sh_degree: u32) -> Vec<String> {
    let rest = 3 * (sh_coeffs_for_degree(sh_degree) - 1);
    let mut names: Vec<String> = ["x", "y", "z", "nx", "ny", "nz"].map(String::from).into();
    names.extend((0..3).map(|i| format!("f_dc_{i}")));
    names.extend((0..rest).map(|i| format!("f_rest_{i}")));
    names.push("opacity".into());
    names.extend((0..3).map(|i| format!("scale_{i}")));
    names.extend((0..4).map(|i| format!("rot_{i}")));
    names
}

/// The header damage-twin writes: an overlay-mode model's class colours as a comment
/// (`OverlayColours::to_comment`), the 3DGS header (all `float`), then `label_*` floats when the
/// model has label channels, then `float survey`, `double id`, `float damage_survey` (the
/// survey a Gaussian was first seen as damage, 65535 for never) and `uchar state` (DESIGN.md's
/// selection and edit bits).
pub fn splat_header(splats: &Splats) -> String {
    let mut header = String::from("ply\nformat binary_little_endian 1.0\n");
    if let Some(overlay) = &splats.overlay {
        header.push_str(&format!("comment {}\n", overlay.to_comment()));
    }
    header.push_str(&format!("element vertex {}\n", splats.len()));
    for name in standard_properties(splats.sh_degree) {
        header.push_str(&format!("property float {name}\n"));
    }
    for k in 0..splats.label_channels {
        header.push_str(&format!("property float {}\n", label_property(k)));
    }
    header.push_str(
        "property float survey\nproperty double id\nproperty float damage_survey\n\
         property uchar state\nend_header\n",
    );
    header
}

/// The bytes `write_splats` writes for `splats`, from its header and row layout (every property
/// a 4-byte float but `double id` and `uchar state`), without writing them.
pub fn splats_file_bytes(splats: &Splats) -> u64 {
    let floats = standard_properties(splats.sh_degree).len() + splats.label_channels + 2;
    let row = 4 * floats + 8 + 1;
    splat_header(splats).len() as u64 + (splats.len() * row) as u64
}

/// Writes `splats` as a binary little-endian 3DGS PLY (atomically: temp file, fsync, rename).
pub fn write_splats(path: &Path, splats: &Splats) -> Result<(), SceneError> {
    splats
        .check_lengths()
        .map_err(|m| SceneError::invalid(path, format!("cannot save splats: {m}")))?;
    if splats.sh_degree > 3 {
        return Err(SceneError::invalid(
            path,
            format!("SH degree {} > 3 has no 3DGS PLY layout", splats.sh_degree),
        ));
    }
    if let Some(id) = splats.meta.ids.iter().find(|&&id| id > MAX_EXACT_ID) {
        return Err(SceneError::invalid(
            path,
            format!("Gaussian id {id} does not fit the PLY `double id` exactly"),
        ));
    }
    let k = splats.sh_coeffs();
    let labels = splats.label_channels;
    write_atomic(path, |w| {
        w.write_all(splat_header(splats).as_bytes())?;
        let mut row: Vec<u8> = Vec::with_capacity(4 * (15 + 3 * k + labels) + 8);
        for g in 0..splats.len() {
            row.clear();
            let mut put = |v: f32| row.extend_from_slice(&v.to_le_bytes());
            let m = splats.means[g];
            [m.x, m.y, m.z, 0.0, 0.0, 0.0]
                .into_iter()
                .for_each(&mut put);
            let sh = splats.sh_of(g);
            (0..3).for_each(|c| put(sh[c]));
            for c in 0..3 {
                for j in 1..k {
                    put(sh[j * 3 + c]);
                }
            }
            put(splats.raw_opacities[g]);
            let s = splats.log_scales[g];
            [s.x, s.y, s.z].into_iter().for_each(&mut put);
            let q = splats.rotations[g];
            [q.w, q.x, q.y, q.z].into_iter().for_each(&mut put);
            splats.labels_of(g).iter().for_each(|&v| put(v));
            put(f32::from(splats.meta.survey[g]));
            row.extend_from_slice(&(splats.meta.ids[g] as f64).to_le_bytes());
            row.extend_from_slice(&f32::from(splats.meta.damage_survey[g]).to_le_bytes());
            row.push(splats.meta.state[g]);
            w.write_all(&row)?;
        }
        Ok(())
    })
}

/// Reads a 3DGS PLY (binary either endianness or ASCII; any property order; any numeric type).
/// SH degree follows the `f_rest_*` count; labels, survey, id, damage_survey and state are
/// optional (ids default to the vertex index, surveys to 0, damage_survey to never, state to 0). Refuses missing properties, NaN/Inf, an all-zero rotation,
/// bad counts and truncated data.
pub fn read_splats(path: &Path) -> Result<Splats, SceneError> {
    let (header, mut rows) = RowReader::open(path, "vertex")?;
    let bad = |msg: String| SceneError::invalid(path, msg);
    let vertex = header.element("vertex", path)?;
    let require = |name: &str| vertex.require(name, path);
    let mut rest_count = 0;
    while vertex.find(&format!("f_rest_{rest_count}")).is_some() {
        rest_count += 1;
    }
    let sh_degree = (0..=3u32)
        .find(|&d| 3 * (sh_coeffs_for_degree(d) - 1) == rest_count)
        .ok_or_else(|| {
            bad(format!(
                "{rest_count} consecutive f_rest properties: expected 0, 9, 24 or 45 (SH degree 0..3)"
            ))
        })?;
    if vertex
        .properties
        .iter()
        .filter(|p| p.name.starts_with("f_rest_"))
        .count()
        != rest_count
    {
        return Err(bad("f_rest properties are not numbered 0..n-1".into()));
    }
    let xyz = [require("x")?, require("y")?, require("z")?];
    let dc = [require("f_dc_0")?, require("f_dc_1")?, require("f_dc_2")?];
    let rest: Vec<usize> = (0..rest_count)
        .map(|i| require(&format!("f_rest_{i}")))
        .collect::<Result<_, _>>()?;
    let opacity = require("opacity")?;
    let scale = [
        require("scale_0")?,
        require("scale_1")?,
        require("scale_2")?,
    ];
    let rot = [
        require("rot_0")?,
        require("rot_1")?,
        require("rot_2")?,
        require("rot_3")?,
    ];
    let mut label_props = Vec::new();
    while let Some(i) = vertex.find(&label_property(label_props.len())) {
        label_props.push(i);
        if label_props.len() > MAX_LABEL_CHANNELS {
            return Err(SceneError::unsupported(
                path,
                format!(
                    "more than {MAX_LABEL_CHANNELS} label_* properties: damage-twin supports at \
                     most {MAX_LABEL_CHANNELS} damage label channels"
                ),
            ));
        }
    }
    let survey = vertex.find("survey");
    let id = vertex.find("id");
    let damage_survey = vertex.find("damage_survey");
    let state = vertex.find("state");

    let n = rows.count;
    let k = sh_coeffs_for_degree(sh_degree);
    let mut splats = Splats::empty(sh_degree, label_props.len());
    for comment in &header.comments {
        if let Some(overlay) = OverlayColours::from_comment(comment) {
            splats.overlay = Some(overlay.map_err(bad)?);
        }
    }
    splats.means.reserve_exact(n);
    splats.log_scales.reserve_exact(n);
    splats.rotations.reserve_exact(n);
    splats.raw_opacities.reserve_exact(n);
    splats.sh.reserve_exact(n * k * 3);
    splats.raw_labels.reserve_exact(n * label_props.len());
    splats.meta.ids.reserve_exact(n);
    splats.meta.survey.reserve_exact(n);
    splats.meta.damage_survey.reserve_exact(n);
    splats.meta.state.reserve_exact(n);
    splats.meta.frozen.reserve_exact(n);

    let names = &vertex.properties;
    let mut values = Vec::with_capacity(names.len());
    let mut sh = vec![0.0f32; k * 3];
    let mut labels = vec![0.0f32; label_props.len()];
    let mut g = 0usize;
    while rows.next_row(&mut values)? {
        // Every value we keep must be finite as an f32 (a huge double overflows to Inf).
        let get = |i: usize| -> Result<f32, SceneError> {
            let v = values[i] as f32;
            if v.is_finite() {
                Ok(v)
            } else {
                Err(bad(format!(
                    "vertex {g}: property `{}` is {} (NaN/Inf not allowed)",
                    names[i].name, values[i]
                )))
            }
        };
        let mean = Vec3::new(get(xyz[0])?, get(xyz[1])?, get(xyz[2])?);
        let log_scale = Vec3::new(get(scale[0])?, get(scale[1])?, get(scale[2])?);
        // PLY stores (w, x, y, z).
        let rotation = Quat::from_xyzw(get(rot[1])?, get(rot[2])?, get(rot[3])?, get(rot[0])?);
        if rotation.to_array().iter().all(|&v| v == 0.0) {
            return Err(bad(format!("vertex {g}: rotation is all zeros")));
        }
        let raw_opacity = get(opacity)?;
        for (c, &dc_c) in dc.iter().enumerate() {
            sh[c] = get(dc_c)?;
            for j in 1..k {
                sh[j * 3 + c] = get(rest[c * (k - 1) + (j - 1)])?;
            }
        }
        for (slot, &i) in labels.iter_mut().zip(&label_props) {
            *slot = get(i)?;
        }
        let small_int = |index: Option<usize>, what: &str, max: u16, default: u16| {
            let Some(i) = index else {
                return Ok(default);
            };
            let v = values[i];
            if !(v >= 0.0 && v <= f64::from(max) && v.fract() == 0.0) {
                return Err(bad(format!(
                    "vertex {g}: {what} {v} is not an integer 0..{max}"
                )));
            }
            Ok(v as u16)
        };
        let survey = small_int(survey, "survey", u16::MAX, 0)?;
        let first_damage = small_int(damage_survey, "damage_survey", u16::MAX, NO_SURVEY)?;
        let bits = small_int(state, "state", u16::from(u8::MAX), 0)? as u8;
        let id = match id {
            Some(i) => {
                let v = values[i];
                if !(v >= 0.0 && v <= MAX_EXACT_ID as f64 && v.fract() == 0.0) {
                    return Err(bad(format!("vertex {g}: id {v} is not an integer 0..2^53")));
                }
                v as u64
            }
            None => g as u64,
        };
        splats.push(
            mean,
            log_scale,
            rotation,
            raw_opacity,
            &sh,
            &labels,
            id,
            survey,
        );
        splats.meta.damage_survey[g] = first_damage;
        splats.meta.state[g] = bits;
        g += 1;
    }
    Ok(splats)
}
