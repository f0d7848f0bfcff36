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
//! The needle holds tissue that is dragged sideways by a fraction of a
//! millimetre, so the load may act anywhere in a band of one element around
//! the needle line (on the slab's mid-plane). The response to any load is
//! a combination of the responses to unit axial forces on the band's nodes:
//! $G = H K_{ff}^{-1} P$, with $P$ the nodal loads of the placed density
//! ([`ShaftResponse::point_loads`] for point forces at material points,
//! [`ShaftResponse::consistent_loads`] for `needle-fem`'s line load on the
//! straight line) and $H K_{ff}^{-1}$ restricted to the band's nodes ($H$
//! the marker interpolation operator) computed once per needle line, one
//! factorisation and one solve per loaded dof. The band's own displacements
//! are kept too: they place the load of the next round.
//!
//! The slab and its loads are symmetric about the mid-plane, so the slab
//! is meshed as the upper half of needle-fem's mirrored slab
//! (`SlabMesh::build_upper_half`), $u_z = 0$ held on $z = 0$, and a unit
//! force on a mid-plane node is half a unit on the half: the mirrored
//! whole slab's responses exactly (needle-fem's test
//! `upper_half_of_the_mirrored_slab_gives_its_displacement`), on three node
//! planes of five for two layers.

use nalgebra::{DMatrix, DVector};
use needle_data::Phantom;
use needle_fem::load::add_line_load;
use needle_fem::{
    Assembler, Dirichlet, ElementKind, Face, Formulation, LineDensity, LinearProblem, Locator,
    Material, Materials, Mesh, RectangleMesh, SlabMesh,
};
use serde::{Deserialize, Serialize};

use crate::error::ForceError;
use crate::observe::{GridIndex, MarkerLayout};
use crate::place::LoadPoint;
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

/// Marker responses to unit axial forces on the mid-plane nodes of a band
/// around one needle line, and the band's own response to them.
#[derive(Debug, Clone)]
pub struct ShaftResponse {
    model: Model,
    mesh: ModelMesh,
    /// Entry point of the model's needle line (rest frame, mid-plane).
    entry: [f64; 2],
    /// Unit axis of the line.
    axis: [f64; 2],
    /// Global dofs an axial load in the band can reach: the band nodes'
    /// in-plane components along which the axis has a component.
    loaded: Vec<usize>,
    /// Position of every global dof in `loaded` (`usize::MAX` if absent).
    loaded_slot: Vec<usize>,
    /// Position of every global dof among the band's in-plane dofs, the
    /// rows of `band` (`usize::MAX` if absent).
    band_slot: Vec<usize>,
    /// Row `2k + c` (marker `k` of the layout, component `c`), column `i`:
    /// displacement for a unit force on dof `loaded[i]`.
    markers: DMatrix<f64>,
    /// The band's in-plane displacements (rows in `band_slot` order) for a
    /// unit force on each loaded dof.
    band: DMatrix<f64>,
}

/// Half-width of the band around the needle line that loads may reach and
/// displacements are read in, in elements: the tissue the needle holds is
/// dragged sideways by a fraction of a millimetre.
const BAND_ELEMENTS: f64 = 1.0;

/// A needle line within this fraction of an element of a mesh line is put
/// on it; otherwise a mesh line is inserted along the needle.
const SNAP_FRACTION: f64 = 0.05;

/// Shape-function weights below this are round-off (a node of a
/// neighbouring element that the point only touches).
const WEIGHT_ROUNDOFF: f64 = 1e-10;

/// The model's mesh: the needle lies in the plane, or on the slab's
/// mid-plane $z = 0$.
#[derive(Debug, Clone)]
enum ModelMesh {
    Plane(Mesh<2>),
    Slab(Mesh<3>),
}

impl ModelMesh {
    /// Dofs per node.
    fn dimension(&self) -> usize {
        match self {
            ModelMesh::Plane(_) => 2,
            ModelMesh::Slab(_) => 3,
        }
    }

    /// A locator over the mesh.
    fn locator(&self) -> PlaneLocator<'_> {
        match self {
            ModelMesh::Plane(mesh) => PlaneLocator::Plane(Locator::new(mesh)),
            ModelMesh::Slab(mesh) => PlaneLocator::Slab(Locator::new(mesh)),
        }
    }
}

