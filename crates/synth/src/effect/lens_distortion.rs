//! `lens_distortion`: the camera model used to rectify the tracks is wrong.
//!
//! The tracks are written as if rectified, but an uncalibrated radial
//! distortion remains. A tracked position $p$ on the top face is moved
//! radially about the image centre $c$:
//! $$p_d = c + (p - c)\,\bigl(1 + k_1\,|p - c|^2\bigr),$$
//! with $k_1$ in 1/m². The rest positions in `markers_rest.csv` are the
//! painted grid (not measured by the camera), so the distortion shows as a
//! radial residual field that is constant in time and grows with radius.
//! Only tracks written directly (`markers.csv`) are distorted; forces and
//! the physics are unchanged.

use serde::{Deserialize, Serialize};

use super::{EffectId, TruthEffect};
use crate::error::SynthError;
use crate::scenario::{FieldChecker, Scenario};

/// Residual radial distortion of the tracked positions.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LensDistortion {
    /// First radial coefficient (1/m²).
    pub k1: f64,
    /// Image centre on the top face (m).
    pub centre: (f64, f64),
}

impl LensDistortion {
    /// The distorted image of position `p` (m).
    pub fn distort(&self, p: [f64; 2]) -> [f64; 2] {
        let (dx, dy) = (p[0] - self.centre.0, p[1] - self.centre.1);
        let scale = 1.0 + self.k1 * (dx * dx + dy * dy);
        [self.centre.0 + dx * scale, self.centre.1 + dy * scale]
    }
}

impl TruthEffect for LensDistortion {
    const ID: EffectId = EffectId::LensDistortion;

    fn check(&self, c: &FieldChecker<'_>, field: &str, s: &Scenario) -> Result<(), SynthError> {
        c.check(self.k1.is_finite(), &format!("{field}.k1"), || {
            format!("must be finite, got {:?}", self.k1)
        })?;
        let radius = s.phantom.width.hypot(s.phantom.depth);
        c.check(
            self.k1.abs() * radius * radius < 0.1,
            &format!("{field}.k1"),
            || {
                format!(
                    "distorts the phantom corners by more than 10% ({})",
                    self.k1 * radius * radius
                )
            },
        )?;
        c.check(
            self.centre.0.is_finite() && self.centre.1.is_finite(),
            &format!("{field}.centre"),
            || "must be finite".into(),
        )
    }
}
