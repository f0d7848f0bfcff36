//! The catalog of physical effects, each implemented as truth physics in its
//! own file and switched on per scenario.
//!
//! An effect is present when its field of [`Effects`] is `Some`; its
//! parameters are the true values written to the ground-truth file. Each
//! file documents the physics it stands for. The ids are those of
//! `docs/effects.md` and stay stable.

pub mod compliant_support;
pub mod layered_stiffness;
pub mod lens_distortion;
pub mod material_nonlinearity;
pub mod material_stiffening;
pub mod out_of_plane;
pub mod platform_friction;
pub mod tip_cutting_force;
pub mod velocity_dependent_friction;

use serde::{Deserialize, Serialize};

pub use compliant_support::CompliantSupport;
pub use layered_stiffness::LayeredStiffness;
pub use lens_distortion::LensDistortion;
pub use material_nonlinearity::MaterialNonlinearity;
pub use material_stiffening::MaterialStiffening;
pub use out_of_plane::OutOfPlane;
pub use platform_friction::PlatformFriction;
pub use tip_cutting_force::TipCuttingForce;
pub use velocity_dependent_friction::VelocityDependentFriction;

use crate::error::SynthError;
use crate::scenario::{FieldChecker, Scenario};

/// The stable id of an effect in the catalog.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EffectId {
    /// The slab is 3-D: markers on the top face, needle in the mid-plane.
    OutOfPlane,
    /// Shaft force density grows with insertion velocity.
    VelocityDependentFriction,
    /// Force peak just behind the needle tip.
    TipCuttingForce,
    /// Layers of different stiffness along the insertion direction.
    LayeredStiffness,
    /// Young's modulus grows over the days after casting.
    MaterialStiffening,
    /// The fixed face is held by an elastic clamp.
    CompliantSupport,
    /// The slab rubs on its platform (elastic foundation).
    PlatformFriction,
    /// Residual radial lens distortion of the tracked positions.
    LensDistortion,
    /// Neo-Hookean material at large strains.
    MaterialNonlinearity,
}

impl EffectId {
    /// Every effect of the catalog, in catalog order.
    pub const ALL: [EffectId; 9] = [
        EffectId::OutOfPlane,
        EffectId::VelocityDependentFriction,
        EffectId::TipCuttingForce,
        EffectId::LayeredStiffness,
        EffectId::MaterialStiffening,
        EffectId::CompliantSupport,
        EffectId::PlatformFriction,
        EffectId::LensDistortion,
        EffectId::MaterialNonlinearity,
    ];

    /// The id as written in files and on the command line.
    pub fn as_str(self) -> &'static str {
        match self {
            EffectId::OutOfPlane => "out_of_plane",
            EffectId::VelocityDependentFriction => "velocity_dependent_friction",
            EffectId::TipCuttingForce => "tip_cutting_force",
            EffectId::LayeredStiffness => "layered_stiffness",
            EffectId::MaterialStiffening => "material_stiffening",
            EffectId::CompliantSupport => "compliant_support",
            EffectId::PlatformFriction => "platform_friction",
            EffectId::LensDistortion => "lens_distortion",
            EffectId::MaterialNonlinearity => "material_nonlinearity",
        }
    }
}

/// What every effect's parameter set provides: its id and the check of its
/// values against the scenario.
pub trait TruthEffect {
    /// The catalog id.
    const ID: EffectId;

    /// Checks the parameters; `field` is the effect's dotted field path.
    fn check(
        &self,
        checker: &FieldChecker<'_>,
        field: &str,
        scenario: &Scenario,
    ) -> Result<(), SynthError>;
}

/// The effects present in a scenario (absent fields are off).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Effects {
    /// 3-D slab truth instead of the plane-strain one.
    #[serde(default)]
    pub out_of_plane: Option<OutOfPlane>,
    /// Velocity-dependent shaft force density.
    #[serde(default)]
    pub velocity_dependent_friction: Option<VelocityDependentFriction>,
    /// Cutting force peak behind the tip.
    #[serde(default)]
    pub tip_cutting_force: Option<TipCuttingForce>,
    /// Layered modulus.
    #[serde(default)]
    pub layered_stiffness: Option<LayeredStiffness>,
    /// Stiffening over days.
    #[serde(default)]
    pub material_stiffening: Option<MaterialStiffening>,
    /// Elastic clamp at the fixed face.
    #[serde(default)]
    pub compliant_support: Option<CompliantSupport>,
    /// Elastic foundation under the slab.
    #[serde(default)]
    pub platform_friction: Option<PlatformFriction>,
    /// Residual lens distortion of the tracks.
    #[serde(default)]
    pub lens_distortion: Option<LensDistortion>,
    /// Neo-Hookean material.
    #[serde(default)]
    pub material_nonlinearity: Option<MaterialNonlinearity>,
}

impl Effects {
    /// No effect at all: the null truth.
    pub fn none() -> Self {
        Self::default()
    }

    /// The ids of the effects present, in catalog order.
    pub fn present(&self) -> Vec<EffectId> {
        let on = [
            self.out_of_plane.is_some(),
            self.velocity_dependent_friction.is_some(),
            self.tip_cutting_force.is_some(),
            self.layered_stiffness.is_some(),
            self.material_stiffening.is_some(),
            self.compliant_support.is_some(),
            self.platform_friction.is_some(),
            self.lens_distortion.is_some(),
            self.material_nonlinearity.is_some(),
        ];
        EffectId::ALL
            .into_iter()
            .zip(on)
            .filter(|(_, on)| *on)
            .map(|(id, _)| id)
            .collect()
    }

    /// Checks the parameters of every present effect.
    pub(crate) fn validate(
        &self,
        c: &FieldChecker<'_>,
        scenario: &Scenario,
    ) -> Result<(), SynthError> {
        fn one<E: TruthEffect>(
            e: &Option<E>,
            c: &FieldChecker<'_>,
            s: &Scenario,
        ) -> Result<(), SynthError> {
            match e {
                Some(e) => e.check(c, &format!("effects.{}", E::ID.as_str()), s),
                None => Ok(()),
            }
        }
        one(&self.out_of_plane, c, scenario)?;
        one(&self.velocity_dependent_friction, c, scenario)?;
        one(&self.tip_cutting_force, c, scenario)?;
        one(&self.layered_stiffness, c, scenario)?;
        one(&self.material_stiffening, c, scenario)?;
        one(&self.compliant_support, c, scenario)?;
        one(&self.platform_friction, c, scenario)?;
        one(&self.lens_distortion, c, scenario)?;
        one(&self.material_nonlinearity, c, scenario)
    }
}
