//! `lens_distortion`: an uncalibrated radial lens distortion in the tracks.

use super::{Effect, EffectParameter, Geometry};

/// The tracks were rectified with a wrong camera model: a true position
/// $p$ is reported at $p + \kappa (\rho/R)^2 (p - c)/R$, with $c$ the image
/// centre, $\rho = |p - c|$ and $R$ the image radius, so $\kappa$ is the
/// radial error at radius $R$ (third-order radial distortion).
pub struct LensDistortion;

impl Effect for LensDistortion {
    fn id(&self) -> &'static str {
        "lens_distortion"
    }

    fn physics(&self) -> &'static str {
        "the camera model used to rectify the tracks is wrong (uncalibrated radial distortion)"
    }

    fn signature(&self) -> &'static str {
        "residual field radial about the image centre, growing with radius"
    }

    fn acts_after_solves(&self) -> bool {
        true
    }

    fn parameters(&self, _geometry: &Geometry) -> Vec<EffectParameter> {
        vec![EffectParameter {
            name: "lens_radial_error".into(),
            null: 0.0,
            initial: 0.0,
            scale: 1.0e-4,
            lower: None,
            upper: None,
            tested: true,
            meaning: "radial position error at the image radius, positive outwards (m)",
        }]
    }

    fn measured_position(
        &self,
        parameters: &[f64],
        geometry: &Geometry,
        position: [f64; 2],
    ) -> [f64; 2] {
        let radius = geometry.image_radius;
        let d = [
            position[0] - geometry.image_centre[0],
            position[1] - geometry.image_centre[1],
        ];
        let rho2 = (d[0] * d[0] + d[1] * d[1]) / (radius * radius);
        let gain = parameters[0] * rho2 / radius;
        [position[0] + gain * d[0], position[1] + gain * d[1]]
    }
}
