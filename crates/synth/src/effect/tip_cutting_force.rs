//! `tip_cutting_force`: a force peak just behind the needle tip (cutting).
//!
//! The tissue is cut at the bevel and squeezed around the first millimetres
//! of the shaft, so the axial force density there is about twice the
//! friction density further back (the paper's Fig. 10(b)). The truth
//! multiplies the shaft density at distance $d$ behind the tip by
//! $$1 + A \exp\!\bigl(-((d - d_p)/w)^2\bigr),$$
//! a Gaussian bump of relative amplitude $A$, centred $d_p$ behind the tip,
//! of width $w$. It moves with the tip.

use serde::{Deserialize, Serialize};

use super::{EffectId, TruthEffect};
use crate::error::SynthError;
use crate::scenario::{FieldChecker, Scenario};

/// The highest relative peak accepted: a hundred times the shaft density
/// behind it, fifty times the paper's (about twice); beyond, the load is no
/// needle's, and a far higher one overflows the field.
const MAX_AMPLITUDE: f64 = 100.0;

/// The tip peak of the shaft force density.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TipCuttingForce {
    /// Peak height relative to the shaft density (1.0: twice the density).
    pub amplitude: f64,
    /// Distance of the peak behind the tip (m).
    pub offset: f64,
    /// Width of the peak (m).
    pub width: f64,
}

impl TipCuttingForce {
    /// Factor on the shaft density at `distance` behind the tip (m).
    pub fn factor(&self, distance: f64) -> f64 {
        let z = (distance - self.offset) / self.width;
        1.0 + self.amplitude * (-z * z).exp()
    }
}

impl TruthEffect for TipCuttingForce {
    const ID: EffectId = EffectId::TipCuttingForce;

    fn check(&self, c: &FieldChecker<'_>, field: &str, _: &Scenario) -> Result<(), SynthError> {
        c.within(
            self.amplitude,
            0.0,
            MAX_AMPLITUDE,
            &format!("{field}.amplitude"),
        )?;
        c.non_negative(self.offset, &format!("{field}.offset"))?;
        c.positive(self.width, &format!("{field}.width"))
    }
}
