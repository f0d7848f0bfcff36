//! The forward map of the regularised estimator: marker displacements on the
//! top face in response to an axial line load along the needle,
//! $u_{markers} = G q$.
//!
//! The model is a finite-element body on the whole phantom with the fixed
//! faces clamped: a plane model (T6 triangles, plane strain or plane stress,
//! the paper's equation (4)) or a 3-D slab (Tet10, markers on the top face,
//! the needle on the mid-plane, the $G$ of the paper's equation (6)). The
//! mesh has a node on every marker and, for a straight insertion, a grid
//! line along the needle.
//!
//! A line load only ever loads the nodes of the elements the needle line
//! crosses, so the response to any density is a combination of the responses
//! to unit forces on those dofs: $G = H K_{ff}^{-1} P$, where
//! $P_{dj} = \int_0^L N_d(x(s))\,\varphi_j(s)\,\hat t\,ds$ is the consistent
//! nodal load of hat function $\varphi_j$ (`needle-fem`'s line load), and
//! $H K_{ff}^{-1}$ restricted to the loaded dofs ($H$ the marker
//! interpolation operator) is computed once per needle line, with one
//! factorisation and one solve per loaded dof.

use nalgebra::DMatrix;
use needle_data::Phantom;
use needle_fem::load::add_line_load;
use needle_fem::{
    Assembler, Dirichlet, ElementKind, Face, Formulation, LineDensity, LinearProblem, Locator,
    Material, Materials, Mesh, RectangleMesh, SlabMesh,
};
use serde::{Deserialize, Serialize};

use crate::error::ForceError;
use crate::observe::{GridIndex, MarkerLayout};
use crate::shaft::ShaftBasis;

/// Which elastic model maps shaft forces to marker displacements.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Model {
    /// The plane model of the paper's equation (4): the phantom as a 2-D
    /// body of its thickness, markers and needle in one plane.
    Plane(PlaneKind),
    /// The 3-D slab of the paper's equation (6): markers on the top face,
    /// the needle on the mid-plane. `layers` element layers through the
    /// thickness (even, so that the mid-plane is a node plane).
    Slab {
        /// Element layers through the thickness (even, at least 2).
        layers: usize,
    },
}

/// Plane strain (the paper's choice) or plane stress (a thin slab with free
/// faces).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum PlaneKind {
    /// $\varepsilon_{zz} = 0$.
    Strain,
    /// $\sigma_{zz} = 0$.
    Stress,
}

impl PlaneKind {
    /// The `needle-fem` formulation for a body of `thickness`.
    pub fn formulation(self, thickness: f64) -> Formulation {
        match self {
            PlaneKind::Strain => Formulation::PlaneStrain { thickness },
            PlaneKind::Stress => Formulation::PlaneStress { thickness },
        }
    }
}

/// The elastic material of the phantom: homogeneous, or layers across the
/// insertion direction (Fig. 15's layered phantom).
#[derive(Debug, Clone, PartialEq)]
pub enum MaterialField {
    /// One material everywhere.
    Homogeneous(Material),
    /// Layers in y: `materials[k]` holds for `boundaries[k-1] <= y < boundaries[k]`
    /// (`boundaries` ascending, one fewer than `materials`).
    LayersInY {
        /// Interfaces between layers (m), ascending.
        boundaries: Vec<f64>,
        /// One material per layer, front to back.
        materials: Vec<Material>,
    },
}

impl MaterialField {
    fn check(&self) -> Result<(), ForceError> {
        if let MaterialField::LayersInY {
            boundaries,
            materials,
        } = self
        {
            if materials.len() != boundaries.len() + 1 {
                return Err(ForceError::Mismatch(format!(
                    "{} layer boundaries need {} materials, got {}",
                    boundaries.len(),
                    boundaries.len() + 1,
                    materials.len()
                )));
            }
            if boundaries.windows(2).any(|w| w[1] <= w[0])
                || boundaries.iter().any(|b| !b.is_finite())
            {
                return Err(ForceError::Mismatch(
                    "layer boundaries must be finite and ascending".into(),
                ));
            }
        }
        Ok(())
    }

