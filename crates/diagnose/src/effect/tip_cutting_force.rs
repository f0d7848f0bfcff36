//! `tip_cutting_force`: a force peak just behind the needle tip.

use super::{Effect, EffectParameter, Geometry, ShaftPoint, TrialContext};

/// Cutting at the tip: the tissue squeezed around the first millimetres of
/// the shaft grips it harder than further back, so the local friction
/// density is multiplied there by a triangular peak of relative height $A$
/// at the tip falling to one a width $w$ behind it,
/// $g(s) = 1 + A \max(0, 1 - (L - s)/w)$. The peak is relative: it scales
/// with whatever the friction density is in the trial (a faster insertion
/// grips harder along the whole shaft, the tip included), and adds
/// $A\,q\,w/2$ to the base force where the density $q$ is uniform.
///
/// The fitted parameters are the peak's excess length $e = A w / 2$ (the
/// length of shaft whose friction the peak adds) and its width $w$, so
/// $A = 2e/w$. The base force and the far markers see the added force
/// $q\,e$ and hardly its shape, so in $(A, w)$ the misfit has a long
/// curved valley along $A w = \text{const}$: on the default campaign a
/// refit from the score test's step walked down it in 9 Jacobians. In
/// $(e, w)$ that valley lies along the $w$ axis.
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
                name: "tip_excess".into(),
                null: 0.0,
                initial: 0.0,
                scale: 0.0025,
                lower: None,
                upper: None,
                tested: true,
                meaning: "length of shaft whose friction the tip peak adds (m); the peak's \
                          height relative to the shaft density is 2 tip_excess / tip_width",
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

    fn shaft_density_factor(
        &self,
        parameters: &[f64],
        _trial: &TrialContext,
        point: ShaftPoint,
    ) -> f64 {
        let (excess, width) = (parameters[0], parameters[1]);
        let amplitude = 2.0 * excess / width;
        1.0 + amplitude * (1.0 - (point.length - point.s) / width).max(0.0)
    }

    fn shaft_breakpoints(&self, parameters: &[f64], length: f64) -> Vec<f64> {
        vec![length - parameters[1]]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use needle_data::TrialKind;

    fn factor(parameters: &[f64], s: f64, length: f64) -> f64 {
        let trial = TrialContext {
            kind: TrialKind::Needle,
            velocity: 0.005,
            day: 2.0,
        };
        TipCuttingForce.shaft_density_factor(parameters, &trial, ShaftPoint { s, length })
    }

    #[test]
    fn the_peak_is_relative_and_falls_to_one_a_width_behind_the_tip() {
        let (length, width) = (0.03, 0.004);
        // Excess length w/2: a peak as high as the shaft density.
        let p = [0.5 * width, width];
        assert_eq!(factor(&p, length, length), 2.0);
        assert!((factor(&p, length - 0.5 * width, length) - 1.5).abs() < 1e-12);
        assert_eq!(factor(&p, length - width, length), 1.0);
        assert_eq!(factor(&p, 0.0, length), 1.0);
        // At the null amplitude it changes nothing anywhere.
        for s in [0.0, 0.02, 0.029, 0.03] {
            assert_eq!(factor(&[0.0, width], s, length), 1.0);
        }
    }
}
