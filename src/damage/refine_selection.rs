//! What a refinement trains: a person's selection as given, or the damage Gaussians selected
//! against the training views' masks; and the regions the selection falls into (one hull per
//! region and view when hulls are per region).

use rayon::prelude::*;

use crate::damage::DamageClass;
use crate::damage::refine_config::RefineConfig;
use crate::damage::select::{MaskView, Selection, select};
use crate::scene::Dataset;
use crate::splats::Splats;
use crate::train::focus::hulls::{median_spacing, regions};
use crate::train::job::{JobContext, JobError, Progress};

/// A person's selection (indices into `model`, out-of-range ones dropped), each classed by its
/// most probable label.
pub(super) fn given_selection(model: &Splats, given: &[u32]) -> Selection {
    let mut selected: Vec<u32> = given
        .iter()
        .copied()
        .filter(|&g| (g as usize) < model.len())
        .collect();
    selected.sort_unstable();
    selected.dedup();
    let channels = model.label_channels.min(DamageClass::ALL.len());
    let validated_class = selected
        .iter()
        .map(|&g| {
            let labels = &model.labels_of(g as usize)[..channels];
            (0..channels)
                .max_by(|&a, &b| labels[a].total_cmp(&labels[b]))
                .map_or(DamageClass::Crack, |k| DamageClass::ALL[k])
        })
        .collect();
    Selection {
        filtered: selected.clone(),
        validated: selected.clone(),
        selected,
        validated_class,
        seconds: Default::default(),
    }
}

/// Damage Gaussians selected against the training views' masks at the selection scale.
pub(super) fn select_by_masks(
    ctx: &mut JobContext,
    dataset: &Dataset,
    model: &Splats,
    config: &RefineConfig,
    train_idx: &[usize],
    masks: &dyn crate::scene::MaskSource,
) -> Result<Selection, JobError> {
    ctx.log(format!(
        "selecting damage Gaussians among {} against {} views' masks",
        model.len(),
        train_idx.len()
    ));
    let mask_views: Vec<MaskView> = train_idx
        .par_iter()
        .map(|&i| {
            let (camera, mut masks) = dataset.load_view_masks(i, masks, config.select_scale)?;
            Ok(MaskView {
                camera,
                masks: DamageClass::ALL.iter().map(|c| masks.remove(c)).collect(),
            })
        })
        .collect::<Result<_, crate::scene::SceneError>>()?;
    let n = model.len();
    let selection = select(
        model,
        &mask_views,
        &config.select,
        config.background,
        &mut |done, total| {
            ctx.progress(Progress::counted("select", done, total, n));
        },
    );
    Ok(selection)
}

/// Per selected Gaussian its region (all in region 0 when hulls are per view).
pub(super) fn region_labels(
    model: &Splats,
    selection: &Selection,
    config: &RefineConfig,
) -> Vec<u32> {
    if !config.hulls.per_region {
        return vec![0; selection.selected.len()];
    }
    // The radius: a few median nearest-neighbour spacings of the selection, so a region is a
    // connected piece of damage at the twin's own density.
    let spacing = median_spacing(model, &selection.selected);
    regions(
        model,
        &selection.selected,
        config.region_spacings * spacing.max(1e-6),
    )
}
