//! The forward model of a probing experiment: a finite-element mesh of the
//! phantom on the marker grid (the top face as a 2-D plane-strain or
//! plane-stress mesh, or the 3-D slab of tetrahedra with element layers
//! through the thickness), the fixed faces, the probe load points on the
//! boundary, and the map from material parameters and the probe's contact
//! width $a$ to marker displacements per unit probe force,
//!
//! $$G_{l,c}(\theta, a) = H\,K(\theta)^{-1} b_{l,c}(a),$$
//!
//! where $b_{l,c}(a)$ is a unit force in direction $c$ spread over the
//! patch of a rigid flat punch of width $a$ centred on load point $l$
//! (`crate::punch`: $p(s) \propto 1/\sqrt{1 - (2s/a)^2}$ along the face;
//! $a = 0$ is the paper's point force) and $H$ interpolates the in-plane
//! nodal displacements at the markers (on the top face $z = t/2$ of the
//! slab). In the plane models each sample of the patch is a point force
//! distributed by the shape functions at that point (`needle-fem`'s
//! consistent point force); in the slab the probe presses the whole
//! thickness of the face, so each sample is a uniform line load along z
//! from $z = -t/2$ to $t/2$. The slab with an even number of layers is
//! meshed as the upper half $z \in [0, t/2]$ of needle-fem's slab mirrored
//! in its mid-plane, $u_z = 0$ held on $z = 0$ (the probe loads and the
//! fixed faces are symmetric about it, so this is the mirrored whole
//! slab's solution exactly, on three node planes of five for two layers;
//! needle-fem's test `upper_half_of_the_mirrored_slab_gives_its_displacement`);
//! an odd number of layers has no mid-plane node plane and is meshed whole.
//! The sensitivities follow from differentiating
//! $K U = B$: $\partial U/\partial p = -K^{-1}\,(\partial K/\partial p)\,U$
//! for the material, $\partial U/\partial a = K^{-1}\,\partial B/\partial a$
//! for the width (a central difference of the load, which is smooth in
//! $a$, with the same factor).

use needle_fem::element::ElementKind;
use std::sync::Mutex;

use needle_fem::load::{LineDensity, add_line_load, add_point_force};
use needle_fem::locate::Locator;
use needle_fem::material::{Formulation, Materials};
use needle_fem::mesh::{Face, MarkerGrid, Mesh, RectangleMesh, SlabMesh};

use crate::error::IdentifyError;
use crate::fe::{FeSystem, Response};
use crate::options::{PlaneModel, Regions};
use crate::probe::ProbeSetup;
use crate::punch::patch_rule;

/// How deep inside (or far outside) the phantom a probe tip may be, as a
/// fraction of the smaller side, and still count as pressing on the
/// boundary.
const MAX_TIP_OFFSET_FRACTION: f64 = 0.2;

/// Step of the central difference in the contact width, as a fraction of
/// the marker spacing: the load is smooth in the width between the widths
/// at which the patch edges reach a mesh line, so the difference is
/// accurate to the square of the step.
const WIDTH_STEP_FRACTION: f64 = 1e-3;

/// The model choices that shape the mesh.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelSpec {
    /// Element kind: Tri3 or Tri6 for the plane models; for the slab the
    /// tetrahedron of the same order (Tri3 or Tet4: Tet4; Tri6 or Tet10:
    /// Tet10).
    pub element: ElementKind,
    /// Plane strain, plane stress or the 3-D slab.
    pub plane: PlaneModel,
    /// Mesh lines per marker spacing.
    pub refinement: usize,
    /// Element layers through the thickness (slab only).
    pub layers: usize,
    /// Material regions.
    pub regions: Regions,
}

impl ModelSpec {
    /// The element the mesh is built with.
    pub fn mesh_element(&self) -> ElementKind {
        match (self.plane, self.element) {
            (PlaneModel::Slab, ElementKind::Tri3 | ElementKind::Tet4) => ElementKind::Tet4,
            (PlaneModel::Slab, _) => ElementKind::Tet10,
            (_, kind) => kind,
        }
    }
}

/// The probing forward model (see the module doc).
#[derive(Debug)]
pub struct ProbeModel {
    system: System,
    element: ElementKind,
    load_points: Vec<[f64; 2]>,
    region_count: usize,
    marker_spacing: f64,
    /// Mesh lines in x and in y: where the shape functions kink along a
    /// face.
    lines: [Vec<f64>; 2],
    /// Width, depth and thickness of the phantom.
    extent: [f64; 3],
    /// z of the mesh's bottom face: $-t/2$, or 0 for the slab's upper half.
    bottom: f64,
    /// The unit loads at the last contact width asked for.
    loads: Mutex<Option<(f64, Vec<Vec<f64>>)>>,
}

/// The plane or the slab system.
#[derive(Debug)]
enum System {
    Plane(FeSystem<2>),
    Slab(FeSystem<3>),
}

