//! Elastic supports: distributed springs that add
//! $K_s = \sum \int k_i\, N_a N_b \, dA$ to the $(a, i), (b, i)$ entries of
//! the stiffness matrix (consistent with the element's shape functions).
//!
//! - [`Support::Boundary`]: springs on boundary facets (edges in 2-D, faces
//!   in 3-D), stiffness per unit area of the facet (N/m³); in 2-D the edge
//!   length is multiplied by the thickness. E.g. a back face that is glued
//!   but compliant, or, in 3-D, the platform under the bottom face.
//! - [`Support::Foundation`]: springs over the whole in-plane area of a
//!   2-D mesh (N/m³ per unit area of the plane), e.g. friction with the
//!   platform of a thin phantom. Not defined for 3-D meshes (use a
//!   boundary support on [`crate::mesh::Face::Bottom`]).
//!
//! Springs act per axis: `stiffness[i]` resists displacement along axis `i`.

use faer::sparse::SparseColMat;

use crate::assemble::StiffnessPattern;
use crate::element::facet::simplex_mass;
use crate::error::{FemError, finite};
use crate::load::pad;
use crate::material::Formulation;
use crate::mesh::{BoundaryFacet, Mesh};

/// A distributed elastic support.
#[derive(Debug, Clone, PartialEq)]
pub enum Support<const D: usize> {
    /// Springs on boundary facets, per unit facet area (N/m³), per axis.
    Boundary {
        /// The supported facets.
        facets: Vec<BoundaryFacet>,
        /// Spring stiffness per unit area along each axis.
        stiffness: [f64; D],
    },
    /// Springs over the whole area of a 2-D mesh (N/m³), per axis.
    Foundation {
        /// Spring stiffness per unit area along each axis.
        stiffness: [f64; D],
    },
}

impl<const D: usize> Support<D> {
    fn stiffness(&self) -> &[f64; D] {
        match self {
            Support::Boundary { stiffness, .. } | Support::Foundation { stiffness } => stiffness,
        }
    }

    /// Checks stiffness values (finite, non-negative) and applicability.
    pub fn validate(&self, mesh: &Mesh<D>) -> Result<(), FemError> {
        for &k in self.stiffness() {
            finite("support stiffness", k)?;
            if k < 0.0 {
                return Err(FemError::InvalidValue {
                    field: "support stiffness",
                    value: k,
                    reason: "must be non-negative",
                });
            }
        }
        match self {
            Support::Foundation { .. } if D != 2 => Err(FemError::InvalidMesh(
                "a foundation applies to 2-D meshes; support a 3-D slab on its bottom face".into(),
            )),
            Support::Boundary { facets, .. } => {
                for facet in facets {
                    if let Some(&node) = facet.nodes.iter().find(|&&n| n >= mesh.node_count()) {
                        return Err(FemError::NodeOutOfRange {
                            context: "support facet",
                            node,
                            node_count: mesh.node_count(),
                        });
                    }
                }
                Ok(())
            }
            Support::Foundation { .. } => Ok(()),
        }
    }

    /// Adds the spring matrix to `matrix` (which must have `pattern`).
    pub fn add_to(
        &self,
        mesh: &Mesh<D>,
        formulation: Formulation,
        pattern: &StiffnessPattern,
        matrix: &mut SparseColMat<usize, f64>,
    ) -> Result<(), FemError> {
        self.validate(mesh)?;
        let values = matrix.val_mut();
        let mut add = |nodes: &[usize], param_dim: usize, scale: f64| -> Result<(), FemError> {
            let coordinates: Vec<[f64; 3]> = nodes.iter().map(|&n| pad(mesh.node(n))).collect();
            let mass = simplex_mass(&coordinates, param_dim, mesh.kind().degree());
            let m = nodes.len();
            for (b, &col) in nodes.iter().enumerate() {
                for (a, &row) in nodes.iter().enumerate() {
                    for i in 0..D {
                        let position = pattern.position(row, i, col, i).ok_or_else(|| {
                            FemError::InvalidMesh(format!(
                                "support nodes {row} and {col} share no element"
                            ))
                        })?;
                        values[position] += scale * self.stiffness()[i] * mass[a * m + b];
                    }
                }
            }
            Ok(())
        };
        match self {
            Support::Boundary { facets, .. } => {
                for facet in facets {
                    add(&facet.nodes, D - 1, formulation.thickness())?;
                }
            }
            Support::Foundation { .. } => {
                for e in 0..mesh.element_count() {
                    add(mesh.element(e), D, 1.0)?;
                }
            }
        }
        Ok(())
    }
}