    fn region_of(&self, y: f64) -> usize {
        match self {
            MaterialField::Homogeneous(_) => 0,
            MaterialField::LayersInY { boundaries, .. } => boundaries.partition_point(|&b| b <= y),
        }
    }

    fn materials(&self) -> Materials {
        match self {
            MaterialField::Homogeneous(m) => Materials::homogeneous(*m),
            MaterialField::LayersInY { materials, .. } => Materials(materials.clone()),
        }
    }
}

/// Marker responses to unit forces on the dofs one needle line can load.
#[derive(Debug, Clone)]
pub struct ShaftResponse {
    model: Model,
    mesh: ModelMesh,
    /// Entry point of the model's needle line (rest frame, mid-plane).
    entry: [f64; 2],
    /// Unit axis of the line.
    axis: [f64; 2],
    /// Global dofs a line load on the needle can reach, ascending.
    loaded: Vec<usize>,
    /// Row `2k + c` (marker `k` of the layout, component `c`), column `i`:
    /// displacement for a unit force on dof `loaded[i]`.
    markers: DMatrix<f64>,
    /// Spacing of the samples along the needle line (m).
    line_step: f64,
    /// Row `k`: axial displacement of the needle line (mid-plane) at arc
    /// length `k * line_step` for a unit force on each loaded dof.
    line: DMatrix<f64>,
}

/// Largest spacing of the displacement samples along the needle line (m).
const LINE_SAMPLE_SPACING: f64 = 0.25e-3;

/// The model's mesh: the needle lies in the plane, or on the slab's
/// mid-plane $z = 0$.
#[derive(Debug, Clone)]
enum ModelMesh {
    Plane(Mesh<2>),
    Slab(Mesh<3>),
}

/// How the model is built.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ModelOptions {
    /// Plane or slab.
    pub model: Model,
    /// Elements per marker spacing in x and y.
    pub refinement: usize,
}

impl ModelOptions {
    /// The default plane model: plane strain, T6 on the marker grid.
    pub fn plane() -> Self {
        Self {
            model: Model::Plane(PlaneKind::Strain),
            refinement: 1,
        }
    }

    /// The default slab: Tet10 on the marker grid, two layers.
    pub fn slab() -> Self {
        Self {
            model: Model::Slab { layers: 2 },
            refinement: 1,
        }
    }
}

/// Relative size below which a consistent load entry is round-off (a shape
/// function that vanishes on the needle line).
const LOAD_ROUNDOFF: f64 = 1e-12;

