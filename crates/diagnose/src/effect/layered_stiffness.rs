//! `layered_stiffness`: two layers of different stiffness, split at a depth.

use super::{Effect, EffectParameter, Geometry, TrialContext};

/// The phantom is cast in two layers (the paper's Fig. 15): beyond the
/// boundary $y_b$ the modulus is $E (1 + d)$. An element cut by the
/// boundary gets the mean over its y-extent, so the model is continuous in
/// $y_b$ and the boundary can be fitted.
pub struct LayeredStiffness;

impl Effect for LayeredStiffness {
    fn id(&self) -> &'static str {
        "layered_stiffness"
    }

    fn physics(&self) -> &'static str {
        "the phantom is made of layers of different stiffness (the paper's Fig. 15)"
    }

    fn signature(&self) -> &'static str {
        "displacement residual changes character across a depth y; \
         identified E differs between probe sites"
    }

    fn parameters(&self, geometry: &Geometry) -> Vec<EffectParameter> {
        vec![
            EffectParameter {
                name: "layer_contrast".into(),
                null: 0.0,
                initial: 0.0,
                scale: 0.1,
                lower: Some(-0.9),
                upper: Some(10.0),
                tested: true,
                meaning: "relative change of Young's modulus beyond the layer boundary",
            },
            EffectParameter {
                name: "layer_boundary".into(),
                null: 0.5 * geometry.depth,
                initial: 0.5 * geometry.depth,
                scale: 0.1 * geometry.depth,
                lower: Some(0.1 * geometry.depth),
                upper: Some(0.9 * geometry.depth),
                tested: false,
                meaning: "depth y of the boundary between the layers (m)",
            },
        ]
    }

    fn stiffness_factor(
        &self,
        parameters: &[f64],
        _trial: &TrialContext,
        _centroid: [f64; 2],
        y_extent: [f64; 2],
    ) -> f64 {
        let (contrast, boundary) = (parameters[0], parameters[1]);
        let span = y_extent[1] - y_extent[0];
        let beyond = ((y_extent[1] - boundary) / span).clamp(0.0, 1.0);
        1.0 + contrast * beyond
    }
}
