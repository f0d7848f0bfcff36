//! Physical effects: the open catalog of what the baseline model may miss.
//!
//! An effect adds named parameters to the model and changes one part of the
//! forward model through one of the hooks of [`Effect`] (all default to "no
//! change"): the material field ([`Effect::stiffness_factor`]), the supports
//! ([`Effect::supports`]), the needle load ([`Effect::shaft_density`] added,
//! [`Effect::shaft_density_factor`] multiplying), the
//! kinematics, plane or slab ([`Effect::slab_weight`]), the constitutive
//! law, linear or neo-Hookean ([`Effect::nonlinear_weight`]), or the
//! measurement map ([`Effect::measured_position`]). An effect may also
//! say that a parameter acts only as the baseline's shaft density or
//! Young's modulus would ([`Effect::chain`]), which spares the fits a
//! solve per Jacobian. Every effect has *null*
//! parameter values at which it changes nothing: the score test of
//! the ranking (module `rank`) evaluates the gradient there.
//!
//! To add an effect: write one file in this folder implementing [`Effect`]
//! and add one line to [`CATALOG`] (see `docs/adding-an-effect.md`).

mod compliant_support;
mod layered_stiffness;
mod lens_distortion;
mod material_nonlinearity;
mod material_stiffening;
mod out_of_plane;
mod platform_friction;
mod tip_cutting_force;
mod velocity_dependent_friction;

use needle_data::TrialKind;

/// The catalog: one constructor per effect, in the order they are listed.
pub const CATALOG: &[fn() -> Box<dyn Effect>] = &[
    || Box::new(tip_cutting_force::TipCuttingForce),
    || Box::new(velocity_dependent_friction::VelocityDependentFriction),
    || Box::new(material_stiffening::MaterialStiffening),
    || Box::new(compliant_support::CompliantSupport),
    || Box::new(platform_friction::PlatformFriction),
    || Box::new(lens_distortion::LensDistortion),
    || Box::new(layered_stiffness::LayeredStiffness),
    || Box::new(out_of_plane::OutOfPlane),
    || Box::new(material_nonlinearity::MaterialNonlinearity),
];

/// Every effect of the catalog.
pub fn catalog() -> Vec<Box<dyn Effect>> {
    CATALOG.iter().map(|make| make()).collect()
}

/// The effect with this id, if the catalog has it.
pub fn lookup(id: &str) -> Option<Box<dyn Effect>> {
    catalog().into_iter().find(|effect| effect.id() == id)
}

/// The phantom as the effects see it (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geometry {
    /// Extent along x.
    pub width: f64,
    /// Extent along y (insertion direction).
    pub depth: f64,
    /// Extent along z.
    pub thickness: f64,
    /// Centre of the marker field, the assumed image centre.
    pub image_centre: [f64; 2],
    /// Largest distance of a marker from `image_centre`.
    pub image_radius: f64,
}

/// What an effect may know about a trial.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrialContext {
    /// Probe, needle or compression.
    pub kind: TrialKind,
    /// Commanded tool speed (m/s).
    pub velocity: f64,
    /// Days since casting.
    pub day: f64,
}

/// The supports of the slab that effects may change. The baseline holds the
/// manifest's fixed faces rigidly and has no foundation.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SupportSpec {
    /// Compliance of the fixed faces per unit area (m³/N): 0 is rigid
    /// (Dirichlet), a positive value replaces the constraint by springs of
    /// stiffness `1 / compliance` in both directions.
    pub fixed_face_compliance: f64,
    /// Foundation stiffness over the plane (N/m³), both directions.
    pub foundation: f64,
}

/// One parameter an effect adds.
#[derive(Debug, Clone, PartialEq)]
pub struct EffectParameter {
    /// Name, unique in a model (prefix it with something of the effect).
    pub name: String,
    /// Value at which the effect changes nothing.
    pub null: f64,
    /// Where a fit with the effect starts.
    pub initial: f64,
    /// Typical magnitude (finite-difference steps, units of the search).
    pub scale: f64,
    /// Lower bound.
    pub lower: Option<f64>,
    /// Upper bound.
    pub upper: Option<f64>,
    /// Whether the score test tests it. A shape parameter that matters only
    /// when another parameter is off its null (the width of a peak whose
    /// excess is zero) is held at `initial` in the score test instead.
    pub tested: bool,
    /// What it means, with its unit.
    pub meaning: &'static str,
}

