//! The bridge's damage, in the building's terms (cracks and spalls on the two side facades, so
//! `DamageState::eval`, the renderer and the quantities serve it unchanged): per span and side,
//! flexural cracks rising from the girder soffit at midspan, shear cracks leaning towards the
//! supports, girder spalls along the bottom edge with the lower bars exposed, pier column spalls
//! with the main bars exposed, and cracks across pier columns and caps. Survey 2 changes only some
//! spans (`BridgeDamage::changed_spans`); the others keep survey 1's damage exactly.

use std::f32::consts::{FRAC_PI_2, FRAC_PI_4, PI};

use glam::Vec2;

use super::bridge::{CAP_DEPTH, PIER_SIZE, SPAN, girder_bottom, span_of, support_x};
use super::building::Building;
use super::cracks::{Crack, CrackSeed, extend_old_cracks, grow};
use super::damage::{DamageState, Rebar, RegionIds, Spall, crack_width, facade_bounds};

/// The side facades (front -y, back +y); the end facades stay clean.
const SIDES: [usize; 2] = [0, 2];

/// Both surveys' damage and which spans survey 2 changed (grown or new damage), in order.
pub struct BridgeDamage {
    pub survey1: DamageState,
    pub survey2: DamageState,
    pub changed_spans: Vec<u32>,
}

/// The damage of `bridge` (made by `bridge::bridge` with `spans` spans).
pub fn generate(bridge: &Building, spans: u32, seed: u64) -> BridgeDamage {
    let mut rng = fastrand::Rng::with_seed(seed ^ 0xB21D_6E00);
    let mut ids = RegionIds::default();
    let mut cracks: [Vec<Crack>; 4] = Default::default();
    let mut spalls = Vec::new();
    for span in 0..spans {
        for f in SIDES {
            let severity = 0.35 + 0.65 * rng.f32();
            let mut site = Site {
                bridge,
                facade: f,
                span,
                rng: &mut rng,
                ids: &mut ids,
            };
            site.span_cracks(severity, &mut cracks[f]);
            site.span_spalls(severity, &mut spalls);
        }
    }
    let survey1 = DamageState::new(cracks.clone(), spalls.clone(), bridge);

    let changed_spans = pick_changed(spans, &mut rng);
    let changed = |x: f32| changed_spans.contains(&span_of(x, spans));
    for sp in spalls.iter_mut().filter(|sp| changed(sp.centre.x)) {
        if rng.f32() < 0.8 {
            sp.radius *= 1.25 + 0.25 * rng.f32();
            if sp.rebar.is_none() {
                sp.rebar = rebar_for(sp.centre, sp.radius, &mut ids);
            }
        }
    }
    for f in SIDES {
        let bounds = facade_bounds(&bridge.facades[f]);
        let keep = |c: &Crack| changed(c.points[0].x);
        let extended = extend_old_cracks(&mut rng, &cracks[f], keep, bounds, [0.3, 0.5], 0.01);
        cracks[f].extend(extended);
    }
    for &span in &changed_spans {
        for f in SIDES {
            let mut site = Site {
                bridge,
                facade: f,
                span,
                rng: &mut rng,
                ids: &mut ids,
            };
            let count = 1 + site.rng.usize(0..3);
            site.flexural_cracks(count, &mut cracks[f]);
            if site.rng.f32() < 0.5 {
                site.girder_spall(&mut spalls);
            }
        }
    }
    let survey2 = DamageState::new(cracks, spalls, bridge);
    BridgeDamage {
        survey1,
        survey2,
        changed_spans,
    }
}

/// About half the spans change; at least one does, and with two spans or more at least one
/// does not (the timeline's "update only what changed" needs both).
fn pick_changed(spans: u32, rng: &mut fastrand::Rng) -> Vec<u32> {
    let mut changed: Vec<bool> = (0..spans).map(|_| rng.f32() < 0.5).collect();
    if !changed.contains(&true) {
        changed[rng.usize(0..spans as usize)] = true;
    }
    if spans >= 2 && !changed.contains(&false) {
        changed[rng.usize(0..spans as usize)] = false;
    }
    (0..spans).filter(|&s| changed[s as usize]).collect()
}

/// Exposed bars under a spall big enough to show them: horizontal girder bars near the soffit,
/// vertical pier bars on a pier column's face.
fn rebar_for(centre: Vec2, radius: f32, ids: &mut RegionIds) -> Option<Rebar> {
    if !(radius > 0.26) {
        return None;
    }
    if centre.y > girder_bottom() - 0.2 {
        let b = girder_bottom();
        return Some(Rebar {
            id: ids.take(),
            vertical: false,
            bars: vec![b + 0.07, b + 0.19],
            tie_spacing: 0.2,
        });
    }
    let pier = support_x((centre.x / SPAN).round() as u32);
    ((centre.x - pier).abs() < 0.5 * PIER_SIZE).then(|| Rebar {
        id: ids.take(),
        vertical: true,
        bars: vec![pier - 0.45, pier - 0.15, pier + 0.15, pier + 0.45],
        tie_spacing: 0.2,
    })
}

/// One span's side: where its damage goes.
struct Site<'a> {
    bridge: &'a Building,
    facade: usize,
    span: u32,
    rng: &'a mut fastrand::Rng,
    ids: &'a mut RegionIds,
}

