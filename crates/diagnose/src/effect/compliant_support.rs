//! `compliant_support`: the fixed faces are held by a compliant clamp.

use super::{Effect, EffectParameter, Geometry, SupportSpec};

/// The fixed faces are held by springs of compliance $c$ per unit area
/// (stiffness $1/c$, N/m³) in both directions instead of rigidly; $c = 0$
/// is the rigid baseline.
pub struct CompliantSupport;

/// Young's modulus used only to give the compliance a natural scale (Pa).
const TYPICAL_MODULUS: f64 = 25.0e3;

impl Effect for CompliantSupport {
    fn id(&self) -> &'static str {
        "compliant_support"
    }

    fn physics(&self) -> &'static str {
        "the fixed face is held by a compliant clamp, not rigidly"
    }

    fn signature(&self) -> &'static str {
        "markers near the fixed face move in the data but not in the model; \
         reaction forces smaller than predicted"
    }

    fn parameters(&self, geometry: &Geometry) -> Vec<EffectParameter> {
        // A clamp as compliant as the slab itself over its depth.
        let scale = geometry.depth / TYPICAL_MODULUS;
        vec![EffectParameter {
            name: "support_compliance".into(),
            null: 0.0,
            initial: 0.1 * scale,
            scale,
            lower: Some(0.0),
            upper: Some(1.0e3 * scale),
            tested: true,
            meaning: "compliance of the fixed faces per unit area (m^3/N); 0 is rigid",
        }]
    }

    fn supports(&self, parameters: &[f64], supports: &mut SupportSpec) {
        supports.fixed_face_compliance = parameters[0];
    }
}