/// Where a point of the shaft is: arclength from the entry point and the
/// inserted length (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShaftPoint {
    /// Arclength from the entry point, `0 <= s <= length`.
    pub s: f64,
    /// Inserted length (entry point to tip).
    pub length: f64,
}

/// How a parameter acts on a trial when it acts only as one of the
/// baseline's would ([`Effect::chain`]). The derivative of every
/// prediction of the trial in the parameter $\theta$ is then a multiple of
/// the derivative in that baseline parameter (chain rule).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Chain {
    /// Adds $\rho\,\theta$ to the trial's shaft density uniformly along
    /// the shaft, before the effects' factors, as the baseline's $q_0$ is
    /// added: $\partial/\partial\theta = \rho\,\partial/\partial q_0$.
    ShaftDensity(f64),
    /// Multiplies the modulus of every element in the trial by a factor
    /// $c(\theta)$ with $\partial \ln c / \partial\theta = \rho$, as a
    /// change of the baseline's $E$ would:
    /// $\partial/\partial\theta = \rho\,E\,\partial/\partial E$.
    Stiffness(f64),
}

/// A physical effect the model may include. Parameters arrive as the slice
/// of this effect's own values, in the order of [`Effect::parameters`].
pub trait Effect: Send + Sync {
    /// Stable id used in model files, on the command line and in reports.
    fn id(&self) -> &'static str;

    /// The physics the effect stands for.
    fn physics(&self) -> &'static str;

    /// What its absence does to the residuals.
    fn signature(&self) -> &'static str;

    /// The parameters it adds.
    fn parameters(&self, geometry: &Geometry) -> Vec<EffectParameter>;

    /// Factor multiplying the baseline Young's modulus of the element with
    /// centroid `centroid`, element extent in y `[y_min, y_max]`, in `trial`.
    fn stiffness_factor(
        &self,
        parameters: &[f64],
        trial: &TrialContext,
        centroid: [f64; 2],
        y_extent: [f64; 2],
    ) -> f64 {
        let _ = (parameters, trial, centroid, y_extent);
        1.0
    }

    /// Changes the supports.
    fn supports(&self, parameters: &[f64], supports: &mut SupportSpec) {
        let _ = (parameters, supports);
    }

    /// Shaft force density (N/m) added to the baseline's uniform density
    /// at a point of the needle, along the needle axis.
    fn shaft_density(&self, parameters: &[f64], trial: &TrialContext, point: ShaftPoint) -> f64 {
        let _ = (parameters, trial, point);
        0.0
    }

    /// Factor multiplying the whole shaft force density (the baseline's
    /// plus every effect's added density) at a point of the needle: for a
    /// change relative to the local friction, which grows with it when
    /// another effect makes the friction grow (e.g. with speed).
    fn shaft_density_factor(
        &self,
        parameters: &[f64],
        trial: &TrialContext,
        point: ShaftPoint,
    ) -> f64 {
        let _ = (parameters, trial, point);
        1.0
    }

    /// Arclengths where [`Effect::shaft_density`] or
    /// [`Effect::shaft_density_factor`] kinks or jumps, for quadrature.
    fn shaft_breakpoints(&self, parameters: &[f64], length: f64) -> Vec<f64> {
        let _ = (parameters, length);
        Vec::new()
    }

    /// Weight of the 3-D slab body in the predicted marker displacements
    /// (the kinematics; the plane body gets one minus the sum over effects).
    fn slab_weight(&self, parameters: &[f64]) -> f64 {
        let _ = parameters;
        0.0
    }

    /// Weight of the neo-Hookean terms of the displacement (the
    /// constitutive law): the prediction is $u_1 + w\,(u_2 + u_3)$ with $w$
    /// the sum over effects (see `material_nonlinearity`).
    fn nonlinear_weight(&self, parameters: &[f64]) -> f64 {
        let _ = parameters;
        0.0
    }

    /// Whether the effect acts only on what is done with the bodies'
    /// solutions, the blend of the plane and slab predictions
    /// ([`Effect::slab_weight`]) or the measurement map
    /// ([`Effect::measured_position`]), and on nothing the solves take:
    /// no stiffness factor, supports, shaft density or neo-Hookean weight.
    /// The finite-difference columns of its parameters then take the base
    /// point's solutions instead of solving again. `false`, the default,
    /// is always right, only slower; a unit test checks the catalog's
    /// claims.
    fn acts_after_solves(&self) -> bool {
        false
    }

