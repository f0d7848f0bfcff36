//! Global assembly of the stiffness matrix $K = \sum_e P_e^T K^e P_e$
//! (the paper's equation (4)) into a faer [`SparseColMat`].
//!
//! Local versus global: [`crate::element::stiffness`] computes each $K^e$
//! with fixed-size nalgebra matrices; this module owns the global sparsity
//! pattern and scatters local matrices into it.
//!
//! - **Pattern.** Two dofs couple when their nodes share an element. The
//!   pattern is built once per mesh ([`StiffnessPattern`]) from the node
//!   adjacency; each node's column block lists its neighbour nodes' dofs in
//!   ascending order, interleaved $(u_x, u_y[, u_z])$. Changing materials
//!   only changes values, so the pattern, and the symbolic Cholesky
//!   factorisation built from it, are reused.
//! - **Parallelism.** Nodes are split into contiguous ranges; each rayon
//!   task owns the value slice of its range's columns and visits the
//!   elements that touch its nodes, so no two tasks write the same entry and
//!   no locking or unsafe code is needed. Elements on a range boundary are
//!   computed by both neighbours (a small overhead when nodes are numbered
//!   spatially, see [`Mesh::renumber_spatially`]).
//! - **Derivatives.** $K$ is linear in $D$, so $\partial K/\partial E = K/E$
//!   for a homogeneous body and, in general,
//!   $\partial K/\partial p = \sum_e \int B^T (\partial D/\partial p) B$,
//!   assembled by the same code with $\partial D/\partial p$ in place of $D$.
//! - **Homogeneous bodies.** $D = a\,D_\lambda + \mu\,D_\mu$ (Lamé's
//!   $\lambda$, or its plane-stress counterpart, and $\mu$), so
//!   $K = a\,K_\lambda + \mu\,K_\mu$ with the two matrices assembled once
//!   per mesh: a new $E$ or $\nu$ of a body with one material costs one
//!   pass over the values instead of every element's integral.

use std::sync::{Arc, OnceLock};

use faer::sparse::{SparseColMat, SymbolicSparseColMat};
use nalgebra::SMatrix;
use rayon::prelude::*;

use crate::element::ElementKind;
use crate::element::stiffness::{ReferenceGradients, element_stiffness};
use crate::error::FemError;
use crate::material::{Constitutive, Formulation, Materials, Parameter, lame_basis};
use crate::mesh::Mesh;

/// The sparsity pattern of the global stiffness matrix of a mesh, shared by
/// $K$, its derivatives, and the spring matrices of supports.
#[derive(Debug, Clone)]
pub struct StiffnessPattern {
    dimension: usize,
    /// CSR of node adjacency: neighbours of node `n` (itself included) are
    /// `adjacency[offsets[n]..offsets[n + 1]]`, ascending.
    offsets: Vec<usize>,
    adjacency: Vec<usize>,
    symbolic: SymbolicSparseColMat<usize>,
}

impl StiffnessPattern {
    /// Builds the pattern from element connectivity.
    pub fn new<const D: usize>(mesh: &Mesh<D>) -> Self {
        let node_elements = node_elements(mesh);
        let per_node: Vec<Vec<usize>> = (0..mesh.node_count())
            .into_par_iter()
            .map(|n| {
                let mut neighbours: Vec<usize> = node_elements
                    .of(n)
                    .iter()
                    .flat_map(|&e| mesh.element(e))
                    .copied()
                    .collect();
                neighbours.push(n);
                neighbours.sort_unstable();
                neighbours.dedup();
                neighbours
            })
            .collect();
        let mut offsets = Vec::with_capacity(per_node.len() + 1);
        offsets.push(0);
        for list in &per_node {
            offsets.push(offsets.last().unwrap_or(&0) + list.len());
        }
        let adjacency: Vec<usize> = per_node.into_iter().flatten().collect();
        let dof_count = D * mesh.node_count();
        let mut col_ptr = Vec::with_capacity(dof_count + 1);
        let mut row_idx = Vec::with_capacity(D * D * adjacency.len());
        col_ptr.push(0);
        for n in 0..mesh.node_count() {
            for _ in 0..D {
                for &m in &adjacency[offsets[n]..offsets[n + 1]] {
                    row_idx.extend((0..D).map(|r| m * D + r));
                }
                col_ptr.push(row_idx.len());
            }
        }
        let symbolic =
            SymbolicSparseColMat::new_checked(dof_count, dof_count, col_ptr, None, row_idx);
        Self {
            dimension: D,
            offsets,
            adjacency,
            symbolic,
        }
    }