/// Point location in the needle's plane (the slab's mid-plane).
enum PlaneLocator<'a> {
    Plane(Locator<'a, 2>),
    Slab(Locator<'a, 3>),
}

impl PlaneLocator<'_> {
    /// Shape-function weights `(node, N)` at a point of the needle's plane,
    /// round-off weights dropped.
    fn weights(&self, point: [f64; 2]) -> Result<Vec<(usize, f64)>, ForceError> {
        let weights = match self {
            PlaneLocator::Plane(l) => l.weights(point),
            PlaneLocator::Slab(l) => l.weights([point[0], point[1], 0.0]),
        };
        let weights = weights.ok_or(ForceError::BadShaft {
            length: point[1],
            reason: "a loaded material point lies outside the phantom",
        })?;
        Ok(weights
            .into_iter()
            .filter(|w| w.1.abs() > WEIGHT_ROUNDOFF)
            .collect())
    }
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
    /// front face) along `axis`, and solves for the responses to unit forces
    /// on the mid-plane nodes within one element of that line.
    ///
    /// For a straight insertion along +y the needle line becomes a mesh grid
    /// line: an existing one when it lies within 5% of an element of it,
    /// otherwise a line inserted along the needle.
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
        let halfwidth = BAND_ELEMENTS * grid.spacing() / options.refinement as f64;
        let materials = material.materials();
        let fixed: Vec<Face> = phantom.fixed.iter().map(|&f| fem_face(f)).collect();
        let (mesh, band_nodes) = match options.model {
            Model::Plane(_) => {
                let mut mesh = plan.build(ElementKind::Tri6)?;
                mesh.assign_regions(|c| material.region_of(c[1]));
                let nodes = band_nodes(&mesh, entry, axis, halfwidth, |_| true);
                (ModelMesh::Plane(mesh), nodes)
            }
            Model::Slab { layers } => {
                if layers < 2 || layers % 2 != 0 {
                    return Err(ForceError::InvalidValue {
                        field: "slab layers",
                        value: layers as f64,
                        reason: "must be even and at least 2, so that the needle's mid-plane is a node plane",
                    });
                }
                let mut mesh = SlabMesh::new(plan, phantom.thickness, layers)?
                    .build_upper_half(ElementKind::Tet10)?;
                mesh.assign_regions(|c| material.region_of(c[1]));
                let tolerance = 1e-9 * phantom.thickness;
                let nodes = band_nodes(&mesh, entry, axis, halfwidth, |x| x[2].abs() <= tolerance);
                (ModelMesh::Slab(mesh), nodes)
            }
        };
        let dimension = mesh.dimension();
        let in_plane: Vec<usize> = band_nodes
            .iter()
            .flat_map(|&n| [n * dimension, n * dimension + 1])
            .collect();
        let loaded: Vec<usize> = band_nodes
            .iter()
            .flat_map(|&n| {
                (0..2)
                    .filter(|&c| axis[c] != 0.0)
                    .map(move |c| n * dimension + c)
            })
            .collect();
        let (markers, band) = match &mesh {
            ModelMesh::Plane(m) => {
                let Model::Plane(kind) = options.model else {
                    unreachable!("a plane mesh comes from a plane model")
                };
                let formulation = kind.formulation(phantom.thickness);
                unit_responses(
                    m,
                    formulation,
                    &materials,
                    &fixed,
                    &layout.rest,
                    &loaded,
                    &in_plane,
                    Span::Whole,
                )?
            }
            ModelMesh::Slab(m) => {
                let top = 0.5 * phantom.thickness;
                let points: Vec<[f64; 3]> = layout.rest.iter().map(|p| [p[0], p[1], top]).collect();
                unit_responses(
                    m,
                    Formulation::Solid,
                    &materials,
                    &fixed,
                    &points,
                    &loaded,
                    &in_plane,
                    Span::UpperHalf,
                )?
            }
        };
        let dofs = match &mesh {
            ModelMesh::Plane(m) => m.dof_count(),
            ModelMesh::Slab(m) => m.dof_count(),
        };
        let slots = |list: &[usize]| {
            let mut slot = vec![usize::MAX; dofs];
            for (i, &d) in list.iter().enumerate() {
                slot[d] = i;
            }
            slot
        };
        Ok(Self {
            model: options.model,
            loaded_slot: slots(&loaded),
            band_slot: slots(&in_plane),
            mesh,
            entry,
            axis,
            loaded,
            markers,
            band,
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

    /// The consistent-load matrix $P$ (loaded dofs x basis functions) of
    /// the straight needle line from the model's entry: the nodal loads of
    /// each hat function applied as an axial line load, computed by
    /// `needle-fem`.
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
            if total - kept > LOAD_ROUNDOFF * total {
                return Err(ForceError::BadShaft {
                    length,
                    reason: "the shaft leaves the needle line the model was prepared for",
                });
            }
        }
        Ok(p)
    }

    /// The load matrix $P$ (loaded dofs x basis functions) of axial point
    /// forces: point `k` carries $w_k \sum_j \varphi_j(s_k)\,q_j$ along the
    /// axis at its material position.
    pub(crate) fn point_loads(
        &self,
        points: &[LoadPoint],
        basis: &ShaftBasis,
    ) -> Result<DMatrix<f64>, ForceError> {
        self.point_loads_of(points, basis.len(), basis.length(), |s| {
            (0..basis.len()).map(|j| (j, basis.hat(j, s))).collect()
        })
    }

    /// The load matrix (loaded dofs x `columns`) of axial point forces for
    /// any basis: point `k` carries $w_k \sum_j \psi_j(s_k)\,c_j$, with
    /// `shape(s)` the pairs $(j, \psi_j(s))$ at arc length $s$ from the
    /// deformed entry (`length` only names the shaft in errors).
    pub(crate) fn point_loads_of(
        &self,
        points: &[LoadPoint],
        columns: usize,
        length: f64,
        shape: impl Fn(f64) -> Vec<(usize, f64)>,
    ) -> Result<DMatrix<f64>, ForceError> {
        let locator = self.mesh.locator();
        let dimension = self.mesh.dimension();
        let mut p = DMatrix::zeros(self.loaded.len(), columns);
        for point in points {
            let hats: Vec<(usize, f64)> = shape(point.s)
                .into_iter()
                .map(|(j, h)| (j, h * point.weight))
                .filter(|h| h.1 != 0.0)
                .collect();
            for (node, w) in locator.weights(point.at)? {
                for c in (0..2).filter(|&c| self.axis[c] != 0.0) {
                    let slot = self.loaded_slot[node * dimension + c];
                    if slot == usize::MAX {
                        return Err(ForceError::BadShaft {
                            length,
                            reason: "the loaded material line left the band around the needle line the model was prepared for",
                        });
                    }
                    for &(j, h) in &hats {
                        p[(slot, j)] += w * self.axis[c] * h;
                    }
                }
            }
        }
        Ok(p)
    }

    /// The marker displacements (rows `2k + c`) of the loads `p` (columns
    /// of a load matrix).
    pub(crate) fn marker_response(&self, p: &DMatrix<f64>) -> DMatrix<f64> {
        &self.markers * p
    }

    /// The in-plane displacement field of the band for the nodal loads
    /// `load` (one value per loaded dof).
    pub(crate) fn band_field(&self, load: &DVector<f64>) -> BandField<'_> {
        BandField {
            values: &self.band * load,
            locator: self.mesh.locator(),
            response: self,
        }
    }

    /// $G = H K_{ff}^{-1} P$ of the straight needle line from the model's
    /// entry: marker displacements (rows `2k + c`) per unit station value.
    pub fn response_matrix(&self, basis: &ShaftBasis) -> Result<DMatrix<f64>, ForceError> {
        Ok(self.marker_response(&self.consistent_loads(basis)?))
    }

    /// Marker displacements (rows `2k + c`) for station values `values` on
    /// the straight needle line from the model's entry.
    pub fn predict(&self, basis: &ShaftBasis, values: &[f64]) -> Result<Vec<f64>, ForceError> {
        if values.len() != basis.len() {
            return Err(ForceError::Mismatch(format!(
                "{} station values for {} stations",
                values.len(),
                basis.len()
            )));
        }
        let q = DVector::from_column_slice(values);
        Ok((self.response_matrix(basis)? * q).iter().copied().collect())
    }
}

