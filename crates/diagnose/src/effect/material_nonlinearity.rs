//! `material_nonlinearity`: strains beyond the linear range.

use super::{Effect, EffectParameter, Geometry};

/// The phantom is a compressible neo-Hookean solid with the model's own
/// small-strain $E$, $\nu$, not a linear one. Its equilibrium
/// $f_\text{int}(u) = f$, expanded in the load, has the solution
/// $u = u_1 + u_2 + u_3 + O(f^4)$: $u_1$ the linear model's, $u_2$ and
/// $u_3$ of second and third order, each one more back-substitution with
/// the factorisation of $K$ the linear model already has (see `series`).
/// The effect predicts
/// $$u = u_1 + w\,(u_2 + u_3):$$
/// $w = 0$ is the paper's linear model, $w = 1$ the neo-Hookean solid to
/// third order in the load. The prediction is linear in $w$, so the score
/// test is exact; a fitted $w$ well away from 1 says that the material is
/// nonlinear but not neo-Hookean. The needle's placement stays that of
/// $u_1$ (see `forward`).
pub struct MaterialNonlinearity;

impl Effect for MaterialNonlinearity {
    fn id(&self) -> &'static str {
        "material_nonlinearity"
    }

    fn physics(&self) -> &'static str {
        "strains above about 15% leave the linear range (the paper's Fig. 5): the phantom \
         responds as a neo-Hookean solid"
    }

    fn signature(&self) -> &'static str {
        "residual grows faster than linearly with load and strain: largest at the deepest \
         probe holds and needle frames, near the tool, with the same sign across trials"
    }

    fn parameters(&self, _geometry: &Geometry) -> Vec<EffectParameter> {
        vec![EffectParameter {
            name: "nonlinear_weight".into(),
            null: 0.0,
            initial: 1.0,
            scale: 1.0,
            lower: Some(0.0),
            upper: Some(3.0),
            tested: true,
            meaning: "weight of the neo-Hookean terms of second and third order in the load \
                      (1: neo-Hookean, 0: linear)",
        }]
    }

    fn nonlinear_weight(&self, parameters: &[f64]) -> f64 {
        parameters[0]
    }
}
