//! `out_of_plane`: the slab is thin but three-dimensional.

use super::{Effect, EffectParameter, Geometry};

/// The markers sit on the top face of a slab whose needle and probe loads
/// act through its thickness; a plane model cannot represent that. The
/// effect brings in a Tet10 model of the slab (markers on the top face,
/// needle in the mid-plane, see `body`) and predicts
/// $u = (1 - w)\,u_\text{plane} + w\,u_\text{slab}$.
///
/// The plane and the slab are different models, not one nested in the
/// other; the weight $w$ nests them in one family (the composite model of
/// Cox and Atkinson for testing non-nested hypotheses), so the score test
/// and the likelihood ratio apply: $w = 0$ is the paper's plane model,
/// $w = 1$ the slab, and a fitted $w$ near 1 with a small interval says
/// that the data prefer the slab outright.
pub struct OutOfPlane;

impl Effect for OutOfPlane {
    fn id(&self) -> &'static str {
        "out_of_plane"
    }

    fn physics(&self) -> &'static str {
        "the slab is thin but 3-D: markers on the top face move less than the needle's \
         mid-plane, and a plane model misreads the shaft forces (the paper: about 26% too low)"
    }

    fn signature(&self) -> &'static str {
        "integrated shaft force below the measured base force in every needle trial; \
         residual largest near the needle line; material constants that fit only outside \
         physical ranges (nu far below 0.45 for PVC)"
    }

    fn acts_after_solves(&self) -> bool {
        true
    }

    fn parameters(&self, _geometry: &Geometry) -> Vec<EffectParameter> {
        vec![EffectParameter {
            name: "slab_weight".into(),
            null: 0.0,
            initial: 1.0,
            scale: 1.0,
            lower: Some(0.0),
            upper: Some(1.5),
            tested: true,
            meaning: "weight of the 3-D slab's prediction against the plane model's (1: slab)",
        }]
    }

    fn slab_weight(&self, parameters: &[f64]) -> f64 {
        parameters[0]
    }
}
