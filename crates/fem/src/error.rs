//! Typed errors of the crate.
//!
//! Every way that bad input can enter (a material, a mesh, a load, a boundary
//! condition) has a variant that names the offending field or index, so that
//! a caller never sees a panic or a silent NaN.

use thiserror::Error;

/// Everything that can go wrong in `needle-fem`.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum FemError {
    /// Young's modulus must be positive and finite.
    #[error(
        "material of region {region}: Young's modulus must be positive and finite, got {value}"
    )]
    YoungsModulus {
        /// Region index of the material.
        region: usize,
        /// The rejected value.
        value: f64,
    },
    /// Poisson's ratio must lie in the open interval (-1, 0.5).
    #[error("material of region {region}: Poisson's ratio must lie in (-1, 0.5), got {value}")]
    PoissonRatio {
        /// Region index of the material.
        region: usize,
        /// The rejected value.
        value: f64,
    },
    /// A geometric or load quantity is NaN, infinite, or out of its range.
    #[error("invalid value for `{field}`: {value} ({reason})")]
    InvalidValue {
        /// Name of the field.
        field: &'static str,
        /// The rejected value.
        value: f64,
        /// Why it was rejected.
        reason: &'static str,
    },
    /// An element has a non-positive Jacobian determinant (inverted or
    /// degenerate).
    #[error(
        "element {element} is inverted or degenerate (Jacobian determinant {determinant:e} at a quadrature point)"
    )]
    DegenerateElement {
        /// Element index.
        element: usize,
        /// The offending determinant.
        determinant: f64,
    },
    /// A node index is outside the mesh.
    #[error("{context}: node index {node} out of range (mesh has {node_count} nodes)")]
    NodeOutOfRange {
        /// Where the index appeared.
        context: &'static str,
        /// The index.
        node: usize,
        /// Number of nodes in the mesh.
        node_count: usize,
    },
    /// A degree of freedom index is outside the system.
    #[error("{context}: dof index {dof} out of range (system has {dof_count} dofs)")]
    DofOutOfRange {
        /// Where the index appeared.
        context: &'static str,
        /// The index.
        dof: usize,
        /// Number of dofs.
        dof_count: usize,
    },
    /// An element refers to a material region that has no material.
    #[error("element {element} has region {region} but only {region_count} materials were given")]
    MissingMaterial {
        /// Element index.
        element: usize,
        /// Its region.
        region: usize,
        /// Number of materials supplied.
        region_count: usize,
    },
    /// Mesh data is inconsistent (lengths, element kind for the dimension, ...).
    #[error("invalid mesh: {0}")]
    InvalidMesh(String),
    /// A vector or matrix has the wrong length.
    #[error("{context}: expected length {expected}, got {actual}")]
    DimensionMismatch {
        /// What was being checked.
        context: &'static str,
        /// Expected length.
        expected: usize,
        /// Actual length.
        actual: usize,
    },
    /// The boundary conditions leave a rigid-body motion free, so the
    /// stiffness matrix is singular.
    #[error(
        "the system is singular: the boundary conditions leave {free_modes} rigid-body mode(s) unconstrained"
    )]
    Unconstrained {
        /// Number of rigid-body modes left free.
        free_modes: usize,
    },
    /// The sparse Cholesky factorisation failed (matrix not positive definite).
    #[error("Cholesky factorisation failed: {0}")]
    Factorization(String),
    /// A point lies outside the mesh.
    #[error("point {index} at {coordinates:?} lies outside the mesh")]
    PointOutsideMesh {
        /// Index of the point in the caller's list.
        index: usize,
        /// Its coordinates.
        coordinates: Vec<f64>,
    },
    /// A computation produced a non-finite value.
    #[error("non-finite value produced in {0}")]
    NonFinite(&'static str),
}

/// Checks that `value` is finite, naming `field` otherwise.
pub(crate) fn finite(field: &'static str, value: f64) -> Result<f64, FemError> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(FemError::InvalidValue {
            field,
            value,
            reason: "must be finite",
        })
    }
}

/// Checks that `value` is finite and strictly positive.
pub(crate) fn positive(field: &'static str, value: f64) -> Result<f64, FemError> {
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err(FemError::InvalidValue {
            field,
            value,
            reason: "must be positive and finite",
        })
    }
}