impl ShaftResponse {
    /// Builds the model for a needle entering at `entry` (rest frame, on the
    /// front face) along `axis`, and solves for the responses.
    ///
    /// For a straight insertion along +y the needle line becomes a mesh grid
    /// line; when it lies within a quarter of an element of an existing line
    /// it is snapped to it (the lateral error is then below a quarter
    /// element).
    pub fn new(
        phantom: &Phantom,
        layout: &MarkerLayout,
        grid: &GridIndex,
        material: &MaterialField,
        options: ModelOptions,
        entry: [f64; 2],
        axis: [f64; 2],
    ) -> Result<Self, ForceError> {
        material.check()?;
        if options.refinement == 0 {
            return Err(ForceError::InvalidValue {
                field: "refinement",
                value: 0.0,
                reason: "must be at least 1",
            });
        }
        if phantom.fixed.is_empty() {
            return Err(ForceError::NoFixedFace);
        }
        if !(entry[0] > 0.0 && entry[0] < phantom.width) {
            return Err(ForceError::InvalidValue {
                field: "needle entry x",
                value: entry[0],
                reason: "the needle must enter through the front face, 0 < x < width",
            });
        }
        let norm = axis[0].hypot(axis[1]);
        if !(norm > 0.0 && axis[1] / norm > 1e-3) {
            return Err(ForceError::InvalidValue {
                field: "needle axis y",
                value: axis[1],
                reason: "the needle must point into the phantom (+y)",
            });
        }
        let axis = [axis[0] / norm, axis[1] / norm];
        let mut plan = RectangleMesh::with_markers(
            phantom.width,
            phantom.depth,
            &grid.marker_grid(),
            options.refinement,
        )?;
        let mut entry = [entry[0], 0.0];
        if axis[0] == 0.0 {
            entry[0] = snap_or_insert(&mut plan.x_lines, entry[0]);
        }
        // The longest shaft: to where the line leaves the phantom.
        let reach = exit_length(phantom, entry, axis);
        let end = [entry[0] + reach * axis[0], entry[1] + reach * axis[1]];
        let materials = material.materials();
        let fixed: Vec<Face> = phantom.fixed.iter().map(|&f| fem_face(f)).collect();
        let samples = (reach / LINE_SAMPLE_SPACING).ceil() as usize;
        let line_step = reach / samples as f64;
        let on_line: Vec<[f64; 2]> = (0..=samples)
            .map(|k| {
                [
                    entry[0] + k as f64 * line_step * axis[0],
                    k as f64 * line_step * axis[1],
                ]
            })
            .collect();
        let (mesh, loaded, markers) = match options.model {
            Model::Plane(kind) => {
                let mut mesh = plan.build(ElementKind::Tri6)?;
                mesh.assign_regions(|c| material.region_of(c[1]));
                let formulation = kind.formulation(phantom.thickness);
                let points: Vec<[f64; 2]> = layout.rest.iter().chain(&on_line).copied().collect();
                let (loaded, markers) =
                    unit_responses(&mesh, formulation, &materials, &fixed, &points, entry, end)?;
                (ModelMesh::Plane(mesh), loaded, markers)
            }
            Model::Slab { layers } => {
                if layers < 2 || layers % 2 != 0 {
                    return Err(ForceError::InvalidValue {
                        field: "slab layers",
                        value: layers as f64,
                        reason: "must be even and at least 2, so that the needle's mid-plane is a node plane",
                    });
                }
                let top = 0.5 * phantom.thickness;
                let mut mesh =
                    SlabMesh::new(plan, phantom.thickness, layers)?.build(ElementKind::Tet10)?;
                mesh.assign_regions(|c| material.region_of(c[1]));
                let points: Vec<[f64; 3]> = layout
                    .rest
                    .iter()
                    .map(|p| [p[0], p[1], top])
                    .chain(on_line.iter().map(|p| [p[0], p[1], 0.0]))
                    .collect();
                let (start, end) = ([entry[0], entry[1], 0.0], [end[0], end[1], 0.0]);
                let (loaded, markers) = unit_responses(
                    &mesh,
                    Formulation::Solid,
                    &materials,
                    &fixed,
                    &points,
                    start,
                    end,
                )?;
                (ModelMesh::Slab(mesh), loaded, markers)
            }
        };
        // Split the needle-line rows off and project them on the axis.
        let marker_rows = 2 * layout.len();
        let line = DMatrix::from_fn(samples + 1, loaded.len(), |k, i| {
            axis[0] * markers[(marker_rows + 2 * k, i)]
                + axis[1] * markers[(marker_rows + 2 * k + 1, i)]
        });
        let markers = markers.rows(0, marker_rows).into_owned();
        Ok(Self {
            model: options.model,
            mesh,
            entry,
            axis,
            loaded,
            markers,
            line_step,
            line,
        })
    }

    /// The model this response was built with.
    pub fn model(&self) -> Model {
        self.model
    }

    /// Entry point of the model's needle line (m).
    pub fn entry(&self) -> [f64; 2] {
        self.entry
    }

    /// Unit axis of the model's needle line.
    pub fn axis(&self) -> [f64; 2] {
        self.axis
    }

    /// Number of marker rows (twice the number of markers).
    pub fn marker_rows(&self) -> usize {
        self.markers.nrows()
    }

