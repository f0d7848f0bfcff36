//! The forward model of a probing experiment: the phantom's top face as a
//! 2-D finite-element mesh on the marker grid, the fixed faces, the probe
//! load points on the boundary, and the map from material parameters to
//! marker displacements per unit probe force,
//!
//! $$G_{l,c}(\theta) = H\,K(\theta)^{-1} b_{l,c},$$
//!
//! where $b_{l,c}$ is a unit force in direction $c$ at load point $l$
//! (distributed to the nodes by the shape functions at that point:
//! `needle-fem`'s consistent point force) and $H$ interpolates nodal displacements at the markers. The
//! sensitivities follow from differentiating $K U = B$:
//! $\partial U/\partial p = -K^{-1}\,(\partial K/\partial p)\,U$.
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
use needle_fem::element::ElementKind;
use needle_fem::load::add_point_force;
use needle_fem::locate::{Locator, NodeWeights};
use needle_fem::material::{Formulation, Materials, Parameter};
use needle_fem::mesh::{Face, MarkerGrid, Mesh2, RectangleMesh};
use needle_fem::solve::LinearProblem;

use crate::error::IdentifyError;
use crate::options::{PlaneModel, Regions};
use crate::probe::ProbeSetup;

/// How deep inside (or far outside) the phantom a probe tip may be, as a
/// fraction of the smaller side, and still count as pressing on the
/// boundary.
const MAX_TIP_OFFSET_FRACTION: f64 = 0.2;

/// The model choices that shape the mesh.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelSpec {
    /// Element kind (Tri3 or Tri6).
    pub element: ElementKind,
    /// Plane strain or plane stress.
    pub plane: PlaneModel,
    /// Mesh lines per marker spacing.
    pub refinement: usize,
    /// Material regions.
    pub regions: Regions,
}

/// The probing forward model (see the module doc).
#[derive(Debug)]
pub struct ProbeModel {
    /// The constrained system with its kept factorisation, and the
    /// materials it was last factorised at.
    system: Mutex<(LinearProblem<2>, Option<Materials>)>,
    mesh: Mesh2,
    markers: Vec<NodeWeights>,
    /// Unit loads, `loads[2 l + c]` a unit force along axis `c` at load
    /// point `l` as a full dof vector.
    loads: Vec<Vec<f64>>,
    load_points: Vec<[f64; 2]>,
    region_count: usize,
    marker_spacing: f64,
}

/// The model's response at one set of materials: the unit-load solutions.
pub struct Response {
    /// `unit[2 l + c]`: nodal displacements under a unit force along axis
    /// `c` at load point `l`.
    unit: Vec<Vec<f64>>,
    /// `markers[2 l + c]`: marker displacements (interleaved x, y per
    /// marker) of the same unit load, $G_{l,c}$.
    pub markers: Vec<Vec<f64>>,
}

impl ProbeModel {
    /// Builds the mesh on the markers of `setup`, the fixed dofs, the
    /// interpolation at the markers and the loads at `load_points` (each
    /// already on the boundary, see [`project_to_boundary`]).
    pub fn new(
        setup: &ProbeSetup,
        load_points: &[[f64; 2]],
        spec: &ModelSpec,
    ) -> Result<Self, IdentifyError> {
        let (mut plan, marker_spacing) = plan_mesh(setup, spec.refinement)?;
        if let Regions::LayersY { boundaries } = &spec.regions {
            insert_lines(&mut plan.y_lines, boundaries, setup.depth)?;
        }
        let mut mesh: Mesh2 = plan.build(spec.element)?;
        let regions = spec.regions.clone();
        mesh.assign_regions(|c| regions.region_of(c[1]));
        let region_count = spec.regions.count();
        if mesh.region_count() != region_count {
            return Err(IdentifyError::Inconsistent(format!(
                "options.regions: {region_count} regions requested but the mesh has elements in {} (is every layer inside the phantom?)",
                mesh.region_count()
            )));
        }
        let formulation = match spec.plane {
            PlaneModel::Strain => Formulation::PlaneStrain {
                thickness: setup.thickness,
            },
            PlaneModel::Stress => Formulation::PlaneStress {
                thickness: setup.thickness,
            },
        };
        let locator = Locator::new(&mesh);
        let weights_at = |what: &str, index: usize, p: [f64; 2]| {
            locator.weights(p).ok_or_else(|| {
                IdentifyError::Inconsistent(format!(
                    "{what} {index} at ({}, {}) m lies outside the mesh",
                    p[0], p[1]
                ))
            })
        };
        let markers = setup
            .markers
            .iter()
            .enumerate()
            .map(|(i, &p)| weights_at("marker", i, p))
            .collect::<Result<Vec<_>, _>>()?;
        let mut loads = Vec::with_capacity(2 * load_points.len());
        for (i, &p) in load_points.iter().enumerate() {
            for c in 0..2 {
                let mut force = [0.0; 2];
                force[c] = 1.0;
                let mut load = vec![0.0; mesh.dof_count()];
                add_point_force(&locator, &mut load, p, force).map_err(|_| {
                    IdentifyError::Inconsistent(format!(
                        "load point {i} at ({}, {}) m lies outside the mesh",
                        p[0], p[1]
                    ))
                })?;
                loads.push(load);
            }
        }
        let mut dirichlet = Dirichlet::new();
        for &face in &setup.fixed {
            dirichlet.fix_nodes(&mesh, &mesh.nodes_on_face(face))?;
        }
        let system = LinearProblem::new(
            Assembler::new(mesh.clone(), formulation)?,
            Vec::new(),
            dirichlet,
        )?;
        Ok(Self {
            system: Mutex::new((system, None)),
            mesh,
            markers,
            loads,
            load_points: load_points.to_vec(),
            region_count,
            marker_spacing,
        })
    }

