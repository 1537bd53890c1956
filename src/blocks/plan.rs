//! The partition plan: the file every block job, the engines' job files and the merge read. One
//! JSON file (`plan.json`) in the plan folder, the folder every node sees at the same path: it
//! names the dataset, the frame the blocks are cut in, each block's box (the box it keeps at the
//! merge, and the box enlarged by the margin that it trains on) and photos, and the training
//! settings every block shares. Versioned; checked whole on load, each refusal one line naming
//! the file and the field.

use std::path::{Path, PathBuf};

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::scene::atomic::write_atomic;
use crate::scene::files::read_text;
use crate::scene::{ImageScale, SceneError};

/// The plan file's name inside the plan folder.
pub const PLAN_FILE: &str = "plan.json";
/// What `format` holds, so another JSON file given as a plan is refused by name.
pub const PLAN_FORMAT: &str = "damage-twin-block-plan";
/// The plan layout this build reads and writes.
pub const PLAN_VERSION: u32 = 1;
/// Most blocks a plan may hold (a 2,000-photo bridge needs tens).
pub const MAX_BLOCKS: usize = 4096;
/// Largest plan file read (a block lists its photo names; 10⁵ photos fit).
const MAX_PLAN_BYTES: u64 = 64 << 20;

/// The frame blocks are cut in: `long` is the structure's long axis, `cross` the horizontal
/// axis across it, `up` the cameras' mean up; coordinates are metres from `origin` (dataset
/// units) along each.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Frame {
    pub origin: [f32; 3],
    pub long: [f32; 3],
    pub cross: [f32; 3],
    pub up: [f32; 3],
}

impl Frame {
    /// `p` in the frame: (along the long axis, across, up).
    pub fn coordinates(&self, p: Vec3) -> Vec3 {
        let d = p - Vec3::from_array(self.origin);
        Vec3::new(
            d.dot(Vec3::from_array(self.long)),
            d.dot(Vec3::from_array(self.cross)),
            d.dot(Vec3::from_array(self.up)),
        )
    }
}

/// How a block is cut from its neighbours along the long axis: `[start, end)` is the part it
/// keeps at the merge; it trains on `[start - margin, end + margin)`. The first block's start
/// and the last block's end are open (nothing outside the partition is lost).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Block {
    pub index: usize,
    pub start: f32,
    pub end: f32,
    /// The photos (dataset view names, training views only) that see the enlarged box.
    pub photos: Vec<String>,
    /// Why the block is not trained (too few photos), or None.
    pub skipped: Option<String>,
}

/// The settings every block trains with.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BlockTraining {
    /// The image scale, as the CLI spells it (`"4"`, `"w960"`).
    pub scale: String,
    /// `label` or `rgb` (label falls back to rgb on a dataset without masks).
    pub mode: crate::damage::TrainMode,
    /// Steps per training photo: block K trains `steps_per_photo × its photos` steps, the
    /// whole run `steps_per_photo × all training photos`.
    pub steps_per_photo: f64,
    pub seed: u64,
    pub sh_degree: u32,
    pub background: [f32; 3],
    /// Every n-th view is held out (never trained by any block; the merge scores on them).
    pub test_every: usize,
}

impl BlockTraining {
    pub fn image_scale(&self) -> Option<ImageScale> {
        ImageScale::parse(&self.scale)
    }

    /// The steps of a block with `photos` photos (at least one).
    pub fn steps_for(&self, photos: usize) -> u32 {
        (self.steps_per_photo * photos as f64)
            .round()
            .clamp(1.0, u32::MAX as f64) as u32
    }
}

/// The coarse whole-scene context model (CityGaussian's coarse prior): one short whole run at a
/// low resolution, trained once before the blocks (`train-block --context`). Each block renders
/// it frozen behind its own Gaussians where it lies outside the block's box, so the sky, the far
/// ground and the rest of the structure in its photos are explained and only its own Gaussians
/// learn; the merge keeps the context's Gaussians that lie outside every block's box.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContextTraining {
    /// Steps of the context run over all training photos.
    pub iters: u32,
    /// Its image scale, as the CLI spells it (`"2"`, `"w80"`).
    pub scale: String,
}

impl ContextTraining {
    pub fn image_scale(&self) -> Option<ImageScale> {
        ImageScale::parse(&self.scale)
    }
}