impl Site<'_> {
    fn x0(&self) -> f32 {
        support_x(self.span)
    }

    fn grow(&mut self, seed: CrackSeed, generation: u32, out: &mut Vec<Crack>) {
        let bounds = facade_bounds(&self.bridge.facades[self.facade]);
        grow(self.rng, seed, bounds, generation, out);
    }

    /// Vertical cracks rising from the girder soffit in the middle of the span.
    fn flexural_cracks(&mut self, count: usize, out: &mut Vec<Crack>) {
        for _ in 0..count {
            let u = self.x0() + SPAN * (0.3 + 0.4 * self.rng.f32());
            let seed = CrackSeed {
                start: Vec2::new(u, girder_bottom() + 0.02),
                angle: FRAC_PI_2 + (self.rng.f32() - 0.5) * 0.3,
                length: 0.5 + 0.6 * self.rng.f32(),
                width: 0.012 + 0.015 * self.rng.f32(),
                region: self.ids.take(),
            };
            self.grow(seed, 0, out);
        }
    }

    fn span_cracks(&mut self, severity: f32, out: &mut Vec<Crack>) {
        self.flexural_cracks((1.0 + 4.0 * severity).round() as usize, out);
        // Shear cracks near both supports, leaning up towards them; they start far enough in
        // that they and survey 2's extensions stay inside the span.
        for (support, angle) in [(self.x0(), PI - FRAC_PI_4), (self.x0() + SPAN, FRAC_PI_4)] {
            if !(self.rng.f32() < 0.6 * severity) {
                continue;
            }
            let inward = if angle > FRAC_PI_2 { 1.0 } else { -1.0 };
            let seed = CrackSeed {
                start: Vec2::new(
                    support + inward * (1.8 + 1.2 * self.rng.f32()),
                    girder_bottom() + 0.1,
                ),
                angle: angle + (self.rng.f32() - 0.5) * 0.3,
                length: 0.9 + 0.5 * self.rng.f32(),
                width: crack_width(self.rng),
                region: self.ids.take(),
            };
            self.grow(seed, 0, out);
        }
        if self.span == 0 {
            return;
        }
        // The pier at the span's start: a crack across a column and one up into the cap.
        let pier = self.x0();
        if self.rng.f32() < 0.6 * severity {
            let seed = CrackSeed {
                start: Vec2::new(pier - 0.5 * PIER_SIZE - 0.02, 0.6 + 2.0 * self.rng.f32()),
                angle: (self.rng.f32() - 0.5) * 0.2,
                length: PIER_SIZE + 0.05,
                width: 0.015 + 0.01 * self.rng.f32(),
                region: self.ids.take(),
            };
            self.grow(seed, 1, out);
        }
        if self.rng.f32() < 0.5 * severity {
            let seed = CrackSeed {
                start: Vec2::new(
                    pier + (self.rng.f32() - 0.5) * 1.0,
                    girder_bottom() - CAP_DEPTH + 0.02,
                ),
                angle: FRAC_PI_2 + (self.rng.f32() - 0.5) * 0.3,
                length: 0.4 + 0.4 * self.rng.f32(),
                width: 0.012 + 0.01 * self.rng.f32(),
                region: self.ids.take(),
            };
            self.grow(seed, 1, out);
        }
    }

    /// A spall along the girder's bottom edge, showing the lower bars when large.
    fn girder_spall(&mut self, out: &mut Vec<Spall>) {
        let centre = Vec2::new(
            self.x0() + 1.0 + (SPAN - 2.0) * self.rng.f32(),
            girder_bottom() + 0.18 + 0.1 * self.rng.f32(),
        );
        let radius = 0.2 + 0.2 * self.rng.f32();
        self.push_spall(centre, radius, out);
    }

    fn push_spall(&mut self, centre: Vec2, radius: f32, out: &mut Vec<Spall>) {
        let id = self.ids.take();
        let seed = self.rng.u32(..);
        out.push(Spall {
            id,
            facade: self.facade,
            centre,
            radius,
            seed,
            rebar: rebar_for(centre, radius, self.ids),
        });
    }

    fn span_spalls(&mut self, severity: f32, out: &mut Vec<Spall>) {
        if self.rng.f32() < 0.9 * severity {
            self.girder_spall(out);
        }
        if self.span > 0 && self.rng.f32() < 0.7 * severity {
            // On the pier column at the span's start, inside the span.
            let centre = Vec2::new(
                self.x0() + 0.05 + 0.25 * self.rng.f32(),
                0.7 + 3.0 * self.rng.f32(),
            );
            let radius = 0.24 + 0.2 * self.rng.f32();
            self.push_spall(centre, radius, out);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::bridge::bridge;
    use super::*;

    #[test]
    fn every_span_is_damaged_and_survey_2_changes_some_spans_but_not_all() {
        let spans = 4;
        let b = bridge(spans, 3);
        for seed in 0..8 {
            let d = generate(&b, spans, seed);
            for span in 0..spans {
                let in_span = |x: f32| span_of(x, spans) == span;
                let cracks = SIDES
                    .iter()
                    .flat_map(|&f| &d.survey1.cracks[f])
                    .filter(|c| in_span(c.points[0].x))
                    .count();
                assert!(cracks >= 2, "seed {seed} span {span}: {cracks} cracks");
            }
            assert!(!d.changed_spans.is_empty() && d.changed_spans.len() < spans as usize);
            // Unchanged spans keep survey 1's spalls exactly.
            for (a, b2) in d.survey1.spalls.iter().zip(&d.survey2.spalls) {
                if !d.changed_spans.contains(&span_of(a.centre.x, spans)) {
                    assert_eq!(a, b2);
                }
            }
        }
    }
}