    /// The mesh.
    pub fn mesh(&self) -> &Mesh2 {
        &self.mesh
    }

    /// Number of material regions.
    pub fn region_count(&self) -> usize {
        self.region_count
    }

    /// Number of markers.
    pub fn marker_count(&self) -> usize {
        self.markers.len()
    }

    /// The load points.
    pub fn load_points(&self) -> &[[f64; 2]] {
        &self.load_points
    }

    /// Typical distance between neighbouring markers (m).
    pub fn marker_spacing(&self) -> f64 {
        self.marker_spacing
    }

    /// Solves for every unit load at `materials` (one numeric Cholesky
    /// factorisation, `2 x load points` right-hand sides).
    pub fn respond(&self, materials: &Materials) -> Result<Response, IdentifyError> {
        let mut guard = self.system.lock().map_err(|_| poisoned())?;
        let (system, factored_at) = &mut *guard;
        factorize(system, factored_at, materials)?;
        let loads: Vec<&[f64]> = self.loads.iter().map(Vec::as_slice).collect();
        let unit: Vec<Vec<f64>> = system
            .solve_many(&loads)?
            .into_iter()
            .map(|s| s.displacement)
            .collect();
        let markers = unit.iter().map(|u| self.at_markers(u)).collect();
        Ok(Response { unit, markers })
    }

    /// Marker-level sensitivities $H\,\partial U/\partial p$ of every unit
    /// response. With `tied` the parameters are one modulus shared by every
    /// region and $\nu$ (then $K \propto E$ and $\partial U/\partial E = -U/E$,
    /// no solve needed); otherwise $E_0, \dots, E_{R-1}, \nu$.
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
    /// system factorised at `materials`.
    fn solution_derivative(
        &self,
        system: &LinearProblem<2>,
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

    /// Interpolates a nodal field at the markers (x, y interleaved).
    fn at_markers(&self, field: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; 2 * self.markers.len()];
        for (m, weights) in self.markers.iter().enumerate() {
            for &(n, w) in weights {
                out[2 * m] += w * field[2 * n];
                out[2 * m + 1] += w * field[2 * n + 1];
            }
        }
        out
    }
}