    /// Number of dofs (rows and columns).
    pub fn dof_count(&self) -> usize {
        self.symbolic.nrows()
    }

    /// Number of stored entries.
    pub fn nnz(&self) -> usize {
        self.symbolic.row_idx().len()
    }

    /// The symbolic CSC structure.
    pub fn symbolic(&self) -> &SymbolicSparseColMat<usize> {
        &self.symbolic
    }

    /// A matrix with this pattern and all values zero.
    pub fn zeros(&self) -> SparseColMat<usize, f64> {
        SparseColMat::new(self.symbolic.clone(), vec![0.0; self.nnz()])
    }

    /// Whether `matrix` has exactly this pattern (same dimension and entries).
    pub fn matches(&self, matrix: &SparseColMat<usize, f64>) -> bool {
        let s = matrix.symbolic();
        s.nrows() == self.dof_count()
            && s.col_ptr() == self.symbolic.col_ptr()
            && s.row_idx() == self.symbolic.row_idx()
    }

    /// The nodes that share an element with node `n`, itself included,
    /// ascending.
    pub fn neighbours(&self, n: usize) -> &[usize] {
        &self.adjacency[self.offsets[n]..self.offsets[n + 1]]
    }

    /// Position in the value array of the entry (row dof of node `row_node`
    /// component `r`, column dof of node `col_node` component `c`), or `None`
    /// if the nodes do not share an element.
    pub fn position(&self, row_node: usize, r: usize, col_node: usize, c: usize) -> Option<usize> {
        let d = self.dimension;
        let k = self.neighbours(col_node).binary_search(&row_node).ok()?;
        Some(self.symbolic.col_ptr()[col_node * d + c] + k * d + r)
    }
}

/// Node-to-element incidence in CSR form.
struct NodeElements {
    offsets: Vec<usize>,
    elements: Vec<usize>,
}

impl NodeElements {
    fn of(&self, n: usize) -> &[usize] {
        &self.elements[self.offsets[n]..self.offsets[n + 1]]
    }
}

fn node_elements<const D: usize>(mesh: &Mesh<D>) -> NodeElements {
    let mut counts = vec![0usize; mesh.node_count() + 1];
    for &n in mesh.connectivity() {
        counts[n + 1] += 1;
    }
    for i in 0..mesh.node_count() {
        counts[i + 1] += counts[i];
    }
    let offsets = counts.clone();
    let mut elements = vec![0; mesh.connectivity().len()];
    let mut cursor = counts;
    for e in 0..mesh.element_count() {
        for &n in mesh.element(e) {
            elements[cursor[n]] = e;
            cursor[n] += 1;
        }
    }
    NodeElements { offsets, elements }
}

/// A contiguous range of nodes assembled by one task, with the elements
/// that touch it.
#[derive(Debug, Clone)]
struct NodeRange {
    nodes: std::ops::Range<usize>,
    elements: Vec<usize>,
}

/// Assembles the stiffness matrix (and its derivatives) of one mesh with a
/// fixed pattern; owns the mesh.
#[derive(Debug, Clone)]
pub struct Assembler<const D: usize> {
    mesh: Mesh<D>,
    formulation: Formulation,
    pattern: StiffnessPattern,
    ranges: Vec<NodeRange>,
    /// The values of $K_\lambda$ and $K_\mu$, made at the first
    /// homogeneous assembly and shared by clones.
    lame_matrices: Arc<OnceLock<[Vec<f64>; 2]>>,
}

impl<const D: usize> Assembler<D> {
    /// Builds the pattern and the parallel work split for `mesh`.
    /// `formulation` must match the mesh dimension (plane strain or stress
    /// for 2-D, solid for 3-D).
    pub fn new(mesh: Mesh<D>, formulation: Formulation) -> Result<Self, FemError> {
        formulation.validate()?;
        if formulation.dimension() != D {
            return Err(FemError::InvalidMesh(format!(
                "formulation {formulation:?} does not apply to a {D}-D mesh"
            )));
        }
        let pattern = StiffnessPattern::new(&mesh);
        let incidence = node_elements(&mesh);
        // Enough ranges to balance the threads, few enough that duplicated
        // boundary elements stay a small fraction.
        let range_count = (4 * rayon::current_num_threads())
            .min(mesh.node_count() / 256)
            .max(1);
        let step = mesh.node_count().div_ceil(range_count).max(1);
        let ranges = (0..mesh.node_count())
            .step_by(step)
            .map(|start| {
                let nodes = start..(start + step).min(mesh.node_count());
                let mut elements: Vec<usize> = nodes
                    .clone()
                    .flat_map(|n| incidence.of(n).iter().copied())
                    .collect();
                elements.sort_unstable();
                elements.dedup();
                NodeRange { nodes, elements }
            })
            .collect();
        Ok(Self {
            mesh,
            formulation,
            pattern,
            ranges,
            lame_matrices: Arc::new(OnceLock::new()),
        })
    }

