//! `compliant_support`: the fixed face is held by a compliant clamp.
//!
//! Instead of a rigid back face ($u = 0$ on $y = d$), the back face rests
//! on a distributed elastic support with stiffness per unit area $k_n$
//! normal to the face (y) and $k_t$ along it (x, and z in 3-D):
//! traction $t = -\mathrm{diag}(k_t, k_n, k_t)\,u$. Its stiffness matrix is
//! $k \int_{\Gamma} N_a N_b\,dA$ per component, integrated exactly over the
//! back-face facets (times the thickness for the plane model, whose
//! boundary integrals are per unit thickness). The markers near the back
//! face then move, and the reactions are smaller than a rigid model
//! predicts.

use serde::{Deserialize, Serialize};

use super::{EffectId, TruthEffect};
use crate::body::Body;
use crate::error::SynthError;
use crate::scenario::{FieldChecker, Scenario};

/// Elastic clamp of the back face.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CompliantSupport {
    /// Stiffness per unit area normal to the face (Pa/m).
    pub normal: f64,
    /// Stiffness per unit area along the face (Pa/m).
    pub tangential: f64,
}

impl CompliantSupport {
    /// Spring triplets over the facets whose nodes all satisfy `on_face`.
    pub(crate) fn springs(
        &self,
        body: &Body,
        on_face: impl Fn([f64; 3]) -> bool,
    ) -> Vec<(usize, usize, f64)> {
        let facets = body.boundary_facets_where(on_face);
        let mut components = vec![(0, self.tangential), (1, self.normal)];
        if body.dim == 3 {
            components.push((2, self.tangential));
        }
        body.distributed_springs(&facets, body.dim - 1, body.plane_factor(), &components)
    }
}

impl TruthEffect for CompliantSupport {
    const ID: EffectId = EffectId::CompliantSupport;

    fn check(&self, c: &FieldChecker<'_>, field: &str, _: &Scenario) -> Result<(), SynthError> {
        c.positive(self.normal, &format!("{field}.normal"))?;
        c.positive(self.tangential, &format!("{field}.tangential"))
    }
}