/// Factorises `system` at `materials` unless it already is.
fn factorize(
    system: &mut LinearProblem<2>,
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

/// The point of the phantom's boundary where a probe with its tip at `tip`
/// loads it: the nearest point of the nearest side face. Fails when the tip
/// is far from every side (deeper than a fifth of the smaller side) or when
/// the nearest side is fixed (a load there moves nothing).
pub fn project_to_boundary(setup: &ProbeSetup, tip: [f64; 2]) -> Result<[f64; 2], &'static str> {
    let (w, d) = (setup.width, setup.depth);
    let clamped = [tip[0].clamp(0.0, w), tip[1].clamp(0.0, d)];
    let outside = (tip[0] - clamped[0]).hypot(tip[1] - clamped[1]);
    let sides = [
        (Face::Left, clamped[0], [0.0, clamped[1]]),
        (Face::Right, w - clamped[0], [w, clamped[1]]),
        (Face::Front, clamped[1], [clamped[0], 0.0]),
        (Face::Back, d - clamped[1], [clamped[0], d]),
    ];
    let (face, depth, point) = sides
        .into_iter()
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((Face::Front, 0.0, clamped));
    let limit = MAX_TIP_OFFSET_FRACTION * w.min(d);
    if outside > limit {
        return Err("outside the phantom, away from every face");
    }
    if depth > limit {
        return Err("too deep inside the phantom for a probe pressing on the boundary");
    }
    if setup.fixed.contains(&face) {
        return Err("nearest to a fixed face, where a load moves nothing");
    }
    // A load at a corner shared with a fixed face would be absorbed too.
    let tol = 1e-9 * w.max(d);
    let on_fixed = setup.fixed.iter().any(|&f| match f {
        Face::Left => point[0] <= tol,
        Face::Right => point[0] >= w - tol,
        Face::Front => point[1] <= tol,
        Face::Back => point[1] >= d - tol,
        Face::Top | Face::Bottom => false,
    });
    if on_fixed {
        return Err("at a corner of a fixed face, where a load moves nothing");
    }
    Ok(point)
}

/// The rectangle mesh plan: on the marker grid when the markers form a full
/// rectangular grid (so the markers are nodes), otherwise a uniform grid of
/// about the markers' spacing that contains them (they are interpolated).
/// Also returns the typical marker spacing.
fn plan_mesh(setup: &ProbeSetup, refinement: usize) -> Result<(RectangleMesh, f64), IdentifyError> {
    let (w, d) = (setup.width, setup.depth);
    if let Some(grid) = recover_grid(&setup.markers, w.max(d)) {
        let spacing = |v: &[f64]| {
            v.windows(2)
                .map(|p| p[1] - p[0])
                .fold(f64::INFINITY, f64::min)
        };
        let marker_spacing = spacing(&grid.x).min(spacing(&grid.y));
        if marker_spacing.is_finite() {
            return Ok((
                RectangleMesh::with_markers(w, d, &grid, refinement)?,
                marker_spacing,
            ));
        }
    }
    let marker_spacing = (w * d / setup.markers.len() as f64).sqrt();
    let cells = |extent: f64| ((extent / marker_spacing).round().max(1.0) as usize) * refinement;
    Ok((
        RectangleMesh::uniform(w, d, cells(w), cells(d))?,
        marker_spacing,
    ))
}

/// The distinct x and y coordinates of markers that form a full grid (every
/// combination present exactly once), within a relative tolerance of
/// $10^{-9}$ of the phantom size.
fn recover_grid(markers: &[[f64; 2]], size: f64) -> Option<MarkerGrid> {
    let tol = 1e-9 * size;
    let lines = |axis: usize| {
        let mut v: Vec<f64> = markers.iter().map(|m| m[axis]).collect();
        v.sort_by(f64::total_cmp);
        v.dedup_by(|a, b| (*a - *b).abs() <= tol);
        v
    };
    let (x, y) = (lines(0), lines(1));
    if x.len() < 2 || y.len() < 2 || x.len() * y.len() != markers.len() {
        return None;
    }
    let index = |v: &[f64], value: f64| v.iter().position(|&l| (l - value).abs() <= tol);
    let mut seen = vec![false; markers.len()];
    for m in markers {
        let cell = index(&y, m[1])? * x.len() + index(&x, m[0])?;
        if std::mem::replace(&mut seen[cell], true) {
            return None;
        }
    }
    Some(MarkerGrid { x, y })
}

/// Adds the layer interfaces to the mesh lines in y.
fn insert_lines(lines: &mut Vec<f64>, boundaries: &[f64], depth: f64) -> Result<(), IdentifyError> {
    let tol = 1e-9 * depth;
    for &b in boundaries {
        if !(b > tol && b < depth - tol) {
            return Err(IdentifyError::InvalidValue {
                field: "options.regions.boundaries",
                value: b,
                reason: "a layer interface must lie strictly inside the phantom",
            });
        }
        if lines.iter().all(|&l| (l - b).abs() > tol) {
            lines.push(b);
        }
    }
    lines.sort_by(f64::total_cmp);
    Ok(())
}