/// The model's displacement in the band around the needle line for one
/// load: what places the load of the next round.
pub(crate) struct BandField<'a> {
    values: DVector<f64>,
    locator: PlaneLocator<'a>,
    response: &'a ShaftResponse,
}

impl BandField<'_> {
    /// The in-plane displacement at the material point `point`.
    pub fn at(&self, point: [f64; 2]) -> Result<[f64; 2], ForceError> {
        let dimension = self.response.mesh.dimension();
        let mut u = [0.0; 2];
        for (node, w) in self.locator.weights(point)? {
            for (c, value) in u.iter_mut().enumerate() {
                let slot = self.response.band_slot[node * dimension + c];
                if slot == usize::MAX {
                    return Err(ForceError::BadShaft {
                        length: point[1],
                        reason: "the loaded material line left the band around the needle line the model was prepared for",
                    });
                }
                *value += w * self.values[slot];
            }
        }
        Ok(u)
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

/// The nodes (passing `keep`, e.g. the slab's mid-plane) of the elements
/// that reach within `halfwidth` of the line through `entry` along `axis`,
/// ascending.
fn band_nodes<const D: usize>(
    mesh: &Mesh<D>,
    entry: [f64; 2],
    axis: [f64; 2],
    halfwidth: f64,
    keep: impl Fn([f64; D]) -> bool,
) -> Vec<usize> {
    let normal = [axis[1], -axis[0]];
    let lateral = |x: [f64; D]| (x[0] - entry[0]) * normal[0] + (x[1] - entry[1]) * normal[1];
    let corners = mesh.kind().corner_count();
    let mut nodes = Vec::new();
    for e in 0..mesh.element_count() {
        let element = mesh.element(e);
        let (lo, hi) = element[..corners]
            .iter()
            .map(|&n| lateral(mesh.node(n)))
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                (lo.min(v), hi.max(v))
            });
        if lo <= halfwidth && hi >= -halfwidth {
            nodes.extend(element.iter().copied().filter(|&n| keep(mesh.node(n))));
        }
    }
    nodes.sort_unstable();
    nodes.dedup();
    nodes
}

