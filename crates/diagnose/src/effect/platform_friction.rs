//! `platform_friction`: the slab rubs on its platform.
//!
//! Added as the proof of `docs/adding-an-effect.md`: this file plus one
//! line in `CATALOG`, nothing else.

use super::{Effect, EffectParameter, Geometry, SupportSpec};

/// A distributed restoring force $-k_f u$ per unit area of the plane
/// (a foundation of stiffness $k_f$, N/m³); $k_f = 0$ is the baseline.
pub struct PlatformFriction;

/// Young's modulus used only to give the stiffness a natural scale (Pa).
const TYPICAL_MODULUS: f64 = 25.0e3;

impl Effect for PlatformFriction {
    fn id(&self) -> &'static str {
        "platform_friction"
    }

    fn physics(&self) -> &'static str {
        "the slab rubs on its platform, a distributed restoring force"
    }

    fn signature(&self) -> &'static str {
        "measured displacements decay faster with distance from the tool than the model's"
    }

    fn parameters(&self, geometry: &Geometry) -> Vec<EffectParameter> {
        // The in-plane stiffness of the slab per unit area, E t / L^2.
        let scale = TYPICAL_MODULUS * geometry.thickness / (geometry.depth * geometry.depth);
        vec![EffectParameter {
            name: "foundation_stiffness".into(),
            null: 0.0,
            initial: 0.0,
            scale,
            lower: Some(0.0),
            upper: Some(1.0e3 * scale),
            tested: true,
            meaning: "restoring force per unit area of the plane per unit displacement (N/m^3)",
        }]
    }

    fn supports(&self, parameters: &[f64], supports: &mut SupportSpec) {
        supports.foundation = parameters[0];
    }
}
