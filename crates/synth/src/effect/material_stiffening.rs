//! `material_stiffening`: the phantom stiffens over the days after casting.
//!
//! Plasticizer leaks out of the PVC, so Young's modulus grows with time;
//! the paper measured about 6% between two tests several days apart. The
//! truth scales every modulus (all layers alike, Poisson's ratio unchanged)
//! on day $d$ by
//! $$E(d) = E(0)\,(1 + r\,d),$$
//! with the daily rate $r$ as parameter. Every trial, and the compression
//! test, sees the modulus of its own day.

use serde::{Deserialize, Serialize};

use super::{EffectId, TruthEffect};
use crate::error::SynthError;
use crate::scenario::{FieldChecker, Scenario};

/// Linear stiffening with time.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialStiffening {
    /// Relative growth of Young's modulus per day.
    pub rate_per_day: f64,
}

impl MaterialStiffening {
    /// The factor $1 + r d$ on the day-0 modulus.
    pub fn factor(&self, day: f64) -> f64 {
        1.0 + self.rate_per_day * day
    }
}

impl TruthEffect for MaterialStiffening {
    const ID: EffectId = EffectId::MaterialStiffening;

    fn check(&self, c: &FieldChecker<'_>, field: &str, _: &Scenario) -> Result<(), SynthError> {
        c.within(
            self.rate_per_day,
            -0.2,
            1.0,
            &format!("{field}.rate_per_day"),
        )
    }
}
