//! `material_stiffening`: the phantom stiffens over the days after casting.

use super::{Chain, Effect, EffectParameter, Geometry, TrialContext};

/// Plasticizer leaks out and the phantom stiffens:
/// $E(\text{day}) = E_0 (1 + r\,\text{day})$.
pub struct MaterialStiffening;

impl Effect for MaterialStiffening {
    fn id(&self) -> &'static str {
        "material_stiffening"
    }

    fn physics(&self) -> &'static str {
        "E grows over the days after casting (the paper: about 6% between two tests days apart)"
    }

    fn signature(&self) -> &'static str {
        "residuals and per-trial E correlate with day"
    }

    fn parameters(&self, _geometry: &Geometry) -> Vec<EffectParameter> {
        vec![EffectParameter {
            name: "stiffening_rate".into(),
            null: 0.0,
            initial: 0.0,
            scale: 0.01,
            // The lower bound keeps E positive for campaigns up to 20 days.
            lower: Some(-0.05),
            upper: Some(1.0),
            tested: true,
            meaning: "relative growth of Young's modulus per day since casting (1/day)",
        }]
    }

    fn stiffness_factor(
        &self,
        parameters: &[f64],
        trial: &TrialContext,
        _centroid: [f64; 2],
        _y_extent: [f64; 2],
    ) -> f64 {
        1.0 + parameters[0] * trial.day
    }

    /// $c = 1 + r d$: $\partial \ln c / \partial r = d / (1 + r d)$.
    fn chain(&self, parameters: &[f64], _index: usize, trial: &TrialContext) -> Option<Chain> {
        Some(Chain::Stiffness(
            trial.day / (1.0 + parameters[0] * trial.day),
        ))
    }
}
