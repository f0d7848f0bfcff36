//! `out_of_plane`: the slab is thin but three-dimensional.
//!
//! With this effect the truth is a 3-D slab of quadratic tetrahedra with
//! several element layers through the thickness $t$ (z from $-t/2$ to
//! $t/2$). The needle load acts on the mid-plane $z = 0$, the probe presses
//! the whole thickness of the front face, and the markers are read on the
//! top face $z = t/2$, where the displacement field is smaller and smoother
//! than in the mid-plane. A plane model that fits these markers misreads the
//! shaft forces (the paper: about 26% too low, with a spurious force at the
//! entry node). Without it the truth is a plane-strain model of the same
//! slab, whose stiffness and loads are totals over the thickness.

use serde::{Deserialize, Serialize};

use super::{EffectId, TruthEffect};
use crate::error::SynthError;
use crate::scenario::{FieldChecker, Scenario};

/// The 3-D slab truth; the number of element layers is
/// [`crate::scenario::Resolution::layers`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct OutOfPlane;

impl TruthEffect for OutOfPlane {
    const ID: EffectId = EffectId::OutOfPlane;

    fn check(&self, _: &FieldChecker<'_>, _: &str, _: &Scenario) -> Result<(), SynthError> {
        Ok(())
    }
}
