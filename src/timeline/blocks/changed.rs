//! Which blocks a detection's changes fall in: each new-damage and no-longer-seen pixel of a
//! change map placed on the twin's surface (the twin rendered at the view, its depth) and given
//! to the block whose own box holds that point along the long axis. Pixels where the twin renders
//! no surface are counted apart (unplaced).

use serde::{Deserialize, Serialize};

use crate::blocks::Plan;
use crate::blocks::surface::{block_of, surface_along};
use crate::raster::{Rasterizer, RenderOutput, RenderSettings};
use crate::scene::{Dataset, ImageScale, SceneError};
use crate::splats::Splats;
use crate::timeline::changes::ViewChanges;
use crate::timeline::near_floaters::leaving_out_near_floaters;

/// Changed pixels a block needs before `twin update` retrains it, at the detection's scale: a
/// few stray pixels of a noisy change map do not retrain a block.
pub const MIN_CHANGED_PIXELS: u64 = 20;

/// One block's share of a detection's changes (pixels at the detection's scale, all views).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct BlockChange {
    pub block: usize,
    /// New damage (any class) on the block's part of the structure.
    pub new_pixels: u64,
    /// Damage the twin shows there that the survey no longer does.
    pub gone_pixels: u64,
}

impl BlockChange {
    /// Whether the block changed enough to retrain: at least `min_pixels` changed pixels.
    pub fn changed(&self, min_pixels: u64) -> bool {
        self.new_pixels + self.gone_pixels >= min_pixels.max(1)
    }
}

/// The changes of a detection per block, and the changed pixels no block holds (no surface).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct BlockChanges {
    pub blocks: Vec<BlockChange>,
    pub unplaced_pixels: u64,
}

impl BlockChanges {
    /// The blocks with at least `min_pixels` changed pixels.
    pub fn changed(&self, min_pixels: u64) -> Vec<usize> {
        self.blocks
            .iter()
            .filter(|b| b.changed(min_pixels))
            .map(|b| b.block)
            .collect()
    }
}

/// Attributes `views`' changes (found on `dataset` at `scale` against `model`, the twin merged
/// from `plan`) to `plan`'s blocks.
pub fn changes_per_block(
    plan: &Plan,
    model: &Splats,
    dataset: &Dataset,
    views: &[ViewChanges],
    scale: ImageScale,
    background: glam::Vec3,
) -> Result<BlockChanges, SceneError> {
    let mut result = BlockChanges {
        blocks: (0..plan.blocks.len())
            .map(|block| BlockChange {
                block,
                ..BlockChange::default()
            })
            .collect(),
        unplaced_pixels: 0,
    };
    let settings = RenderSettings::new(background, model.sh_degree);
    let mut rasterizer = Rasterizer::new();
    let mut out = RenderOutput::default();
    for view in views {
        let changed = |masks: &[crate::scene::Mask], p: usize| masks.iter().any(|m| m.data[p] != 0);
        let any =
            |masks: &[crate::scene::Mask]| masks.iter().any(|m| m.data.iter().any(|&v| v != 0));
        if !any(&view.new) && !any(&view.gone) {
            continue;
        }
        let camera = dataset.view_camera(view.index, scale)?;
        // The twin as detection rendered it (floaters in front of a new pose left out).
        let seen = leaving_out_near_floaters(model, &camera, &settings);
        rasterizer.forward(model, &camera, &seen, &mut out);
        for (p, along) in surface_along(&out, &camera, plan).into_iter().enumerate() {
            let (new, gone) = (changed(&view.new, p), changed(&view.gone, p));
            if !new && !gone {
                continue;
            }
            match along {
                Some(a) => {
                    let block = &mut result.blocks[block_of(plan, a)];
                    block.new_pixels += u64::from(new);
                    block.gone_pixels += u64::from(gone);
                }
                None => result.unplaced_pixels += 1,
            }
        }
    }
    Ok(result)
}
