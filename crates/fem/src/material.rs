//! Isotropic linear elastic materials and their constitutive matrices.
//!
//! With Lamé parameters
//! $\lambda = \frac{E\nu}{(1+\nu)(1-2\nu)}$ and $\mu = \frac{E}{2(1+\nu)}$,
//! stresses and engineering strains in Voigt order
//! ($\varepsilon = [\varepsilon_{xx}, \varepsilon_{yy}, \gamma_{xy}]$ in 2-D,
//! $[\varepsilon_{xx}, \varepsilon_{yy}, \varepsilon_{zz}, \gamma_{yz}, \gamma_{xz}, \gamma_{xy}]$ in 3-D)
//! are related by $\sigma = D\varepsilon$ with
//!
//! - 3-D: $D = \lambda\, m m^T + \mu\,\mathrm{diag}(2,2,2,1,1,1)$, $m = (1,1,1,0,0,0)^T$;
//! - plane strain: $D = \begin{bmatrix}\lambda+2\mu & \lambda & 0\\ \lambda & \lambda+2\mu & 0\\ 0&0&\mu\end{bmatrix}$;
//! - plane stress: the same with $\lambda$ replaced by $\lambda^* = \frac{2\lambda\mu}{\lambda+2\mu} = \frac{E\nu}{1-\nu^2}$.
//!
//! $D$ is linear in $E$, so $\partial D/\partial E = D/E$; $\partial D/\partial\nu$
//! follows from $\partial\lambda/\partial\nu = \frac{E(1+2\nu^2)}{(1+\nu)^2(1-2\nu)^2}$,
//! $\partial\mu/\partial\nu = -\frac{E}{2(1+\nu)^2}$ and
//! $\partial\lambda^*/\partial\nu = \frac{E(1+\nu^2)}{(1-\nu^2)^2}$.

use nalgebra::{Matrix3, Matrix6};
use serde::{Deserialize, Serialize};

use crate::error::{FemError, positive};

/// An isotropic linear elastic material: Young's modulus $E$ (Pa) and
/// Poisson's ratio $\nu$. Construct with [`Material::new`], which validates.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Material {
    youngs_modulus: f64,
    poisson_ratio: f64,
}

/// Which material parameter a derivative is taken with respect to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Parameter {
    /// Young's modulus $E$.
    YoungsModulus,
    /// Poisson's ratio $\nu$.
    PoissonRatio,
}

/// How a 2-D mesh represents the 3-D body, or that the mesh is 3-D.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Formulation {
    /// Plane strain ($\varepsilon_{zz} = 0$) of a slab of the given
    /// out-of-plane thickness (m); stiffness and loads are totals over the
    /// thickness, so forces are in N.
    PlaneStrain {
        /// Out-of-plane thickness (m).
        thickness: f64,
    },
    /// Plane stress ($\sigma_{zz} = 0$) of a plate of the given thickness (m).
    PlaneStress {
        /// Out-of-plane thickness (m).
        thickness: f64,
    },
    /// Full 3-D elasticity (3-D meshes only).
    Solid,
}

impl Formulation {
    /// Spatial dimension the formulation applies to (2 or 3).
    pub fn dimension(&self) -> usize {
        match self {
            Formulation::Solid => 3,
            _ => 2,
        }
    }

    /// Out-of-plane thickness multiplying 2-D integrals (1 for 3-D).
    pub fn thickness(&self) -> f64 {
        match *self {
            Formulation::PlaneStrain { thickness } | Formulation::PlaneStress { thickness } => {
                thickness
            }
            Formulation::Solid => 1.0,
        }
    }

    pub(crate) fn validate(&self) -> Result<(), FemError> {
        match *self {
            Formulation::PlaneStrain { thickness } | Formulation::PlaneStress { thickness } => {
                positive("formulation.thickness", thickness).map(|_| ())
            }
            Formulation::Solid => Ok(()),
        }
    }
}

/// A constitutive matrix in Voigt notation, 3x3 (2-D) or 6x6 (3-D).
// A small value type copied per region; boxing the 6x6 variant would cost
// an allocation for no gain.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Constitutive {
    /// 2-D (plane strain or plane stress), strains $[\varepsilon_{xx}, \varepsilon_{yy}, \gamma_{xy}]$.
    Plane(Matrix3<f64>),
    /// 3-D, strains $[\varepsilon_{xx}, \varepsilon_{yy}, \varepsilon_{zz}, \gamma_{yz}, \gamma_{xz}, \gamma_{xy}]$.
    Solid(Matrix6<f64>),
}

impl Material {
    /// A validated material: `E` positive and finite, `nu` in (-1, 0.5).
    /// `region` only labels the error.
    pub fn new(youngs_modulus: f64, poisson_ratio: f64) -> Result<Self, FemError> {
        Self::for_region(0, youngs_modulus, poisson_ratio)
    }

    /// As [`Material::new`], naming `region` in the error.
    pub fn for_region(
        region: usize,
        youngs_modulus: f64,
        poisson_ratio: f64,
    ) -> Result<Self, FemError> {
        if !(youngs_modulus.is_finite() && youngs_modulus > 0.0) {
            return Err(FemError::YoungsModulus {
                region,
                value: youngs_modulus,
            });
        }
        if !(poisson_ratio.is_finite() && poisson_ratio > -1.0 && poisson_ratio < 0.5) {
            return Err(FemError::PoissonRatio {
                region,
                value: poisson_ratio,
            });
        }
        Ok(Self {
            youngs_modulus,
            poisson_ratio,
        })
    }

