//! The finite-element side of the probing model in `D` dimensions (the
//! plane mesh, `D = 2`, or the slab, `D = 3`): the constrained stiffness
//! system with its kept factorisation, the solution for unit loads (built
//! by the caller, `crate::model`), and the marker interpolation $H$, which reads the in-plane components $(u_x, u_y)$ of
//! the field at each marker.
//!
//! The fixed faces are eliminated and the stiffness pattern and its
//! symbolic Cholesky factorisation are built once (`needle-fem`'s
//! [`LinearProblem`]); each evaluation assembles values into the same
//! pattern and refactors numerically, and the sensitivities reuse the
//! factor of the residual evaluation at the same point.

use std::sync::Mutex;

use faer::sparse::SparseColMat;
use needle_fem::assemble::{Assembler, multiply};
use needle_fem::dirichlet::Dirichlet;
use needle_fem::locate::NodeWeights;
use needle_fem::material::{Formulation, Materials, Parameter};
use needle_fem::mesh::{Face, Mesh};
use needle_fem::solve::LinearProblem;

use crate::error::IdentifyError;

/// The model's response at one set of materials: the unit-load solutions.
pub struct Response {
    /// `unit[2 l + c]`: nodal displacements (all `D` components) under a
    /// unit force along axis `c` at load point `l` (spread over the
    /// punch's patch, or at the point).
    unit: Vec<Vec<f64>>,
    /// `markers[2 l + c]`: marker displacements (interleaved x, y per
    /// marker) of the same unit load, $G_{l,c}$.
    pub markers: Vec<Vec<f64>>,
}

/// A constrained linear elastic system with its unit loads and markers.
#[derive(Debug)]
pub(crate) struct FeSystem<const D: usize> {
    /// The system and the materials it was last factorised at.
    system: Mutex<(LinearProblem<D>, Option<Materials>)>,
    /// The mesh, to place loads on (the system keeps its own).
    mesh: Mesh<D>,
    /// Shape-function weights of every marker.
    markers: Vec<NodeWeights>,
    region_count: usize,
}

impl<const D: usize> FeSystem<D> {
    /// Sets up the system on `mesh` with every node of the `fixed` faces
    /// held, and the last component (z) of every node of the `symmetry`
    /// face (a mirror plane of the body and its loads).
    pub fn new(
        mesh: Mesh<D>,
        formulation: Formulation,
        fixed: &[Face],
        symmetry: Option<Face>,
        markers: Vec<NodeWeights>,
    ) -> Result<Self, IdentifyError> {
        let mut dirichlet = Dirichlet::new();
        for &face in fixed {
            dirichlet.fix_nodes(&mesh, &mesh.nodes_on_face(face))?;
        }
        if let Some(face) = symmetry {
            dirichlet.set_nodes(&mesh, &mesh.nodes_on_face(face), D - 1, 0.0)?;
        }
        let region_count = mesh.region_count();
        let system = LinearProblem::new(
            Assembler::new(mesh.clone(), formulation)?,
            Vec::new(),
            dirichlet,
        )?;
        Ok(Self {
            system: Mutex::new((system, None)),
            mesh,
            markers,
            region_count,
        })
    }

    /// The mesh.
    pub fn mesh(&self) -> &Mesh<D> {
        &self.mesh
    }

    /// Nodes and elements of the mesh.
    pub fn size(&self) -> (usize, usize) {
        (self.mesh.node_count(), self.mesh.element_count())
    }

    /// Solves for every unit load (full dof vectors, `loads[2 l + c]`) at
    /// `materials` (one numeric Cholesky factorisation, one
    /// back-substitution per load).
    pub fn respond(
        &self,
        materials: &Materials,
        loads: &[Vec<f64>],
    ) -> Result<Response, IdentifyError> {
        let unit = self.solve(materials, loads)?;
        let markers = unit.iter().map(|u| self.at_markers(u)).collect();
        Ok(Response { unit, markers })
    }