    /// The mesh.
    pub fn mesh(&self) -> &Mesh<D> {
        &self.mesh
    }

    /// The formulation.
    pub fn formulation(&self) -> Formulation {
        self.formulation
    }

    /// The sparsity pattern.
    pub fn pattern(&self) -> &StiffnessPattern {
        &self.pattern
    }

    /// Checks that every element's region has a material.
    fn check_materials(&self, materials: &Materials) -> Result<(), FemError> {
        let regions = self.mesh.regions();
        if let Some(element) = regions.iter().position(|&r| r >= materials.len()) {
            return Err(FemError::MissingMaterial {
                element,
                region: regions[element],
                region_count: materials.len(),
            });
        }
        Ok(())
    }

    /// The global stiffness matrix $K(E, \nu)$ (full symmetric storage,
    /// no boundary conditions applied).
    pub fn stiffness(&self, materials: &Materials) -> Result<SparseColMat<usize, f64>, FemError> {
        let mut k = self.pattern.zeros();
        self.stiffness_into(materials, &mut k)?;
        Ok(k)
    }

    /// Overwrites the values of `matrix` (which must have this assembler's
    /// pattern) with $K(E, \nu)$, reusing its storage.
    pub fn stiffness_into(
        &self,
        materials: &Materials,
        matrix: &mut SparseColMat<usize, f64>,
    ) -> Result<(), FemError> {
        self.check_materials(materials)?;
        if let Some(first) = materials.0.first()
            && materials.0.iter().all(|m| m == first)
        {
            self.check_pattern(matrix)?;
            let [k_lambda, k_mu] = self.lame_matrices()?;
            let (a, mu) = first.lame_coefficients(self.formulation);
            for ((value, l), m) in matrix.val_mut().iter_mut().zip(k_lambda).zip(k_mu) {
                *value = a * l + mu * m;
            }
            return Ok(());
        }
        let per_region: Vec<Option<Constitutive>> = materials
            .0
            .iter()
            .map(|m| Some(m.constitutive(self.formulation)))
            .collect();
        self.assemble_into(&per_region, matrix)
    }

    /// The values of $K_\lambda$ and $K_\mu$ (every element with
    /// $D_\lambda$, then with $D_\mu$).
    fn lame_matrices(&self) -> Result<&[Vec<f64>; 2], FemError> {
        if let Some(matrices) = self.lame_matrices.get() {
            return Ok(matrices);
        }
        let mut assembled = [0, 1].map(|_| self.pattern.zeros());
        for (d, matrix) in lame_basis(self.formulation).into_iter().zip(&mut assembled) {
            self.assemble_into(&vec![Some(d); self.region_count()], matrix)?;
        }
        Ok(self
            .lame_matrices
            .get_or_init(|| assembled.map(|m| m.val().to_vec())))
    }

    fn check_pattern(&self, matrix: &SparseColMat<usize, f64>) -> Result<(), FemError> {
        if self.pattern.matches(matrix) {
            Ok(())
        } else {
            Err(FemError::InvalidMesh(
                "matrix does not have the assembler's sparsity pattern".into(),
            ))
        }
    }

    /// Regions the mesh's elements refer to.
    fn region_count(&self) -> usize {
        self.mesh.regions().iter().max().map_or(0, |r| r + 1)
    }

    /// The derivative $\partial K/\partial p$ with respect to parameter `p`
    /// of the material of `region` (or of all regions at once when `region`
    /// is `None`, i.e. for a homogeneous body with one $E$ and one $\nu$).
    pub fn stiffness_derivative(
        &self,
        materials: &Materials,
        parameter: Parameter,
        region: Option<usize>,
    ) -> Result<SparseColMat<usize, f64>, FemError> {
        self.check_materials(materials)?;
        let per_region: Vec<Option<Constitutive>> = materials
            .0
            .iter()
            .enumerate()
            .map(|(r, m)| {
                (region.is_none() || region == Some(r))
                    .then(|| m.constitutive_derivative(self.formulation, parameter))
            })
            .collect();
        let mut k = self.pattern.zeros();
        self.assemble_into(&per_region, &mut k)?;
        Ok(k)
    }

