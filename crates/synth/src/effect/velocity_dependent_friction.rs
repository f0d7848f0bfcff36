//! `velocity_dependent_friction`: the shaft force density grows with the
//! insertion velocity (the paper's Fig. 14).
//!
//! The friction between shaft and tissue is partly viscous, so the axial
//! force per unit length behind the tip grows with the sliding speed. The
//! truth uses a linear law about the reference velocity $v_0$ of
//! [`crate::scenario::Shaft`]:
//! $$q(v) = q_0\,\bigl(1 + s\,(v - v_0)\bigr),$$
//! with the slope $s$ (s/m) as the effect's parameter. Without the effect,
//! $q = q_0$ at every velocity.

use serde::{Deserialize, Serialize};

use super::{EffectId, TruthEffect};
use crate::error::SynthError;
use crate::scenario::{FieldChecker, Scenario};

/// Linear growth of the shaft force density with velocity.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VelocityDependentFriction {
    /// Relative growth of the density per m/s above the reference velocity
    /// (s/m); 60 means +6% per mm/s.
    pub slope: f64,
}

impl VelocityDependentFriction {
    /// The factor $1 + s (v - v_0)$ on the density at velocity `v`.
    pub fn factor(&self, velocity: f64, reference_velocity: f64) -> f64 {
        1.0 + self.slope * (velocity - reference_velocity)
    }
}

impl TruthEffect for VelocityDependentFriction {
    const ID: EffectId = EffectId::VelocityDependentFriction;

    fn check(&self, c: &FieldChecker<'_>, field: &str, s: &Scenario) -> Result<(), SynthError> {
        c.check(self.slope.is_finite(), &format!("{field}.slope"), || {
            format!("must be finite, got {:?}", self.slope)
        })?;
        for &v in &s.needles.velocities {
            let f = self.factor(v, s.shaft.reference_velocity);
            c.check(f > 0.0, &format!("{field}.slope"), || {
                format!("gives a non-positive density factor {f} at velocity {v}")
            })?;
        }
        Ok(())
    }
}
