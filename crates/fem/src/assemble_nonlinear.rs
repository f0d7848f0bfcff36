//! Assembly of the neo-Hookean internal force $f_\text{int}(u)$ and its
//! consistent tangent $K_T(u) = \partial f_\text{int}/\partial u$.
//!
//! In the reference configuration (total Lagrangian), with physical
//! shape-function gradients $\nabla_X N_a$ and $F = I + \sum_a u_a \otimes \nabla_X N_a$,
//!
//! $$f_{a,i} = \int_{\Omega_0} P_{iJ}\, \frac{\partial N_a}{\partial X_J}\, dV, \qquad
//!   K_{(a,i),(b,k)} = \int_{\Omega_0} \frac{\partial N_a}{\partial X_J}\,
//!   \mathbb{A}_{iJkL}\, \frac{\partial N_b}{\partial X_L}\, dV$$
//!
//! (times the thickness in plane strain), with $P$ and $\mathbb{A}$ from
//! [`crate::hyperelastic`]. Element integrals use the same quadrature as the
//! linear stiffness, so $K_T(0)$ is the linear $K$ to rounding. Per element
//! this is $K^e = \sum_q w_q \det J_q\, G_q^T \mathbb{A}_q G_q$ with the
//! gradient operator $G$ (`D*D x D*N`, $\partial F_{iJ}/\partial u_{a,k} = \delta_{ik}\,\partial N_a/\partial X_J$),
//! and $f^e = \sum_q w_q \det J_q\, P_q \nabla_X N$.
//!
//! $K_T$ has the linear $K$'s [`crate::StiffnessPattern`], so the symbolic
//! Cholesky analysis is shared. Parallelism follows [`crate::Assembler`]:
//! contiguous node ranges, each rayon task owning the force entries and
//! matrix columns of its nodes.

use std::ops::Range;

use faer::sparse::SparseColMat;
use nalgebra::{SMatrix, SVector};
use rayon::prelude::*;

use crate::assemble::Assembler;
use crate::element::ElementKind;
use crate::element::stiffness::{ReferenceGradients, physical_gradients};
use crate::error::FemError;
use crate::hyperelastic::NeoHookean;
use crate::material::{Formulation, Materials};
use crate::mesh::Mesh;
use crate::nonlinear_error::NonlinearError;

/// Assembles the neo-Hookean internal force and tangent of one mesh; owns
/// a linear [`Assembler`] for the mesh, formulation and pattern.
#[derive(Debug, Clone)]
pub struct HyperelasticAssembler<const D: usize> {
    assembler: Assembler<D>,
    ranges: Vec<NodeRange>,
}

/// A contiguous range of nodes assembled by one task, with the elements
/// that touch it.
#[derive(Debug, Clone)]
struct NodeRange {
    nodes: Range<usize>,
    elements: Vec<usize>,
}

/// Why an element's response could not be computed.
enum ElementFailure {
    /// Non-positive reference Jacobian determinant.
    Degenerate(f64),
    /// Non-positive $J = \det F$.
    Inverted(f64),
}

impl<const D: usize> HyperelasticAssembler<D> {
    /// Wraps `assembler`; its formulation must be plane strain (2-D) or
    /// solid (3-D).
    pub fn new(assembler: Assembler<D>) -> Result<Self, NonlinearError> {
        let formulation = assembler.formulation();
        if matches!(formulation, Formulation::PlaneStress { .. }) {
            return Err(NonlinearError::UnsupportedFormulation(formulation));
        }
        let ranges = node_ranges(assembler.mesh());
        Ok(Self { assembler, ranges })
    }

    /// The linear assembler (mesh, formulation, pattern).
    pub fn assembler(&self) -> &Assembler<D> {
        &self.assembler
    }

    /// The mesh.
    pub fn mesh(&self) -> &Mesh<D> {
        self.assembler.mesh()
    }

    /// The internal force $f_\text{int}(u)$ (full, interleaved; no boundary
    /// conditions applied).
    pub fn internal_force(
        &self,
        materials: &Materials,
        displacement: &[f64],
    ) -> Result<Vec<f64>, NonlinearError> {
        let mut force = vec![0.0; self.mesh().dof_count()];
        self.assemble_into(materials, displacement, &mut force, None)?;
        Ok(force)
    }

    /// The tangent $K_T(u)$ in the linear pattern (full symmetric storage).
    pub fn tangent(
        &self,
        materials: &Materials,
        displacement: &[f64],
    ) -> Result<SparseColMat<usize, f64>, NonlinearError> {
        let mut force = vec![0.0; self.mesh().dof_count()];
        let mut tangent = self.assembler.pattern().zeros();
        self.assemble_into(materials, displacement, &mut force, Some(&mut tangent))?;
        Ok(tangent)
    }