    /// The consistent-load matrix $P$ (loaded dofs x basis functions): the
    /// nodal loads of each hat function applied as an axial line load from
    /// the entry, computed by `needle-fem`.
    pub fn consistent_loads(&self, basis: &ShaftBasis) -> Result<DMatrix<f64>, ForceError> {
        let (entry, axis) = (self.entry, self.axis);
        let length = basis.length();
        let tip = [entry[0] + length * axis[0], entry[1] + length * axis[1]];
        let mut p = DMatrix::zeros(self.loaded.len(), basis.len());
        for j in 0..basis.len() {
            let column = match &self.mesh {
                ModelMesh::Plane(mesh) => {
                    let density = (0..basis.len())
                        .map(|k| if k == j { axis } else { [0.0; 2] })
                        .collect();
                    line_load(mesh, entry, tip, &basis.stations, density)?
                }
                ModelMesh::Slab(mesh) => {
                    let density = (0..basis.len())
                        .map(|k| {
                            if k == j {
                                [axis[0], axis[1], 0.0]
                            } else {
                                [0.0; 3]
                            }
                        })
                        .collect();
                    line_load(
                        mesh,
                        [entry[0], entry[1], 0.0],
                        [tip[0], tip[1], 0.0],
                        &basis.stations,
                        density,
                    )?
                }
            };
            let total: f64 = column.iter().map(|v| v.abs()).sum();
            let mut kept = 0.0;
            for (i, &dof) in self.loaded.iter().enumerate() {
                p[(i, j)] = column[dof];
                kept += column[dof].abs();
            }
            if total - kept > 1e-9 * total {
                return Err(ForceError::BadShaft {
                    length,
                    reason: "the shaft leaves the needle line the model was prepared for",
                });
            }
        }
        Ok(p)
    }

    /// $G = H K_{ff}^{-1} P$: marker displacements (rows `2k + c`) per unit
    /// station value of the density.
    pub fn response_matrix(&self, basis: &ShaftBasis) -> Result<DMatrix<f64>, ForceError> {
        Ok(&self.markers * self.consistent_loads(basis)?)
    }

    /// The axial displacement of the needle line (mid-plane) at arc length
    /// `s`, per unit station value: a row to multiply with the station
    /// values (linear between samples 0.25 mm apart).
    pub fn line_displacement_row(
        &self,
        basis: &ShaftBasis,
        s: f64,
    ) -> Result<nalgebra::RowDVector<f64>, ForceError> {
        let last = self.line.nrows() - 1;
        let position = (s / self.line_step).clamp(0.0, last as f64);
        let k = (position.floor() as usize).min(last.saturating_sub(1));
        let w = position - k as f64;
        let row = self.line.row(k) * (1.0 - w) + self.line.row((k + 1).min(last)) * w;
        Ok(row * self.consistent_loads(basis)?)
    }

    /// Marker displacements (rows `2k + c`) for station values `values`.
    pub fn predict(&self, basis: &ShaftBasis, values: &[f64]) -> Result<Vec<f64>, ForceError> {
        if values.len() != basis.len() {
            return Err(ForceError::Mismatch(format!(
                "{} station values for {} stations",
                values.len(),
                basis.len()
            )));
        }
        let q = nalgebra::DVector::from_column_slice(values);
        Ok((self.response_matrix(basis)? * q).iter().copied().collect())
    }
}

/// The full load vector of a sampled line density from `start` to `end`.
fn line_load<const D: usize>(
    mesh: &Mesh<D>,
    start: [f64; D],
    end: [f64; D],
    stations: &[f64],
    density: Vec<[f64; D]>,
) -> Result<Vec<f64>, ForceError> {
    let mut loads = vec![0.0; mesh.dof_count()];
    let sampled = LineDensity::Sampled {
        arclength: stations.to_vec(),
        density,
    };
    add_line_load(&Locator::new(mesh), &mut loads, start, end, &sampled)?;
    Ok(loads)
}

