//! Meshes: node coordinates, element connectivity, a material region per
//! element, and the structured generators used by the pipeline.
//!
//! A [`Mesh<D>`] holds `D`-dimensional nodes and elements of one
//! [`ElementKind`] of that dimension. Degrees of freedom are interleaved per
//! node: node `n` owns dofs `D*n .. D*n + D` in the order $(u_x, u_y[, u_z])$.

pub mod quadratic;
pub mod quality;
pub mod query;
pub mod rectangle;
pub mod slab;

use nalgebra::SMatrix;

use crate::element::ElementKind;
use crate::element::stiffness::{ReferenceGradients, physical_gradients};
use crate::error::FemError;

pub use quality::QualityReport;
pub use query::{BoundaryFacet, Face};
pub use rectangle::{MarkerGrid, RectangleMesh};
pub use slab::SlabMesh;

/// A mesh of simplices in `D` dimensions.
#[derive(Debug, Clone, PartialEq)]
pub struct Mesh<const D: usize> {
    kind: ElementKind,
    nodes: Vec<[f64; D]>,
    connectivity: Vec<usize>,
    regions: Vec<usize>,
}

/// A 2-D triangle mesh (T3 or T6).
pub type Mesh2 = Mesh<2>;
/// A 3-D tetrahedral mesh (Tet4 or Tet10).
pub type Mesh3 = Mesh<3>;

impl<const D: usize> Mesh<D> {
    /// A validated mesh: `connectivity` holds `kind.node_count()` node
    /// indices per element (local order of [`ElementKind`]), `regions` one
    /// material region per element. Every coordinate must be finite and every
    /// element must have positive Jacobian determinant at its nodes'
    /// quadrature points (no inverted or degenerate element).
    pub fn new(
        kind: ElementKind,
        nodes: Vec<[f64; D]>,
        connectivity: Vec<usize>,
        regions: Vec<usize>,
    ) -> Result<Self, FemError> {
        if kind.dimension() != D {
            return Err(FemError::InvalidMesh(format!(
                "element kind {kind:?} is {}-D but the mesh is {D}-D",
                kind.dimension()
            )));
        }
        let per = kind.node_count();
        if !connectivity.len().is_multiple_of(per) {
            return Err(FemError::InvalidMesh(format!(
                "connectivity length {} is not a multiple of {per} nodes per element",
                connectivity.len()
            )));
        }
        let element_count = connectivity.len() / per;
        if regions.len() != element_count {
            return Err(FemError::DimensionMismatch {
                context: "mesh regions (one per element)",
                expected: element_count,
                actual: regions.len(),
            });
        }
        for node in &nodes {
            for &x in node {
                crate::error::finite("mesh node coordinate", x)?;
            }
        }
        if let Some(&node) = connectivity.iter().find(|&&n| n >= nodes.len()) {
            return Err(FemError::NodeOutOfRange {
                context: "mesh connectivity",
                node,
                node_count: nodes.len(),
            });
        }
        let mesh = Self {
            kind,
            nodes,
            connectivity,
            regions,
        };
        mesh.check_orientation()?;
        Ok(mesh)
    }

    /// Checks every element's Jacobian determinant at the stiffness
    /// quadrature points and at the corners.
    fn check_orientation(&self) -> Result<(), FemError> {
        match self.kind {
            ElementKind::Tri3 => self.check_kind::<3>(),
            ElementKind::Tri6 => self.check_kind::<6>(),
            ElementKind::Tet4 => self.check_kind::<4>(),
            ElementKind::Tet10 => self.check_kind::<10>(),
        }
    }

    fn check_kind<const N: usize>(&self) -> Result<(), FemError> {
        let mut reference = ReferenceGradients::<D, N>::for_stiffness();
        // Corners too: a quadratic element can fold at a vertex while its
        // interior quadrature points still look fine.
        for a in 0..=D {
            let mut xi = nalgebra::SVector::<f64, D>::zeros();
            if a > 0 {
                xi[a - 1] = 1.0;
            }
            reference
                .points
                .push((crate::element::shape::gradients::<D, N>(&xi), 0.0));
        }
        for e in 0..self.element_count() {
            let x = self.element_coordinates::<N>(e);
            let mut extent: f64 = 0.0;
            for i in 0..D {
                extent = extent.max(x.row(i).max() - x.row(i).min());
            }
            for (g, _) in &reference.points {
                let (_, determinant) = physical_gradients(&x, g);
                if determinant.partial_cmp(&(1e-12 * extent.powi(D as i32)))
                    != Some(std::cmp::Ordering::Greater)
                {
                    return Err(FemError::DegenerateElement {
                        element: e,
                        determinant,
                    });
                }
            }
        }
        Ok(())
    }