    /// How parameter `index` acts on `trial`, if it acts only as the
    /// [`Chain`] says and through no other hook: the fits then take its
    /// Jacobian column from the baseline parameter's instead of solving
    /// the model again. `None`, the default, is always right, only slower;
    /// a unit test checks the catalog's claims.
    fn chain(&self, parameters: &[f64], index: usize, trial: &TrialContext) -> Option<Chain> {
        let _ = (parameters, index, trial);
        None
    }

    /// Maps a true marker position on the top face to what the measurement
    /// reports (e.g. through an uncalibrated lens).
    fn measured_position(
        &self,
        parameters: &[f64],
        geometry: &Geometry,
        position: [f64; 2],
    ) -> [f64; 2] {
        let _ = (parameters, geometry);
        position
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The paper's phantom with its 21 x 21 marker field.
    fn paper_geometry() -> Geometry {
        Geometry {
            width: 0.075,
            depth: 0.075,
            thickness: 0.0075,
            image_centre: [0.0375, 0.0375],
            image_radius: 0.04,
        }
    }

    #[test]
    fn catalog_ids_are_unique_and_parameters_valid() {
        let geometry = paper_geometry();
        let effects = catalog();
        for (i, a) in effects.iter().enumerate() {
            for b in &effects[i + 1..] {
                assert_ne!(a.id(), b.id());
            }
            let parameters = a.parameters(&geometry);
            assert!(!parameters.is_empty(), "{}", a.id());
            assert!(parameters.iter().any(|p| p.tested), "{}", a.id());
            for p in &parameters {
                assert!(p.scale > 0.0);
                for v in [p.null, p.initial] {
                    assert!(p.lower.is_none_or(|l| v >= l), "{} {}", a.id(), p.name);
                    assert!(p.upper.is_none_or(|u| v <= u), "{} {}", a.id(), p.name);
                }
            }
            assert_eq!(lookup(a.id()).map(|e| e.id()), Some(a.id()));
        }
        assert!(lookup("no_such_effect").is_none());
    }

    #[test]
    fn effects_that_act_after_the_solves_leave_everything_the_solves_take() {
        let geometry = paper_geometry();
        let after: Vec<_> = catalog()
            .into_iter()
            .filter(|e| e.acts_after_solves())
            .collect();
        let ids: Vec<_> = after.iter().map(|e| e.id()).collect();
        assert_eq!(ids, ["lens_distortion", "out_of_plane"]);
        for effect in &after {
            let specs = effect.parameters(&geometry);
            for multiple in [0.0, 0.3, 1.0, 2.5] {
                let p: Vec<f64> = specs
                    .iter()
                    .map(|s| {
                        let v = s.initial + multiple * s.scale;
                        v.clamp(s.lower.unwrap_or(v), s.upper.unwrap_or(v))
                    })
                    .collect();
                for (kind, velocity, day) in [
                    (TrialKind::Probe, 0.002, 0.0),
                    (TrialKind::Needle, 0.009, 3.0),
                ] {
                    let trial = TrialContext {
                        kind,
                        velocity,
                        day,
                    };
                    for centroid in [[0.01, 0.02], [0.05, 0.07]] {
                        let y = [centroid[1] - 0.001, centroid[1] + 0.001];
                        assert_eq!(effect.stiffness_factor(&p, &trial, centroid, y), 1.0);
                    }
                    for (s, length) in [(0.0, 0.03), (0.01, 0.03), (0.049, 0.05)] {
                        let point = ShaftPoint { s, length };
                        assert_eq!(effect.shaft_density(&p, &trial, point), 0.0);
                        assert_eq!(effect.shaft_density_factor(&p, &trial, point), 1.0);
                    }
                }
                let mut supports = SupportSpec::default();
                effect.supports(&p, &mut supports);
                assert_eq!(supports, SupportSpec::default(), "{}", effect.id());
                assert!(effect.shaft_breakpoints(&p, 0.05).is_empty());
                assert_eq!(effect.nonlinear_weight(&p), 0.0, "{}", effect.id());
            }
        }
    }
}
