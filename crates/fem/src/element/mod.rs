//! Finite elements: reference shape functions, quadrature, and the local
//! (element-level) matrices.
//!
//! All elements are isoparametric simplices. The reference element is the
//! unit simplex: triangle $(0,0),(1,0),(0,1)$, tetrahedron
//! $(0,0,0),(1,0,0),(0,1,0),(0,0,1)$, with barycentric coordinates
//! $L_0 = 1-\sum_j\xi_j$, $L_i = \xi_{i-1}$.
//!
//! | kind | nodes | shape functions | local node order |
//! |---|---|---|---|
//! | [`ElementKind::Tri3`] | 3 | $N_i = L_i$ | corners 0,1,2 counter-clockwise |
//! | [`ElementKind::Tri6`] | 6 | $L_i(2L_i-1)$, $4L_iL_j$ | corners, then mid-edges 01, 12, 20 |
//! | [`ElementKind::Tet4`] | 4 | $N_i = L_i$ | corners 0..3, positive volume |
//! | [`ElementKind::Tet10`] | 10 | $L_i(2L_i-1)$, $4L_iL_j$ | corners, then mid-edges 01, 12, 20, 03, 13, 23 |
//!
//! Local matrices use nalgebra fixed-size matrices; global assembly is in
//! [`crate::assemble`].

pub mod facet;
pub mod quadrature;
pub mod shape;
pub mod stiffness;

use serde::{Deserialize, Serialize};

/// The element types of the crate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum ElementKind {
    /// Linear 3-node triangle (2-D), constant strain.
    Tri3,
    /// Quadratic 6-node triangle (2-D), linear strain. Default for the model:
    /// it does not lock at the phantom's $\nu = 0.48$ (see `docs/locking.md`).
    Tri6,
    /// Linear 4-node tetrahedron (3-D), constant strain.
    Tet4,
    /// Quadratic 10-node tetrahedron (3-D).
    Tet10,
}

/// Corner pairs of the mid-edge nodes of a quadratic triangle, in local order.
pub const TRIANGLE_EDGES: [(usize, usize); 3] = [(0, 1), (1, 2), (2, 0)];
/// Corner pairs of the mid-edge nodes of a quadratic tetrahedron, in local order.
pub const TETRAHEDRON_EDGES: [(usize, usize); 6] = [(0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3)];

impl ElementKind {
    /// Spatial dimension (2 or 3).
    pub const fn dimension(self) -> usize {
        match self {
            ElementKind::Tri3 | ElementKind::Tri6 => 2,
            ElementKind::Tet4 | ElementKind::Tet10 => 3,
        }
    }

    /// Nodes per element.
    pub const fn node_count(self) -> usize {
        match self {
            ElementKind::Tri3 => 3,
            ElementKind::Tri6 => 6,
            ElementKind::Tet4 => 4,
            ElementKind::Tet10 => 10,
        }
    }

    /// Corner (vertex) nodes per element, which come first in the local order.
    pub const fn corner_count(self) -> usize {
        self.dimension() + 1
    }

    /// Polynomial degree of the shape functions (1 or 2).
    pub const fn degree(self) -> usize {
        match self {
            ElementKind::Tri3 | ElementKind::Tet4 => 1,
            ElementKind::Tri6 | ElementKind::Tet10 => 2,
        }
    }

    /// Degrees of freedom per element (`node_count * dimension`).
    pub const fn dof_count(self) -> usize {
        self.node_count() * self.dimension()
    }

    /// The quadratic element with the same corners (identity for quadratic kinds).
    pub const fn quadratic(self) -> ElementKind {
        match self {
            ElementKind::Tri3 | ElementKind::Tri6 => ElementKind::Tri6,
            ElementKind::Tet4 | ElementKind::Tet10 => ElementKind::Tet10,
        }
    }

    /// Corner pairs of the simplex's edges, in the local order of the
    /// mid-edge nodes of the quadratic kind.
    pub const fn edges(self) -> &'static [(usize, usize)] {
        match self.dimension() {
            2 => &TRIANGLE_EDGES,
            _ => &TETRAHEDRON_EDGES,
        }
    }

    /// Local node lists of the facets (edges in 2-D, faces in 3-D): corners
    /// first, then mid-edge nodes for quadratic kinds. Facet `k` is opposite
    /// corner `k` for tetrahedra and runs from corner `k` to `k+1` for triangles.
    pub fn facets(self) -> Vec<Vec<usize>> {
        match self {
            ElementKind::Tri3 => vec![vec![0, 1], vec![1, 2], vec![2, 0]],
            ElementKind::Tri6 => vec![vec![0, 1, 3], vec![1, 2, 4], vec![2, 0, 5]],
            ElementKind::Tet4 => TET_FACES.iter().map(|f| f.to_vec()).collect(),
            ElementKind::Tet10 => TET_FACES
                .iter()
                .map(|f| {
                    let mut nodes = f.to_vec();
                    for k in 0..3 {
                        nodes.push(tet_edge_node(f[k], f[(k + 1) % 3]));
                    }
                    nodes
                })
                .collect(),
        }
    }
}

/// Corner triples of tetrahedron faces; face `k` is opposite corner `k`.
const TET_FACES: [[usize; 3]; 4] = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]];

/// Local index of the mid-edge node between corners `a` and `b` of a Tet10.
fn tet_edge_node(a: usize, b: usize) -> usize {
    let k = TETRAHEDRON_EDGES
        .iter()
        .position(|&(p, q)| (p, q) == (a, b) || (q, p) == (a, b))
        .expect("corners of a tetrahedron face are joined by an edge");
    4 + k
}