/// A partition plan (see the module doc).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Plan {
    pub format: String,
    pub version: u32,
    /// The dataset, as an absolute path (every node must see it there).
    pub dataset: PathBuf,
    pub frame: Frame,
    /// Margin added on both sides of each block along the long axis, in metres.
    pub margin: f32,
    /// Half width of the band around each inner boundary that the merge's seam report scores.
    pub seam_band: f32,
    /// Blocks seeing fewer training photos than this are skipped.
    pub min_photos: usize,
    /// Across and up extents of the structure (its points), for the picture and the boxes.
    pub cross_range: [f32; 2],
    pub up_range: [f32; 2],
    pub training: BlockTraining,
    pub blocks: Vec<Block>,
    /// The context every block renders frozen (None: none; plans written before it have none,
    /// and their digest is unchanged: the field is not written when None).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub context: Option<ContextTraining>,
}

impl Plan {
    /// The inner boundaries between consecutive blocks along the long axis.
    pub fn boundaries(&self) -> Vec<f32> {
        self.blocks.iter().skip(1).map(|b| b.start).collect()
    }

    /// Whether a point at `along` (long-axis coordinate) belongs to block `k`'s kept part:
    /// open at the outer ends.
    pub fn keeps(&self, k: usize, along: f32) -> bool {
        let last = self.blocks.len() - 1;
        let b = &self.blocks[k];
        (k == 0 || along >= b.start) && (k == last || along < b.end)
    }

    /// Whether `along` is inside block `k`'s enlarged box along the long axis (open at the ends
    /// like `keeps`).
    pub fn trains_on(&self, k: usize, along: f32) -> bool {
        let last = self.blocks.len() - 1;
        let b = &self.blocks[k];
        (k == 0 || along >= b.start - self.margin) && (k == last || along < b.end + self.margin)
    }

    /// Whether a point at frame coordinates `local` lies within the structure's across and up
    /// extents (`cross_range`, `up_range`).
    pub fn in_structure(&self, local: Vec3) -> bool {
        let within = |v: f32, [lo, hi]: [f32; 2]| v >= lo && v <= hi;
        within(local.y, self.cross_range) && within(local.z, self.up_range)
    }

    /// Whether a Gaussian at frame coordinates `local` is block `k`'s to train: in its enlarged
    /// box along the axis and, with a context, within the structure across and up (the sky and
    /// the far ground are the context's).
    pub fn trains_point(&self, k: usize, local: Vec3) -> bool {
        self.trains_on(k, local.x) && (self.context.is_none() || self.in_structure(local))
    }

    /// Whether the merge keeps block `k`'s Gaussian at frame coordinates `local`: in its own box
    /// along the axis and, with a context, within the structure across and up.
    pub fn keeps_point(&self, k: usize, local: Vec3) -> bool {
        self.keeps(k, local.x) && (self.context.is_none() || self.in_structure(local))
    }

    /// Whether a context Gaussian at `local` lies outside every block's own box: what the merge
    /// keeps of the context. The blocks tile the axis, so that is outside the structure across
    /// or up.
    pub fn outside_every_block(&self, local: Vec3) -> bool {
        !self.in_structure(local)
    }