    /// The marker displacements of `loads` at `materials`.
    pub fn marker_response(
        &self,
        materials: &Materials,
        loads: &[Vec<f64>],
    ) -> Result<Vec<Vec<f64>>, IdentifyError> {
        Ok(self
            .solve(materials, loads)?
            .iter()
            .map(|u| self.at_markers(u))
            .collect())
    }

    /// The nodal displacements of `loads` at `materials`.
    fn solve(
        &self,
        materials: &Materials,
        loads: &[Vec<f64>],
    ) -> Result<Vec<Vec<f64>>, IdentifyError> {
        let mut guard = self.system.lock().map_err(|_| poisoned())?;
        let (system, factored_at) = &mut *guard;
        factorize(system, factored_at, materials)?;
        let loads: Vec<&[f64]> = loads.iter().map(Vec::as_slice).collect();
        Ok(system
            .solve_many(&loads)?
            .into_iter()
            .map(|s| s.displacement)
            .collect())
    }

    /// Marker-level sensitivities $H\,\partial U/\partial p$ of every unit
    /// response; see [`crate::ProbeModel::sensitivities`].
    pub fn sensitivities(
        &self,
        materials: &Materials,
        response: &Response,
        tied: bool,
    ) -> Result<Vec<Vec<Vec<f64>>>, IdentifyError> {
        let mut guard = self.system.lock().map_err(|_| poisoned())?;
        let (system, factored_at) = &mut *guard;
        factorize(system, factored_at, materials)?;
        let assembler = system.assembler();
        let mut out = Vec::with_capacity(self.region_count + 1);
        if tied {
            let e = materials.0[0].youngs_modulus();
            out.push(
                response
                    .markers
                    .iter()
                    .map(|g| g.iter().map(|x| -x / e).collect())
                    .collect(),
            );
        } else {
            for r in 0..self.region_count {
                let derivative =
                    assembler.stiffness_derivative(materials, Parameter::YoungsModulus, Some(r))?;
                out.push(self.solution_derivative(system, &derivative, response)?);
            }
        }
        let derivative =
            assembler.stiffness_derivative(materials, Parameter::PoissonRatio, None)?;
        out.push(self.solution_derivative(system, &derivative, response)?);
        Ok(out)
    }

    /// $-H K^{-1} (\partial K/\partial p)\,U$ for every unit load, with the
    /// system factorised at the materials of `response`.
    fn solution_derivative(
        &self,
        system: &LinearProblem<D>,
        derivative: &SparseColMat<usize, f64>,
        response: &Response,
    ) -> Result<Vec<Vec<f64>>, IdentifyError> {
        let rhs: Vec<Vec<f64>> = response
            .unit
            .iter()
            .map(|u| multiply(derivative, u).into_iter().map(|v| -v).collect())
            .collect();
        let rhs: Vec<&[f64]> = rhs.iter().map(Vec::as_slice).collect();
        Ok(system
            .solve_many(&rhs)?
            .into_iter()
            .map(|s| self.at_markers(&s.displacement))
            .collect())
    }

    /// Interpolates the in-plane components of a nodal field at the markers
    /// (x, y interleaved).
    fn at_markers(&self, field: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; 2 * self.markers.len()];
        for (m, weights) in self.markers.iter().enumerate() {
            for &(n, w) in weights {
                out[2 * m] += w * field[D * n];
                out[2 * m + 1] += w * field[D * n + 1];
            }
        }
        out
    }
}

/// Factorises `system` at `materials` unless it already is.
fn factorize<const D: usize>(
    system: &mut LinearProblem<D>,
    factored_at: &mut Option<Materials>,
    materials: &Materials,
) -> Result<(), IdentifyError> {
    if factored_at.as_ref() != Some(materials) {
        *factored_at = None;
        system.factorize(materials)?;
        *factored_at = Some(materials.clone());
    }
    Ok(())
}

fn poisoned() -> IdentifyError {
    IdentifyError::Factorization("a previous evaluation panicked while holding the system".into())
}