    /// Overwrites `force` with $f_\text{int}(u)$ and, if given, the values of
    /// `tangent` (which must have the assembler's pattern) with $K_T(u)$, in
    /// one pass over the elements.
    pub fn assemble_into(
        &self,
        materials: &Materials,
        displacement: &[f64],
        force: &mut [f64],
        tangent: Option<&mut SparseColMat<usize, f64>>,
    ) -> Result<(), NonlinearError> {
        let dof_count = self.mesh().dof_count();
        for (context, length) in [
            ("displacement", displacement.len()),
            ("internal force", force.len()),
        ] {
            if length != dof_count {
                return Err(FemError::DimensionMismatch {
                    context,
                    expected: dof_count,
                    actual: length,
                }
                .into());
            }
        }
        if let Some(&value) = displacement.iter().find(|v| !v.is_finite()) {
            return Err(FemError::InvalidValue {
                field: "displacement",
                value,
                reason: "must be finite",
            }
            .into());
        }
        if let Some(matrix) = &tangent
            && !self.assembler.pattern().matches(matrix)
        {
            return Err(FemError::InvalidMesh(
                "tangent does not have the assembler's sparsity pattern".into(),
            )
            .into());
        }
        let regions = self.mesh().regions();
        if let Some(element) = regions.iter().position(|&r| r >= materials.len()) {
            return Err(FemError::MissingMaterial {
                element,
                region: regions[element],
                region_count: materials.len(),
            }
            .into());
        }
        let models: Vec<NeoHookean> = materials.0.iter().map(NeoHookean::from_material).collect();
        let values = tangent.map(|k| k.val_mut());
        match self.mesh().kind() {
            ElementKind::Tri3 => {
                self.assemble_kind::<3, 4, 6>(&models, displacement, force, values)
            }
            ElementKind::Tri6 => {
                self.assemble_kind::<6, 4, 12>(&models, displacement, force, values)
            }
            ElementKind::Tet4 => {
                self.assemble_kind::<4, 9, 12>(&models, displacement, force, values)
            }
            ElementKind::Tet10 => {
                self.assemble_kind::<10, 9, 30>(&models, displacement, force, values)
            }
        }
    }

