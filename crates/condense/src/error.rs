//! The one error type of the crate: every bad input is named, never a panic.

/// Errors returned by the condensed solver.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum CondenseError {
    /// The stiffness matrix is not square.
    #[error("stiffness matrix is {rows}x{cols}, expected a square matrix")]
    NotSquare {
        /// Rows of the given matrix.
        rows: usize,
        /// Columns of the given matrix.
        cols: usize,
    },
    /// Nodes must carry 2 (planar) or 3 (spatial) dofs.
    #[error("dofs_per_node must be 2 or 3, got {0}")]
    Dimension(usize),
    /// The matrix size is not a whole number of nodes.
    #[error("stiffness matrix has {dofs} rows, not a multiple of dofs_per_node = {dofs_per_node}")]
    Layout {
        /// Rows of the matrix.
        dofs: usize,
        /// Dofs per node.
        dofs_per_node: usize,
    },
    /// A fixed dof index is outside the matrix.
    #[error("fixed dof {dof} is out of range (the model has {n_dofs} dofs)")]
    FixedDofOutOfRange {
        /// The offending dof.
        dof: usize,
        /// Number of dofs of the model.
        n_dofs: usize,
    },
    /// Every dof is fixed: there is nothing to solve.
    #[error("every dof of the model is fixed")]
    NothingFree,
    /// The sparse Cholesky factorisation failed.
    #[error(
        "the free-dof stiffness matrix is not symmetric positive definite (sparse Cholesky: {0})"
    )]
    NotPositiveDefinite(String),
    /// A node index is outside the mesh.
    #[error("node {node} is out of range (the model has {n_nodes} nodes)")]
    NodeOutOfRange {
        /// The offending node.
        node: usize,
        /// Number of nodes of the model.
        n_nodes: usize,
    },
    /// Working nodes must be entirely free (a fixed dof has no compliance).
    #[error("node {node} has a fixed dof and cannot be a working node")]
    NodeFixed {
        /// The offending node.
        node: usize,
    },
    /// The node is already in the working set.
    #[error("node {node} is already a working node")]
    AlreadyWorking {
        /// The offending node.
        node: usize,
    },
    /// The node is not in the working set.
    #[error("node {node} is not a working node")]
    NotWorking {
        /// The offending node.
        node: usize,
    },
    /// An axis index is not below the node dimension.
    #[error("axis {axis} is out of range for {dim}-D nodes")]
    AxisOutOfRange {
        /// The offending axis.
        axis: usize,
        /// Dofs per node.
        dim: usize,
    },
    /// A working-coordinate index is not below `N`.
    #[error("working coordinate {coordinate} is out of range (N = {len})")]
    CoordinateOutOfRange {
        /// The offending coordinate.
        coordinate: usize,
        /// Number of working coordinates.
        len: usize,
    },
    /// A vector argument has the wrong length.
    #[error("{what} has length {got}, expected {expected}")]
    Length {
        /// Which argument.
        what: &'static str,
        /// Its length.
        got: usize,
        /// The expected length.
        expected: usize,
    },
    /// The exchange pivot is not positive: the mixed problem would be ill-posed
    /// (for a positive definite model every pivot of a well-posed exchange is > 0).
    #[error("exchange pivot {pivot} at working coordinate {coordinate} is not positive")]
    SingularPivot {
        /// Working coordinate being exchanged.
        coordinate: usize,
        /// The pivot found.
        pivot: f64,
    },
    /// The rotation is not proper orthonormal.
    #[error("rotation is not a proper orthonormal {dim}x{dim} matrix (deviation {deviation:e})")]
    InvalidRotation {
        /// Dimension.
        dim: usize,
        /// max |R^T R - I| or |det R - 1|.
        deviation: f64,
    },
    /// The node block of (M - K_W^{-1} N) in equation (10) is singular.
    #[error("slip transform (M - K_W^-1 N) of node {node} is singular (determinant {det:e})")]
    SingularSlipTransform {
        /// The node.
        node: usize,
        /// Determinant of the node block.
        det: f64,
    },
}
