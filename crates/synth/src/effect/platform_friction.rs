//! `platform_friction`: the slab rubs on the platform it lies on.
//!
//! Sticking friction between the bottom face and the platform acts as an
//! elastic foundation: a restoring traction $t = -k_f\,(u_x, u_y)$ per unit
//! area of the bottom face, in the plane only. In 3-D it acts on the
//! bottom face $z = -t/2$; in the plane model it acts over the whole plan
//! (each triangle's area). Its stiffness matrix is
//! $k_f \int N_a N_b\,dA$ for $u_x$ and $u_y$. Displacements then decay
//! faster with distance from the tool than a model without it predicts,
//! and part of the tool force goes into the platform instead of the back
//! face.

use serde::{Deserialize, Serialize};

use super::{EffectId, TruthEffect};
use crate::body::Body;
use crate::error::SynthError;
use crate::scenario::{FieldChecker, Scenario};

/// Elastic foundation under the slab.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlatformFriction {
    /// Foundation stiffness per unit area (Pa/m).
    pub stiffness: f64,
}

impl PlatformFriction {
    /// Spring triplets of the foundation.
    pub(crate) fn springs(&self, body: &Body) -> Vec<(usize, usize, f64)> {
        let components = [(0, self.stiffness), (1, self.stiffness)];
        if body.dim == 3 {
            let bottom = -0.5 * body.thickness;
            let tol = 1e-9 * body.thickness;
            let facets = body.boundary_facets_where(|x| (x[2] - bottom).abs() < tol);
            body.distributed_springs(&facets, 2, 1.0, &components)
        } else {
            body.distributed_springs(&body.element_patches(), 2, 1.0, &components)
        }
    }
}

impl TruthEffect for PlatformFriction {
    const ID: EffectId = EffectId::PlatformFriction;

    fn check(&self, c: &FieldChecker<'_>, field: &str, _: &Scenario) -> Result<(), SynthError> {
        c.positive(self.stiffness, &format!("{field}.stiffness"))
    }
}