/// What a model mesh spans of the phantom's thickness.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Span {
    /// All of it (the plane model).
    Whole,
    /// The half above the mid-plane, its bottom face the mid-plane (the
    /// slab; see the module doc).
    UpperHalf,
}

/// Factorises the clamped model and returns, for a unit force on each dof
/// of `loaded` (on the mid-plane of a [`Span::UpperHalf`] mesh, half of
/// one: the whole slab's unit force), the displacements at the markers
/// (interpolated at `points`, components x and y) and at the dofs
/// `sampled`.
#[allow(clippy::too_many_arguments)]
fn unit_responses<const D: usize>(
    mesh: &Mesh<D>,
    formulation: Formulation,
    materials: &Materials,
    fixed: &[Face],
    points: &[[f64; D]],
    loaded: &[usize],
    sampled: &[usize],
    span: Span,
) -> Result<(DMatrix<f64>, DMatrix<f64>), ForceError> {
    let locator = Locator::new(mesh);
    let mut dirichlet = Dirichlet::new();
    for &face in fixed {
        dirichlet.fix_nodes(mesh, &mesh.nodes_on_face(face))?;
    }
    // The loaded nodes lie on the mid-plane: on the half, each carries half.
    let unit = match span {
        Span::Whole => 1.0,
        Span::UpperHalf => {
            dirichlet.set_nodes(mesh, &mesh.nodes_on_face(Face::Bottom), D - 1, 0.0)?;
            0.5
        }
    };
    let interpolation = locator.interpolation_matrix(points, &[0, 1])?;
    let mut problem = LinearProblem::new(
        Assembler::new(mesh.clone(), formulation)?,
        Vec::new(),
        dirichlet,
    )?;
    problem.factorize(materials)?;
    // A load on a clamped dof goes to the support: its column stays zero.
    let mut columns = faer::Mat::<f64>::zeros(problem.free_dofs().len(), loaded.len());
    for (i, &dof) in loaded.iter().enumerate() {
        if let Some(k) = problem.reduced_index(dof) {
            columns[(k, i)] = unit;
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
    let band = DMatrix::from_fn(sampled.len(), loaded.len(), |r, i| {
        problem
            .reduced_index(sampled[r])
            .map_or(0.0, |k| columns[(k, i)])
    });
    Ok((markers, band))
}

/// Puts the needle on a grid line: the nearest existing line when it lies
/// within [`SNAP_FRACTION`] of the neighbouring elements, otherwise a new
/// line.
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
        if (lines[i] - x).abs() <= SNAP_FRACTION * h {
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