    /// The element kind.
    pub fn kind(&self) -> ElementKind {
        self.kind
    }

    /// Node coordinates.
    pub fn nodes(&self) -> &[[f64; D]] {
        &self.nodes
    }

    /// Coordinates of node `n`.
    pub fn node(&self, n: usize) -> [f64; D] {
        self.nodes[n]
    }

    /// Number of nodes.
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Number of degrees of freedom, `D * node_count()`.
    pub fn dof_count(&self) -> usize {
        D * self.nodes.len()
    }

    /// Number of elements.
    pub fn element_count(&self) -> usize {
        self.regions.len()
    }

    /// Node indices of element `e`, in local order.
    pub fn element(&self, e: usize) -> &[usize] {
        let per = self.kind.node_count();
        &self.connectivity[e * per..(e + 1) * per]
    }

    /// Flat connectivity, `kind().node_count()` entries per element.
    pub fn connectivity(&self) -> &[usize] {
        &self.connectivity
    }

    /// Material region of every element.
    pub fn regions(&self) -> &[usize] {
        &self.regions
    }

    /// Number of regions, `1 + max region id`.
    pub fn region_count(&self) -> usize {
        self.regions.iter().max().map_or(0, |&r| r + 1)
    }

    /// Sets each element's region from its centroid, e.g. layers in y
    /// (`|c| if c[1] < 0.03 { 0 } else { 1 }`) or an inclusion.
    pub fn assign_regions(&mut self, region_of: impl Fn([f64; D]) -> usize) {
        for e in 0..self.element_count() {
            self.regions[e] = region_of(self.centroid(e));
        }
    }

    /// Centroid of element `e` (mean of its corners).
    pub fn centroid(&self, e: usize) -> [f64; D] {
        let corners = self.kind.corner_count();
        let mut c = [0.0; D];
        for &n in &self.element(e)[..corners] {
            for i in 0..D {
                c[i] += self.nodes[n][i] / corners as f64;
            }
        }
        c
    }

    /// Coordinates of element `e` as a `D x N` matrix, column per node.
    pub fn element_coordinates<const N: usize>(&self, e: usize) -> SMatrix<f64, D, N> {
        let nodes = self.element(e);
        SMatrix::from_fn(|i, a| self.nodes[nodes[a]][i])
    }

    /// Axis-aligned bounding box `(min, max)`.
    pub fn bounding_box(&self) -> ([f64; D], [f64; D]) {
        let mut lo = [f64::INFINITY; D];
        let mut hi = [f64::NEG_INFINITY; D];
        for p in &self.nodes {
            for i in 0..D {
                lo[i] = lo[i].min(p[i]);
                hi[i] = hi[i].max(p[i]);
            }
        }
        (lo, hi)
    }

    /// Renumbers nodes in lexicographic order of their coordinates (last
    /// axis slowest), which keeps each element's nodes close in index: good
    /// for cache locality and for the node-range parallel assembly.
    pub fn renumber_spatially(&mut self) {
        let mut order: Vec<usize> = (0..self.nodes.len()).collect();
        order.sort_by(|&a, &b| {
            let (pa, pb) = (self.nodes[a], self.nodes[b]);
            for i in (0..D).rev() {
                match pa[i].total_cmp(&pb[i]) {
                    std::cmp::Ordering::Equal => continue,
                    other => return other,
                }
            }
            std::cmp::Ordering::Equal
        });
        let mut new_index = vec![0; order.len()];
        for (new, &old) in order.iter().enumerate() {
            new_index[old] = new;
        }
        self.nodes = order.iter().map(|&old| self.nodes[old]).collect();
        for n in &mut self.connectivity {
            *n = new_index[*n];
        }
    }
}