impl ProbeModel {
    /// Builds the mesh on the markers of `setup`, the fixed dofs and the
    /// interpolation at the markers, for loads at `load_points` (each
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
        let element = spec.mesh_element();
        let whole_bottom = -0.5 * setup.thickness;
        let (system, bottom) = match spec.plane {
            PlaneModel::Strain | PlaneModel::Stress => {
                let formulation = if spec.plane == PlaneModel::Strain {
                    Formulation::PlaneStrain {
                        thickness: setup.thickness,
                    }
                } else {
                    Formulation::PlaneStress {
                        thickness: setup.thickness,
                    }
                };
                let mesh = with_regions(plan.build(element)?, &spec.regions)?;
                let system = System::Plane(plane_system(setup, mesh, formulation)?);
                (system, whole_bottom)
            }
            PlaneModel::Slab => {
                if spec.layers == 0 {
                    return Err(IdentifyError::InvalidValue {
                        field: "options.slab_layers",
                        value: 0.0,
                        reason: "must be at least 1",
                    });
                }
                let slab = SlabMesh::new(plan.clone(), setup.thickness, spec.layers)?;
                let half = spec.layers.is_multiple_of(2);
                let mesh = if half {
                    slab.build_upper_half(element)?
                } else {
                    slab.build(element)?
                };
                let mesh = with_regions(mesh, &spec.regions)?;
                let system = System::Slab(slab_system(setup, mesh, half)?);
                (system, if half { 0.0 } else { whole_bottom })
            }
        };
        let model = Self {
            system,
            element,
            load_points: load_points.to_vec(),
            region_count: spec.regions.count(),
            marker_spacing,
            lines: [plan.x_lines, plan.y_lines],
            extent: [setup.width, setup.depth, setup.thickness],
            bottom,
            loads: Mutex::new(None),
        };
        // Every load point must carry its force into the mesh.
        model.unit_loads(0.0)?;
        Ok(model)
    }

    /// The element of the mesh.
    pub fn element(&self) -> ElementKind {
        self.element
    }

    /// Nodes and elements of the mesh.
    pub fn mesh_size(&self) -> (usize, usize) {
        match &self.system {
            System::Plane(s) => s.size(),
            System::Slab(s) => s.size(),
        }
    }

    /// Number of material regions.
    pub fn region_count(&self) -> usize {
        self.region_count
    }

    /// The load points.
    pub fn load_points(&self) -> &[[f64; 2]] {
        &self.load_points
    }

    /// Typical distance between neighbouring markers (m).
    pub fn marker_spacing(&self) -> f64 {
        self.marker_spacing
    }

    /// Solves for every unit load at `materials`, spread over a flat
    /// punch's patch of `width` (m; 0: the point force): one numeric
    /// Cholesky factorisation, `2 x load points` right-hand sides.
    pub fn respond(&self, materials: &Materials, width: f64) -> Result<Response, IdentifyError> {
        let loads = self.cached_loads(width)?;
        match &self.system {
            System::Plane(s) => s.respond(materials, &loads),
            System::Slab(s) => s.respond(materials, &loads),
        }
    }

    /// Marker-level sensitivities $H\,\partial U/\partial a$ of every unit
    /// response to the contact width, by a central difference of the
    /// loads (the rule is even in the width, so this holds at 0 too).
    pub fn width_sensitivity(
        &self,
        materials: &Materials,
        width: f64,
    ) -> Result<Vec<Vec<f64>>, IdentifyError> {
        let h = WIDTH_STEP_FRACTION * self.marker_spacing;
        let (plus, minus) = (self.unit_loads(width + h)?, self.unit_loads(width - h)?);
        let difference: Vec<Vec<f64>> = plus
            .iter()
            .zip(&minus)
            .map(|(p, m)| p.iter().zip(m).map(|(p, m)| (p - m) / (2.0 * h)).collect())
            .collect();
        match &self.system {
            System::Plane(s) => s.marker_response(materials, &difference),
            System::Slab(s) => s.marker_response(materials, &difference),
        }
    }

    /// The unit loads at `width`, kept for the next call at the same width.
    fn cached_loads(&self, width: f64) -> Result<Vec<Vec<f64>>, IdentifyError> {
        let mut cache = self.loads.lock().map_err(|_| {
            IdentifyError::Factorization("a previous load evaluation panicked".into())
        })?;
        if let Some((at, loads)) = cache.as_ref()
            && *at == width
        {
            return Ok(loads.clone());
        }
        let loads = self.unit_loads(width)?;
        *cache = Some((width, loads.clone()));
        Ok(loads)
    }

    /// The unit loads `b[2 l + c]` (full dof vectors) of a punch of
    /// `width` at every load point.
    fn unit_loads(&self, width: f64) -> Result<Vec<Vec<f64>>, IdentifyError> {
        match &self.system {
            System::Plane(s) => self.unit_loads_on(s.mesh(), width),
            System::Slab(s) => self.unit_loads_on(s.mesh(), width),
        }
    }

    fn unit_loads_on<const D: usize>(
        &self,
        mesh: &Mesh<D>,
        width: f64,
    ) -> Result<Vec<Vec<f64>>, IdentifyError> {
        let locator = Locator::new(mesh);
        let [w, d, t] = self.extent;
        let tol = 1e-9 * w.max(d);
        let mut loads = Vec::with_capacity(2 * self.load_points.len());
        for (i, &p) in self.load_points.iter().enumerate() {
            // The patch runs along the face the load point lies on.
            let along = if p[1] <= tol || p[1] >= d - tol { 0 } else { 1 };
            let extent = (0.0, [w, d][along]);
            let rule = patch_rule(p[along], width, &self.lines[along], extent);
            for c in 0..2 {
                let mut load = vec![0.0; mesh.dof_count()];
                for &(s, weight) in &rule {
                    let mut point = p;
                    point[along] = s;
                    add_unit_force(&locator, &mut load, point, c, weight, [self.bottom, t])
                        .map_err(|_| outside("load point", i, p))?;
                }
                loads.push(load);
            }
        }
        Ok(loads)
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
        match &self.system {
            System::Plane(s) => s.sensitivities(materials, response, tied),
            System::Slab(s) => s.sensitivities(materials, response, tied),
        }
    }
}