    /// Young's modulus $E$ (Pa).
    pub fn youngs_modulus(&self) -> f64 {
        self.youngs_modulus
    }

    /// Poisson's ratio $\nu$.
    pub fn poisson_ratio(&self) -> f64 {
        self.poisson_ratio
    }

    /// Lamé's first parameter $\lambda$.
    pub fn lame_lambda(&self) -> f64 {
        let (e, nu) = (self.youngs_modulus, self.poisson_ratio);
        e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    }

    /// Shear modulus $\mu$.
    pub fn shear_modulus(&self) -> f64 {
        self.youngs_modulus / (2.0 * (1.0 + self.poisson_ratio))
    }

    /// The constitutive matrix $D$ for `formulation`.
    pub fn constitutive(&self, formulation: Formulation) -> Constitutive {
        let (a, mu) = self.lame_coefficients(formulation);
        build(formulation, a, mu, a)
    }

    /// The coefficients $(a, \mu)$ with $D = a\,D_\lambda + \mu\,D_\mu$
    /// (see [`lame_basis`]): $a = \lambda$, or in plane stress
    /// $2\lambda\mu/(\lambda + 2\mu)$.
    pub(crate) fn lame_coefficients(&self, formulation: Formulation) -> (f64, f64) {
        let (lambda, mu) = (self.lame_lambda(), self.shear_modulus());
        match formulation {
            Formulation::PlaneStress { .. } => (2.0 * lambda * mu / (lambda + 2.0 * mu), mu),
            _ => (lambda, mu),
        }
    }

    /// The derivative $\partial D/\partial p$ of the constitutive matrix.
    pub fn constitutive_derivative(
        &self,
        formulation: Formulation,
        parameter: Parameter,
    ) -> Constitutive {
        let (e, nu) = (self.youngs_modulus, self.poisson_ratio);
        match parameter {
            Parameter::YoungsModulus => {
                let unit = Material {
                    youngs_modulus: 1.0,
                    poisson_ratio: nu,
                };
                unit.constitutive(formulation)
            }
            Parameter::PoissonRatio => {
                let d_lambda = e * (1.0 + 2.0 * nu * nu) / ((1.0 + nu) * (1.0 - 2.0 * nu)).powi(2);
                let d_mu = -e / (2.0 * (1.0 + nu).powi(2));
                let d_plane_stress_lambda = e * (1.0 + nu * nu) / (1.0 - nu * nu).powi(2);
                build(formulation, d_lambda, d_mu, d_plane_stress_lambda)
            }
        }
    }
}

/// The constitutive matrices $[D_\lambda, D_\mu]$ of which every
/// isotropic $D$ of `formulation` is the combination
/// $a\,D_\lambda + \mu\,D_\mu$.
pub(crate) fn lame_basis(formulation: Formulation) -> [Constitutive; 2] {
    [
        build(formulation, 1.0, 0.0, 1.0),
        build(formulation, 0.0, 1.0, 0.0),
    ]
}

/// Assembles $D$ (or its derivative, which has the same structure) from
/// $\lambda$, $\mu$ and $\lambda^*$ (or their derivatives).
fn build(formulation: Formulation, lambda: f64, mu: f64, plane_stress_lambda: f64) -> Constitutive {
    match formulation {
        Formulation::PlaneStrain { .. } => Constitutive::Plane(plane(lambda, mu)),
        Formulation::PlaneStress { .. } => Constitutive::Plane(plane(plane_stress_lambda, mu)),
        Formulation::Solid => {
            let mut d = Matrix6::zeros();
            for i in 0..3 {
                for j in 0..3 {
                    d[(i, j)] = lambda;
                }
                d[(i, i)] += 2.0 * mu;
                d[(i + 3, i + 3)] = mu;
            }
            Constitutive::Solid(d)
        }
    }
}

fn plane(lambda: f64, mu: f64) -> Matrix3<f64> {
    Matrix3::new(
        lambda + 2.0 * mu,
        lambda,
        0.0,
        lambda,
        lambda + 2.0 * mu,
        0.0,
        0.0,
        0.0,
        mu,
    )
}

/// Materials indexed by region id: element with region `r` uses `materials[r]`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Materials(pub Vec<Material>);

impl Materials {
    /// One material for every element (all regions 0).
    pub fn homogeneous(material: Material) -> Self {
        Self(vec![material])
    }

    /// Validated materials from `(E, nu)` pairs, one per region.
    pub fn from_parameters(parameters: &[(f64, f64)]) -> Result<Self, FemError> {
        parameters
            .iter()
            .enumerate()
            .map(|(region, &(e, nu))| Material::for_region(region, e, nu))
            .collect::<Result<Vec<_>, _>>()
            .map(Self)
    }

    /// Number of regions with a material.
    pub fn len(&self) -> usize {
        self.0.len()
    }

    /// True if there is no material.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// Material of `region`, if any.
    pub fn get(&self, region: usize) -> Option<&Material> {
        self.0.get(region)
    }
}