    fn assemble_kind<const N: usize, const DD: usize, const NDOF: usize>(
        &self,
        models: &[NeoHookean],
        displacement: &[f64],
        force: &mut [f64],
        values: Option<&mut [f64]>,
    ) -> Result<(), NonlinearError> {
        let mesh = self.mesh();
        let pattern = self.assembler.pattern();
        let reference = ReferenceGradients::<D, N>::for_stiffness();
        let scale = self.assembler.formulation().thickness();
        let col_ptr = pattern.symbolic().col_ptr();
        let with_tangent = values.is_some();
        // Split force and matrix values at the first dof / column of each range.
        let mut tasks = Vec::with_capacity(self.ranges.len());
        let mut force_rest = force;
        let mut values_rest = values;
        let mut consumed = 0;
        for range in &self.ranges {
            let (force_head, force_tail) = force_rest.split_at_mut(D * range.nodes.len());
            force_rest = force_tail;
            let matrix_slice = values_rest.take().map(|rest| {
                let end = col_ptr[range.nodes.end * D];
                let (head, tail) = rest.split_at_mut(end - consumed);
                values_rest = Some(tail);
                let slice = (consumed, head);
                consumed = end;
                slice
            });
            tasks.push((range, force_head, matrix_slice));
        }
        tasks
            .into_par_iter()
            .try_for_each(|(range, force_slice, mut matrix_slice)| {
                force_slice.fill(0.0);
                if let Some((_, slice)) = &mut matrix_slice {
                    slice.fill(0.0);
                }
                for &e in &range.elements {
                    let nodes = mesh.element(e);
                    let coordinates = mesh.element_coordinates::<N>(e);
                    let element_displacement =
                        SMatrix::<f64, D, N>::from_fn(|i, a| displacement[nodes[a] * D + i]);
                    let (fe, ke) = element_response::<D, N, DD, NDOF>(
                        &coordinates,
                        &element_displacement,
                        &reference,
                        &models[mesh.regions()[e]],
                        scale,
                        with_tangent,
                    )
                    .map_err(|failure| match failure {
                        ElementFailure::Degenerate(determinant) => {
                            NonlinearError::Fem(FemError::DegenerateElement {
                                element: e,
                                determinant,
                            })
                        }
                        ElementFailure::Inverted(jacobian) => NonlinearError::InvertedElement {
                            element: e,
                            jacobian,
                        },
                    })?;
                    for (b, &n) in nodes.iter().enumerate() {
                        if !range.nodes.contains(&n) {
                            continue;
                        }
                        let local = (n - range.nodes.start) * D;
                        for c in 0..D {
                            force_slice[local + c] += fe[b * D + c];
                        }
                        let (Some(ke), Some((offset, slice))) = (&ke, &mut matrix_slice) else {
                            continue;
                        };
                        for (a, &m) in nodes.iter().enumerate() {
                            for c in 0..D {
                                let base = pattern.position(m, 0, n, c).unwrap_or_else(|| {
                                    unreachable!("element nodes are neighbours")
                                }) - *offset;
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

/// Internal force (interleaved) and, if asked, tangent of one element:
/// $f^e = s\sum_q w_q \det J_q P_q \nabla_X N$ and
/// $K^e = s\sum_q w_q \det J_q G_q^T \mathbb{A}_q G_q$.
fn element_response<const D: usize, const N: usize, const DD: usize, const NDOF: usize>(
    coordinates: &SMatrix<f64, D, N>,
    displacement: &SMatrix<f64, D, N>,
    reference: &ReferenceGradients<D, N>,
    material: &NeoHookean,
    scale: f64,
    with_tangent: bool,
) -> Result<(SVector<f64, NDOF>, Option<SMatrix<f64, NDOF, NDOF>>), ElementFailure> {
    let mut force = SMatrix::<f64, D, N>::zeros();
    let mut tangent = with_tangent.then(SMatrix::<f64, NDOF, NDOF>::zeros);
    for (grad_ref, weight) in &reference.points {
        let (gradients, determinant) = physical_gradients(coordinates, grad_ref);
        if determinant.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return Err(ElementFailure::Degenerate(determinant));
        }
        // H = grad_X u, so F = I + H (never formed: see `crate::hyperelastic`).
        let displacement_gradient = displacement * gradients.transpose();
        let volume = weight * determinant * scale;
        match &mut tangent {
            None => {
                let stress = material
                    .stress(&displacement_gradient)
                    .map_err(ElementFailure::Inverted)?;
                force += stress * gradients * volume;
            }
            Some(k) => {
                let (stress, moduli) = material
                    .stress_and_tangent::<D, DD>(&displacement_gradient)
                    .map_err(ElementFailure::Inverted)?;
                force += stress * gradients * volume;
                let g = gradient_operator::<D, N, DD, NDOF>(&gradients);
                *k += g.transpose() * (moduli * g) * volume;
            }
        }
    }
    // Column-major D x N storage is the interleaved nodal order.
    Ok((SVector::from_column_slice(force.as_slice()), tangent))
}

/// $G$ with $G_{(iD+J),(aD+k)} = \delta_{ik}\,\partial N_a/\partial X_J$,
/// so that $\operatorname{vec} F = \operatorname{vec} I + G u^e$.
fn gradient_operator<const D: usize, const N: usize, const DD: usize, const NDOF: usize>(
    gradients: &SMatrix<f64, D, N>,
) -> SMatrix<f64, DD, NDOF> {
    let mut g = SMatrix::<f64, DD, NDOF>::zeros();
    for a in 0..N {
        for i in 0..D {
            for big_j in 0..D {
                g[(i * D + big_j, a * D + i)] = gradients[(big_j, a)];
            }
        }
    }
    g
}

/// Splits the nodes into contiguous ranges for the parallel assembly, each
/// with the elements that touch it (as [`Assembler`] does).
fn node_ranges<const D: usize>(mesh: &Mesh<D>) -> Vec<NodeRange> {
    let node_count = mesh.node_count();
    let range_count = (4 * rayon::current_num_threads())
        .min(node_count / 256)
        .max(1);
    let step = node_count.div_ceil(range_count).max(1);
    let mut ranges: Vec<NodeRange> = (0..node_count)
        .step_by(step)
        .map(|start| NodeRange {
            nodes: start..(start + step).min(node_count),
            elements: Vec::new(),
        })
        .collect();
    for e in 0..mesh.element_count() {
        let mut touched: Vec<usize> = mesh.element(e).iter().map(|&n| n / step).collect();
        touched.sort_unstable();
        touched.dedup();
        for r in touched {
            ranges[r].elements.push(e);
        }
    }
    ranges
}
