//! `layered_stiffness`: the phantom is cast in layers of different
//! stiffness across the insertion direction (the paper's Fig. 15).
//!
//! The truth's modulus is piecewise constant in y: layer $k$ spans
//! $b_{k-1} \le y < b_k$ (with $b_{-1} = 0$ and the last layer reaching the
//! back face) and has its own Young's modulus $E_k$ on day 0; the Poisson
//! ratio is the phantom's. The mesh has grid lines on the boundaries, so
//! every element lies in one layer. The modulus replaces the phantom's
//! `youngs_modulus`.

use serde::{Deserialize, Serialize};

use super::{EffectId, TruthEffect};
use crate::error::SynthError;
use crate::scenario::{FieldChecker, PhantomSpec, Scenario};

/// Layers along y with their moduli.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LayeredStiffness {
    /// Layer boundaries in y (m), increasing, inside the phantom.
    pub boundaries: Vec<f64>,
    /// Young's modulus of each layer on day 0 (Pa), one more than boundaries.
    pub moduli: Vec<f64>,
}

impl LayeredStiffness {
    /// Index of the layer that holds depth `y`.
    pub fn layer_of(&self, y: f64) -> usize {
        self.boundaries.iter().filter(|&&b| y >= b).count()
    }
}

impl TruthEffect for LayeredStiffness {
    const ID: EffectId = EffectId::LayeredStiffness;

    fn check(&self, c: &FieldChecker<'_>, field: &str, s: &Scenario) -> Result<(), SynthError> {
        c.check(
            self.moduli.len() == self.boundaries.len() + 1,
            &format!("{field}.moduli"),
            || {
                format!(
                    "needs one modulus more than boundaries ({} boundaries, {} moduli)",
                    self.boundaries.len(),
                    self.moduli.len()
                )
            },
        )?;
        for (i, &e) in self.moduli.iter().enumerate() {
            // As for the phantom's own modulus: below it, no solid.
            c.check(
                e.is_finite() && e >= PhantomSpec::MIN_YOUNGS_MODULUS,
                &format!("{field}.moduli[{i}]"),
                || {
                    format!(
                        "must be finite and at least {} Pa, got {e:?}",
                        PhantomSpec::MIN_YOUNGS_MODULUS
                    )
                },
            )?;
        }
        let mut previous = 0.0;
        for (i, &b) in self.boundaries.iter().enumerate() {
            c.check(
                b > previous && b < s.phantom.depth,
                &format!("{field}.boundaries[{i}]"),
                || {
                    format!(
                        "must increase and lie inside (0, {}), got {b:?}",
                        s.phantom.depth
                    )
                },
            )?;
            previous = b;
        }
        Ok(())
    }
}
