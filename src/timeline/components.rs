//! The building component under a point, where a survey's dataset labels components per photo
//! (`truth/components/<stem>.png`, 8-bit ids named in `truth/manifest.ron`'s `components`, with
//! `truth/depth/<stem>.png` in millimetres to tell whether the photo sees the point): the id most
//! of the photos that see it give. The synthetic surveys have these; real captures do not, and
//! their regions have no component.

use std::collections::BTreeMap;
use std::path::Path;

use glam::DVec3;
use serde::Deserialize;

use crate::scene::Dataset;

/// A photo sees a point when its depth there is within this fraction of the point's depth...
const DEPTH_TOLERANCE: f64 = 0.1;
/// ...plus this many metres (a region's centroid lies on its fitted plane, not on the
/// protruding beam or column it may be on).
const DEPTH_SLACK_M: f64 = 0.15;

#[derive(Deserialize)]
struct ComponentManifest {
    #[serde(default)]
    components: Vec<(u8, String)>,
}

/// Per point, the name of the component most photos that see it label it with; all None when
/// the dataset has no component labels or `metres_per_unit` is unknown for the depth test.
pub fn components_at(
    dataset: &Dataset,
    points: &[DVec3],
    metres_per_unit: f64,
) -> Vec<Option<String>> {
    let none = vec![None; points.len()];
    let truth = dataset.root.join("truth");
    let Some(names) = component_names(&truth.join("manifest.ron")) else {
        return none;
    };
    let mut votes: Vec<BTreeMap<u8, usize>> = vec![BTreeMap::new(); points.len()];
    for view in &dataset.views {
        let labels = truth.join("components").join(format!("{}.png", view.name));
        let depth = truth.join("depth").join(format!("{}.png", view.name));
        let (Ok(labels), Ok(depth)) = (image::open(&labels), image::open(&depth)) else {
            continue;
        };
        let (labels, depth) = (labels.to_luma8(), depth.to_luma16());
        if labels.dimensions() != depth.dimensions() {
            continue;
        }
        let camera = view.camera.resized(labels.width(), labels.height());
        for (p, vote) in points.iter().zip(&mut votes) {
            let Some((x, y)) = camera.pixel_of(p.as_vec3()) else {
                continue;
            };
            let z = f64::from(camera.world_to_camera(p.as_vec3()).z) * metres_per_unit;
            let seen = f64::from(depth.get_pixel(x, y).0[0]) / 1000.0;
            if seen > 0.0 && (seen - z).abs() <= DEPTH_TOLERANCE * z + DEPTH_SLACK_M {
                *vote.entry(labels.get_pixel(x, y).0[0]).or_default() += 1;
            }
        }
    }
    votes
        .into_iter()
        .map(|v| {
            v.into_iter()
                .max_by_key(|&(id, n)| (n, std::cmp::Reverse(id)))
                .and_then(|(id, _)| names.get(&id).cloned())
        })
        .collect()
}

fn component_names(manifest: &Path) -> Option<BTreeMap<u8, String>> {
    let text =
        crate::scene::files::read_text(manifest, crate::scene::limits::MAX_PROJECT_JSON_BYTES)
            .ok()?;
    let parsed: ComponentManifest = ron::from_str(&text).ok()?;
    (!parsed.components.is_empty()).then(|| parsed.components.into_iter().collect())
}