/// Length from `entry` along `axis` to where the line leaves the phantom.
fn exit_length(phantom: &Phantom, entry: [f64; 2], axis: [f64; 2]) -> f64 {
    let mut reach = (phantom.depth - entry[1]) / axis[1];
    if axis[0] > 0.0 {
        reach = reach.min((phantom.width - entry[0]) / axis[0]);
    } else if axis[0] < 0.0 {
        reach = reach.min(-entry[0] / axis[0]);
    }
    reach
}

/// Factorises the clamped model, finds the dofs a line load from `start` to
/// `end` reaches, and returns them with the marker displacements (markers
/// interpolated at `points`) for a unit force on each.
fn unit_responses<const D: usize>(
    mesh: &Mesh<D>,
    formulation: Formulation,
    materials: &Materials,
    fixed: &[Face],
    points: &[[f64; D]],
    start: [f64; D],
    end: [f64; D],
) -> Result<(Vec<usize>, DMatrix<f64>), ForceError> {
    let locator = Locator::new(mesh);
    let mut reach = vec![0.0; mesh.dof_count()];
    let constant = |_: f64| -> [f64; D] { [1.0; D] };
    add_line_load(
        &locator,
        &mut reach,
        start,
        end,
        &LineDensity::Function {
            density: &constant,
            breakpoints: vec![],
        },
    )?;
    let largest = reach.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let mut dirichlet = Dirichlet::new();
    for &face in fixed {
        dirichlet.fix_nodes(mesh, &mesh.nodes_on_face(face))?;
    }
    let loaded: Vec<usize> = (0..reach.len())
        .filter(|&d| reach[d].abs() > LOAD_ROUNDOFF * largest && !dirichlet.contains(d))
        .collect();
    let interpolation = locator.interpolation_matrix(points, &[0, 1])?;
    let mut problem = LinearProblem::new(
        Assembler::new(mesh.clone(), formulation)?,
        Vec::new(),
        dirichlet,
    )?;
    problem.factorize(materials)?;
    let mut columns = faer::Mat::<f64>::zeros(problem.free_dofs().len(), loaded.len());
    for (i, &dof) in loaded.iter().enumerate() {
        if let Some(k) = problem.reduced_index(dof) {
            columns[(k, i)] = 1.0;
        }
    }
    problem.solve_reduced_in_place(columns.as_mut())?;
    // Row r of H K^-1 restricted to the loaded dofs.
    let mut markers = DMatrix::zeros(interpolation.nrows(), loaded.len());
    for dof in 0..interpolation.ncols() {
        let Some(k) = problem.reduced_index(dof) else {
            continue;
        };
        for (&row, &w) in interpolation
            .row_idx_of_col_raw(dof)
            .iter()
            .zip(interpolation.val_of_col(dof))
        {
            for i in 0..loaded.len() {
                markers[(row, i)] += w * columns[(k, i)];
            }
        }
    }
    Ok((loaded, markers))
}

/// Puts the needle on a grid line: the nearest existing line when it lies
/// within a quarter of the neighbouring elements, otherwise a new line.
fn snap_or_insert(lines: &mut Vec<f64>, x: f64) -> f64 {
    let k = lines.partition_point(|&l| l < x);
    let nearest = [k.wrapping_sub(1), k]
        .into_iter()
        .filter(|&i| i < lines.len())
        .min_by(|&a, &b| (lines[a] - x).abs().total_cmp(&(lines[b] - x).abs()));
    if let Some(i) = nearest {
        let h = if i + 1 < lines.len() {
            lines[i + 1] - lines[i]
        } else {
            lines[i] - lines[i - 1]
        };
        if (lines[i] - x).abs() <= 0.25 * h {
            return lines[i];
        }
    }
    lines.insert(k, x);
    x
}

/// The bundle's face as `needle-fem`'s.
pub(crate) fn fem_face(face: needle_data::Face) -> Face {
    match face {
        needle_data::Face::Front => Face::Front,
        needle_data::Face::Back => Face::Back,
        needle_data::Face::Left => Face::Left,
        needle_data::Face::Right => Face::Right,
    }
}
