//! `velocity_dependent_friction`: shaft force density growing with speed.

use super::{Chain, Effect, EffectParameter, Geometry, ShaftPoint, TrialContext};

/// Friction that grows with insertion speed (the paper's Fig. 14):
/// $q(v) = q_0 + q_1 v$, the baseline density being $q_0$.
pub struct VelocityDependentFriction;

impl Effect for VelocityDependentFriction {
    fn id(&self) -> &'static str {
        "velocity_dependent_friction"
    }

    fn physics(&self) -> &'static str {
        "shaft force density grows with insertion speed (the paper's Fig. 14)"
    }

    fn signature(&self) -> &'static str {
        "force and displacement residuals of needle trials correlate with trial velocity, \
         sign flips between slow and fast trials"
    }

    fn parameters(&self, _geometry: &Geometry) -> Vec<EffectParameter> {
        vec![EffectParameter {
            name: "friction_velocity_slope".into(),
            null: 0.0,
            initial: 0.0,
            scale: 1000.0,
            lower: None,
            upper: None,
            tested: true,
            meaning: "growth of the shaft density with insertion speed, q1 in q0 + q1 v (N s/m^2)",
        }]
    }

    fn shaft_density(&self, parameters: &[f64], trial: &TrialContext, _point: ShaftPoint) -> f64 {
        parameters[0] * trial.velocity
    }

    fn chain(&self, _parameters: &[f64], _index: usize, trial: &TrialContext) -> Option<Chain> {
        Some(Chain::ShaftDensity(trial.velocity))
    }
}
