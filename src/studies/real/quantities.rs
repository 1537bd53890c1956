//! The twin's measured damage against a stamped survey's `truth/quantities.json`: crack length,
//! spalled area and rebar length, in metres.

use std::path::Path;

use serde::Deserialize;

use crate::damage::DamageClass;
use crate::damage::measure::Measurement;
use crate::studies::real::rows::QuantityRow;

/// The totals `synth::stamp` writes (`truth/quantities.json`; other fields are not read).
#[derive(Clone, Debug, Deserialize)]
pub struct TruthQuantities {
    pub metres_per_unit: f64,
    pub totals: TruthTotals,
}

#[derive(Clone, Copy, Debug, Deserialize)]
pub struct TruthTotals {
    pub crack_length_m: f64,
    pub spalling_area_m2: f64,
    pub rebar_length_m: f64,
}

/// Reads `survey/truth/quantities.json`; one line naming the file when it is missing or not
/// the stamp's.
pub fn read_truth(survey: &Path) -> Result<TruthQuantities, String> {
    let path = survey.join("truth").join("quantities.json");
    let bytes =
        crate::scene::files::read_regular(&path, crate::scene::limits::MAX_PROJECT_JSON_BYTES)
            .map_err(|e| e.to_string())?;
    serde_json::from_slice(&bytes).map_err(|e| format!("{}: {e}", path.display()))
}

/// One row per quantity the truth has (a class the stamp did not draw has 0 and no row).
pub fn quantity_rows(
    truth: &TruthTotals,
    measured: &Measurement,
    metres_per_unit: f64,
) -> Vec<QuantityRow> {
    let m = metres_per_unit;
    [
        (
            "crack length (m)",
            truth.crack_length_m,
            measured.total_length(DamageClass::Crack) * m,
        ),
        (
            "spalled area (m²)",
            truth.spalling_area_m2,
            measured.total_area(DamageClass::Spalling) * m * m,
        ),
        (
            "rebar length (m)",
            truth.rebar_length_m,
            measured.total_length(DamageClass::Rebar) * m,
        ),
    ]
    .into_iter()
    .filter(|&(_, truth, _)| truth > 0.0)
    .map(|(quantity, truth, measured)| QuantityRow {
        quantity: quantity.to_string(),
        truth,
        measured,
        relative_error: (measured - truth) / truth,
    })
    .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::damage::measure::MeasuredRegion;

    fn region(class: DamageClass, length: Option<f64>, area: f64) -> MeasuredRegion {
        MeasuredRegion {
            class,
            plane: 0,
            centroid: [0.0; 3],
            length,
            width: None,
            area,
            gaussians: 1,
            first_survey: None,
            voxels: Default::default(),
            members: Vec::new(),
        }
    }

    #[test]
    fn measured_totals_are_scaled_to_metres_and_compared() {
        let measured = Measurement {
            regions: vec![
                region(DamageClass::Crack, Some(0.1), 0.001),
                region(DamageClass::Crack, Some(0.05), 0.001),
                region(DamageClass::Spalling, None, 0.01),
            ],
            ..Measurement::default()
        };
        let truth = TruthTotals {
            crack_length_m: 2.0,
            spalling_area_m2: 1.0,
            rebar_length_m: 0.0,
        };
        let rows = quantity_rows(&truth, &measured, 10.0);
        assert_eq!(rows.len(), 2, "no rebar in the truth, no rebar row");
        assert!((rows[0].measured - 1.5).abs() < 1e-12);
        assert!((rows[0].relative_error + 0.25).abs() < 1e-12);
        assert!((rows[1].measured - 1.0).abs() < 1e-12);
        assert!(rows[1].relative_error.abs() < 1e-12);
    }
}