    /// Every check `load` makes, naming `path` and the field that fails.
    pub fn validate(&self, path: &Path) -> Result<(), SceneError> {
        let bad = |message: String| Err(SceneError::invalid(path, message));
        if self.format != PLAN_FORMAT {
            return bad(format!(
                "format is {:?}, not {PLAN_FORMAT:?}: not a block plan",
                self.format
            ));
        }
        if self.version != PLAN_VERSION {
            return bad(format!(
                "version {} is not the {PLAN_VERSION} this build reads",
                self.version
            ));
        }
        if !self.dataset.is_absolute() {
            return bad(format!(
                "dataset {} is not an absolute path (every node must find it at the same path)",
                self.dataset.display()
            ));
        }
        let unit = |name: &str, v: [f32; 3]| -> Result<(), SceneError> {
            let v = Vec3::from_array(v);
            if !v.is_finite() || (v.length() - 1.0).abs() > 1e-3 {
                return bad(format!("frame.{name} is not a unit vector: {v:?}"));
            }
            Ok(())
        };
        unit("long", self.frame.long)?;
        unit("cross", self.frame.cross)?;
        unit("up", self.frame.up)?;
        if !Vec3::from_array(self.frame.origin).is_finite() {
            return bad("frame.origin is not finite".into());
        }
        for (name, v) in [("margin", self.margin), ("seam_band", self.seam_band)] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(format!("{name} {v} is not a length (finite, at least 0)"));
            }
        }
        for (name, [lo, hi]) in [
            ("cross_range", self.cross_range),
            ("up_range", self.up_range),
        ] {
            if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
                return bad(format!("{name} [{lo}, {hi}] is not a range"));
            }
        }
        let t = &self.training;
        if t.image_scale().is_none() {
            return bad(format!(
                "training.scale {:?} is not an image scale",
                t.scale
            ));
        }
        if !matches!(
            t.mode,
            crate::damage::TrainMode::Label | crate::damage::TrainMode::Rgb
        ) {
            return bad(format!(
                "training.mode {} is not label or rgb (blocks do not train overlay mode)",
                t.mode
            ));
        }
        if !(t.steps_per_photo.is_finite() && t.steps_per_photo > 0.0 && t.steps_per_photo < 1e6) {
            return bad(format!(
                "training.steps_per_photo {} is not in (0, 10⁶)",
                t.steps_per_photo
            ));
        }
        if t.sh_degree > 3 {
            return bad(format!("training.sh_degree {} is above 3", t.sh_degree));
        }
        if t.test_every == 0 || !t.background.iter().all(|c| c.is_finite()) {
            return bad("training.test_every is 0 or training.background not finite".into());
        }
        if let Some(context) = &self.context {
            if context.image_scale().is_none() {
                return bad(format!(
                    "context.scale {:?} is not an image scale",
                    context.scale
                ));
            }
            if context.iters == 0 {
                return bad("context.iters is 0: a context trains at least one step".into());
            }
        }
        if self.blocks.is_empty() || self.blocks.len() > MAX_BLOCKS {
            return bad(format!(
                "{} blocks: a plan holds 1 to {MAX_BLOCKS}",
                self.blocks.len()
            ));
        }
        for (k, b) in self.blocks.iter().enumerate() {
            if b.index != k {
                return bad(format!("blocks[{k}].index is {}, not {k}", b.index));
            }
            if !(b.start.is_finite() && b.end.is_finite() && b.start < b.end) {
                return bad(format!(
                    "blocks[{k}] spans [{}, {}): not a range",
                    b.start, b.end
                ));
            }
            if k > 0 && b.start != self.blocks[k - 1].end {
                return bad(format!(
                    "blocks[{k}].start {} is not blocks[{}].end {} (blocks must tile the axis)",
                    b.start,
                    k - 1,
                    self.blocks[k - 1].end
                ));
            }
            if b.skipped.is_none() && b.photos.is_empty() {
                return bad(format!("blocks[{k}] has no photos and is not skipped"));
            }
        }
        Ok(())
    }

    /// A digest of the plan's content: a block's result records the digest of the plan it was
    /// trained for, so a changed plan retrains instead of reusing it.
    pub fn digest(&self) -> String {
        let text = serde_json::to_string(self).unwrap_or_default();
        // FNV-1a, 64 bits: not a security hash, a change detector.
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for byte in text.bytes() {
            h ^= byte as u64;
            h = h.wrapping_mul(0x100_0000_01b3);
        }
        format!("{h:016x}")
    }
}

/// The plan file of a plan folder, or `path` itself when it names a file.
pub fn plan_file(path: &Path) -> PathBuf {
    if path.is_dir() {
        path.join(PLAN_FILE)
    } else {
        path.to_path_buf()
    }
}

/// The plan folder (the shared directory) of a plan given as its folder or its file.
pub fn plan_folder(path: &Path) -> PathBuf {
    if path.is_dir() {
        path.to_path_buf()
    } else {
        match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        }
    }
}

/// Reads and checks a plan (its folder or its file).
pub fn load_plan(path: &Path) -> Result<Plan, SceneError> {
    let file = plan_file(path);
    let text = read_text(&file, MAX_PLAN_BYTES)?;
    let plan: Plan = serde_json::from_str(&text)
        .map_err(|e| SceneError::invalid(&file, format!("not a block plan: {e}")))?;
    plan.validate(&file)?;
    Ok(plan)
}

/// Writes `plan` (checked first) into `folder` as `plan.json`, atomically.
pub fn save_plan(folder: &Path, plan: &Plan) -> Result<(), SceneError> {
    let file = folder.join(PLAN_FILE);
    plan.validate(&file)?;
    let text = serde_json::to_string_pretty(plan)
        .map_err(|e| SceneError::invalid(&file, e.to_string()))?;
    write_atomic(&file, |w| std::io::Write::write_all(w, text.as_bytes()))
}
