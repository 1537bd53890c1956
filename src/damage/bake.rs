//! Damage baked into a model's colours, for viewers that cannot read label channels (SPZ has no
//! place for them): `export --damage-colours`.

use crate::damage::layer::{DamageLayer, display_splats};
use crate::splats::Splats;
use crate::splats::model::state::{HIDDEN, SELECTED};

/// The damage layer's colours painted in outright: labels hardened to 0 or 1 at probability 0.5
/// (logit 0) and drawn by `display_splats` at full opacity, which sets a Gaussian's DC to its
/// class colour and drops its view-dependent colour (where several classes pass, the last in
/// `DamageClass::ALL` order shows, as in the viewer). Labels and state bits are kept as they
/// were; selection and hiding are view state, not painted.
pub fn bake_damage_colours(splats: &Splats) -> Splats {
    let mut hard = splats.clone();
    for raw in &mut hard.raw_labels {
        // `!(raw >= 0)` sends NaN to "not damage".
        *raw = if !(*raw >= 0.0) {
            f32::NEG_INFINITY
        } else {
            f32::INFINITY
        };
    }
    for bits in &mut hard.meta.state {
        *bits &= !(SELECTED | HIDDEN);
    }
    let layer = DamageLayer {
        enabled: true,
        opacity: 1.0,
        ..DamageLayer::default()
    };
    let mut out = display_splats(&hard, 1.0, &layer).into_owned();
    out.raw_labels.clone_from(&splats.raw_labels);
    out.meta.state.clone_from(&splats.meta.state);
    out
}