    /// Assembles $\sum_e \int B^T D_{r(e)} B$ with one constitutive matrix per
    /// region (`None`: the region contributes nothing) into `matrix`.
    pub fn assemble_into(
        &self,
        per_region: &[Option<Constitutive>],
        matrix: &mut SparseColMat<usize, f64>,
    ) -> Result<(), FemError> {
        self.check_pattern(matrix)?;
        if let Some(element) = self
            .mesh
            .regions()
            .iter()
            .position(|&r| r >= per_region.len())
        {
            let region = self.mesh.regions()[element];
            return Err(FemError::MissingMaterial {
                element,
                region,
                region_count: per_region.len(),
            });
        }
        let values = matrix.val_mut();
        match self.mesh.kind() {
            ElementKind::Tri3 => self.assemble_kind::<3, 3, 6>(per_region, values),
            ElementKind::Tri6 => self.assemble_kind::<6, 3, 12>(per_region, values),
            ElementKind::Tet4 => self.assemble_kind::<4, 6, 12>(per_region, values),
            ElementKind::Tet10 => self.assemble_kind::<10, 6, 30>(per_region, values),
        }
    }

    fn assemble_kind<const N: usize, const S: usize, const NDOF: usize>(
        &self,
        per_region: &[Option<Constitutive>],
        values: &mut [f64],
    ) -> Result<(), FemError> {
        let constitutive: Vec<Option<SMatrix<f64, S, S>>> = per_region
            .iter()
            .map(|c| {
                c.map(|c| match c {
                    Constitutive::Plane(m) => SMatrix::from_fn(|i, j| m[(i, j)]),
                    Constitutive::Solid(m) => SMatrix::from_fn(|i, j| m[(i, j)]),
                })
            })
            .collect();
        let reference = ReferenceGradients::<D, N>::for_stiffness();
        let scale = self.formulation.thickness();
        let col_ptr = self.pattern.symbolic.col_ptr();
        // Split the value array at the first column of each node range.
        let mut slices = Vec::with_capacity(self.ranges.len());
        let mut rest = values;
        let mut consumed = 0;
        for range in &self.ranges {
            let end = col_ptr[range.nodes.end * D];
            let (head, tail) = rest.split_at_mut(end - consumed);
            slices.push((range, consumed, head));
            rest = tail;
            consumed = end;
        }
        slices
            .into_par_iter()
            .try_for_each(|(range, offset, slice)| {
                slice.fill(0.0);
                for &e in &range.elements {
                    let Some(d) = &constitutive[self.mesh.regions()[e]] else {
                        continue;
                    };
                    let coordinates = self.mesh.element_coordinates::<N>(e);
                    let ke = element_stiffness::<D, N, S, NDOF>(&coordinates, &reference, d, scale)
                        .map_err(|determinant| FemError::DegenerateElement {
                            element: e,
                            determinant,
                        })?;
                    let nodes = self.mesh.element(e);
                    for (b, &n) in nodes.iter().enumerate() {
                        if !range.nodes.contains(&n) {
                            continue;
                        }
                        let neighbours = &self.pattern.adjacency
                            [self.pattern.offsets[n]..self.pattern.offsets[n + 1]];
                        for (a, &m) in nodes.iter().enumerate() {
                            let k = neighbours
                                .binary_search(&m)
                                .unwrap_or_else(|_| unreachable!("element nodes are neighbours"));
                            for c in 0..D {
                                let base = col_ptr[n * D + c] + k * D - offset;
                                for r in 0..D {
                                    slice[base + r] += ke[(a * D + r, b * D + c)];
                                }
                            }
                        }
                    }
                }
                Ok(())
            })
    }
}

/// $y = A x$ for a sparse matrix in column storage.
pub fn multiply(matrix: &SparseColMat<usize, f64>, x: &[f64]) -> Vec<f64> {
    let symbolic = matrix.symbolic();
    let (col_ptr, row_idx, values) = (symbolic.col_ptr(), symbolic.row_idx(), matrix.val());
    let mut y = vec![0.0; symbolic.nrows()];
    for j in 0..symbolic.ncols() {
        let xj = x[j];
        if xj != 0.0 {
            for p in col_ptr[j]..col_ptr[j + 1] {
                y[row_idx[p]] += values[p] * xj;
            }
        }
    }
    y
}
