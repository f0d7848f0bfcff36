//! `tip_cutting_force`: a force peak just behind the needle tip.

use super::{Effect, EffectParameter, Geometry, ShaftPoint, TrialContext};

/// Cutting at the tip: the shaft density gains a triangular peak of height
/// $A$ at the tip falling to zero a width $w$ behind it,
/// $\Delta q(s) = A \max(0, 1 - (L - s)/w)$, total force $A w / 2$.
pub struct TipCuttingForce;

impl Effect for TipCuttingForce {
    fn id(&self) -> &'static str {
        "tip_cutting_force"
    }

    fn physics(&self) -> &'static str {
        "a force peak just behind the tip, about twice the shaft density (cutting)"
    }

    fn signature(&self) -> &'static str {
        "residual concentrated around the current tip position, moving with it"
    }

    fn parameters(&self, _geometry: &Geometry) -> Vec<EffectParameter> {
        vec![
            EffectParameter {
                name: "tip_amplitude".into(),
                null: 0.0,
                initial: 0.0,
                scale: 10.0,
                lower: None,
                upper: None,
                tested: true,
                meaning: "peak shaft force density at the tip, added to the shaft density (N/m)",
            },
            EffectParameter {
                name: "tip_width".into(),
                null: 0.005,
                initial: 0.005,
                scale: 0.005,
                lower: Some(0.001),
                upper: Some(0.03),
                tested: false,
                meaning: "length behind the tip over which the peak falls to zero (m)",
            },
        ]
    }

    fn shaft_density(&self, parameters: &[f64], _trial: &TrialContext, point: ShaftPoint) -> f64 {
        let (amplitude, width) = (parameters[0], parameters[1]);
        amplitude * (1.0 - (point.length - point.s) / width).max(0.0)
    }

    fn shaft_breakpoints(&self, parameters: &[f64], length: f64) -> Vec<f64> {
        vec![length - parameters[1]]
    }
}