/// Assigns the regions by element centroid (y) and checks that every
/// requested region has elements.
fn with_regions<const D: usize>(
    mut mesh: Mesh<D>,
    regions: &Regions,
) -> Result<Mesh<D>, IdentifyError> {
    mesh.assign_regions(|c| regions.region_of(c[1]));
    let requested = regions.count();
    if mesh.region_count() != requested {
        return Err(IdentifyError::Inconsistent(format!(
            "options.regions: {requested} regions requested but the mesh has elements in {} (is every layer inside the phantom?)",
            mesh.region_count()
        )));
    }
    Ok(mesh)
}

fn outside(what: &str, index: usize, p: [f64; 2]) -> IdentifyError {
    IdentifyError::Inconsistent(format!(
        "{what} {index} at ({}, {}) m lies outside the mesh",
        p[0], p[1]
    ))
}

/// The plane system: markers interpolated in the plane.
fn plane_system(
    setup: &ProbeSetup,
    mesh: Mesh<2>,
    formulation: Formulation,
) -> Result<FeSystem<2>, IdentifyError> {
    let locator = Locator::new(&mesh);
    let markers = setup
        .markers
        .iter()
        .enumerate()
        .map(|(i, &p)| locator.weights(p).ok_or_else(|| outside("marker", i, p)))
        .collect::<Result<Vec<_>, _>>()?;
    FeSystem::new(mesh, formulation, &setup.fixed, None, markers)
}

/// The slab system: markers on the top face $z = t/2$; $u_z$ held on the
/// bottom face of the `upper_half`.
fn slab_system(
    setup: &ProbeSetup,
    mesh: Mesh<3>,
    upper_half: bool,
) -> Result<FeSystem<3>, IdentifyError> {
    let half = 0.5 * setup.thickness;
    let locator = Locator::new(&mesh);
    let markers = setup
        .markers
        .iter()
        .enumerate()
        .map(|(i, &p)| {
            locator
                .weights([p[0], p[1], half])
                .ok_or_else(|| outside("marker", i, p))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let symmetry = upper_half.then_some(Face::Bottom);
    FeSystem::new(mesh, Formulation::Solid, &setup.fixed, symmetry, markers)
}

/// Adds `weight` times a unit force along axis `axis` at the boundary
/// point `point`: a point force in the plane (`D = 2`), a uniform line load
/// of density `weight / thickness` through the thickness of the slab
/// (`D = 3`), over the mesh's part of it, from `bottom` to $t/2$ (the upper
/// half carries half). Fails when the point (or the line) leaves the mesh.
fn add_unit_force<const D: usize>(
    locator: &Locator<'_, D>,
    load: &mut [f64],
    point: [f64; 2],
    axis: usize,
    weight: f64,
    [bottom, thickness]: [f64; 2],
) -> Result<(), IdentifyError> {
    let mut force = [0.0; D];
    let (mut start, mut end) = ([0.0; D], [0.0; D]);
    start[..2].copy_from_slice(&point);
    end[..2].copy_from_slice(&point);
    if D == 2 {
        force[axis] = weight;
        add_point_force(locator, load, start, force)?;
        return Ok(());
    }
    force[axis] = weight / thickness;
    start[2] = bottom;
    end[2] = 0.5 * thickness;
    let length = end[2] - start[2];
    let line = LineDensity::Sampled {
        arclength: vec![0.0, length],
        density: vec![force; 2],
    };
    let total = add_line_load(locator, load, start, end, &line)?;
    // The quadrature must carry the mesh's share of the force into it.
    let share = weight * length / thickness;
    if (total[axis] - share).abs() > 1e-9 * weight.abs() {
        return Err(IdentifyError::Inconsistent(
            "line load leaves the mesh".into(),
        ));
    }
    Ok(())
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
