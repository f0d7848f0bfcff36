//! The discretised phantom: a plane-strain mesh of 6-node triangles or a
//! slab of 10-node tetrahedra (built by needle-fem), with point location
//! and interpolation, which the truth needs to apply loads at material
//! points and to read displacements at the markers.
//!
//! Geometry is handled dimension-free: nodes are padded to 3 coordinates
//! (z = 0 in 2-D) and displacements are interleaved $(u_x, u_y[, u_z])$.

use faer::sparse::SparseColMat;
use needle_fem::assemble::Assembler;
use needle_fem::element::ElementKind;
use needle_fem::element::facet::simplex_mass;
use needle_fem::element::shape::values_and_gradients;
use needle_fem::material::{Formulation, Materials};
use needle_fem::mesh::{BoundaryFacet, Mesh, RectangleMesh};
use rstar::RTree;
use rstar::primitives::{GeomWithData, Rectangle};

use crate::error::SynthError;
use crate::grid::{NEO_HOOKEAN_GRADING_LEVELS, PLANE_GRADING_LEVELS, grade, grid_lines};
use crate::scenario::{Scenario, SlabGrading};
use crate::slab_mesh::{
    MaterialPaths, Span, grade_plan, layered_slab, local_slab, slab_features, upper_planes,
};

/// The meshed phantom.
pub(crate) struct Body {
    /// Spatial dimension (2 or 3).
    pub dim: usize,
    /// Nodes per element.
    pub npe: usize,
    /// Node coordinates, padded to 3.
    pub nodes: Vec<[f64; 3]>,
    elements: Vec<usize>,
    /// Slab thickness (m).
    pub thickness: f64,
    /// Whether the mesh is the upper half of the symmetric slab (solved
    /// with $u_z = 0$ held on the mid-plane).
    pub upper_half: bool,
    /// Element size in the plane (m): the largest grid spacing, or of a
    /// locally refined slab the largest octree cell.
    pub element_size: f64,
    assembly: Assembly,
    locator: Locator,
    boundary: Vec<BoundaryFacet>,
    bounds: ([f64; 3], [f64; 3]),
}

enum Assembly {
    Plane(Assembler<2>),
    Slab(Assembler<3>),
}

/// Where a point lies: its element and the shape function values there.
#[derive(Debug, Clone)]
pub(crate) struct Location {
    /// The element.
    pub element: usize,
    /// Shape function values at the point, one per element node.
    pub shape: Vec<f64>,
}

impl Body {
    /// Meshes the phantom of `scenario`: grid lines on every marker row and
    /// column, on `x_lines` (needle lines, probe centres and edges) and
    /// `y_lines` (layer boundaries), each interval split to at most marker
    /// spacing / refinement. 3-D when the scenario has `out_of_plane`,
    /// graded as its `resolution.slab_grading` asks and covering `span`
    /// of it (`slab_mesh`); otherwise plane strain, the grid graded towards
    /// the probe edges `x_edges`, the sides and the front and back faces.
    /// A locally refined slab is refined towards the needles' material
    /// `paths` when they are given, towards their lines otherwise.
    pub fn build(
        scenario: &Scenario,
        span: Span,
        paths: Option<&MaterialPaths>,
        x_lines: &[f64],
        x_edges: &[f64],
        y_lines: &[f64],
        region_of: impl Fn(f64) -> usize,
    ) -> Result<Self, SynthError> {
        let p = &scenario.phantom;
        let r = &scenario.resolution;
        let spacing_x = p.width / (p.markers.0 - 1) as f64;
        let spacing_y = p.depth / (p.markers.1 - 1) as f64;
        let slab = scenario.effects.out_of_plane.is_some();
        let grading = r.slab_grading.unwrap_or(SlabGrading::DEFAULT);
        let refinement = match grading.local {
            Some(local) if slab => local.refinement.unwrap_or(r.refinement),
            _ => r.refinement,
        };
        let target = spacing_x.min(spacing_y) / refinement as f64;
        let mut xs = grid_lines(p.width, p.markers.0, x_lines, target);
        let mut ys = grid_lines(p.depth, p.markers.1, y_lines, target);
        if slab {
            let needles: Vec<f64> = scenario.needles.plan().iter().map(|n| n.line).collect();
            let extent = (p.width, p.depth);
            grade_plan(
                &mut xs,
                &mut ys,
                extent,
                (&needles, x_edges),
                target,
                &grading,
            );
        } else {
            // The plane truth is graded towards its singular lines (see
            // `grid`).
            let mut singular_x = vec![0.0, p.width];
            singular_x.extend_from_slice(x_edges);
            let levels =
                r.plane_grading
                    .unwrap_or(if scenario.effects.material_nonlinearity.is_some() {
                        NEO_HOOKEAN_GRADING_LEVELS
                    } else {
                        PLANE_GRADING_LEVELS
                    });
            grade(&mut xs, &singular_x, target, levels);
            grade(&mut ys, &[0.0, p.depth], target, levels);
        }
        let mut element_size = xs
            .windows(2)
            .chain(ys.windows(2))
            .map(|w| w[1] - w[0])
            .fold(0.0, f64::max);
        let plan = RectangleMesh {
            width: p.width,
            depth: p.depth,
            x_lines: xs,
            y_lines: ys,
        };
        let (dim, npe, nodes, elements, assembly) = if slab {
            let planes = upper_planes(p.thickness, r.layers, &grading);
            let mut mesh: Mesh<3> = match &grading.local {
                None => layered_slab(plan, &planes, span)?,
                Some(local) => {
                    let features = slab_features(scenario, x_edges, target, local, paths);
                    let lines = [&plan.x_lines[..], &plan.y_lines, &planes];
                    let (mesh, largest) = local_slab(lines, &features, local, span)?;
                    element_size = largest;
                    mesh
                }
            };
            mesh.renumber_spatially();
            mesh.assign_regions(|x| region_of(x[1]));
            let nodes = mesh.nodes().to_vec();
            let elements = mesh.connectivity().to_vec();
            (
                3,
                10,
                nodes,
                elements,
                Assembly::Slab(Assembler::new(mesh, Formulation::Solid)?),
            )
        } else {
            let mut mesh: Mesh<2> = plan.build(ElementKind::Tri6)?;
            mesh.renumber_spatially();
            mesh.assign_regions(|x| region_of(x[1]));
            let nodes = mesh.nodes().iter().map(|n| [n[0], n[1], 0.0]).collect();
            let elements = mesh.connectivity().to_vec();
            let formulation = Formulation::PlaneStrain {
                thickness: p.thickness,
            };
            (
                2,
                6,
                nodes,
                elements,
                Assembly::Plane(Assembler::new(mesh, formulation)?),
            )
        };
        let boundary = match &assembly {
            Assembly::Plane(a) => a.mesh().boundary_facets(),
            Assembly::Slab(a) => a.mesh().boundary_facets(),
        };
        let on_grid = !slab || grading.local.is_none();
        let locator = Locator::new(&nodes, &elements, npe, dim, on_grid);
        let mut bounds = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for n in &nodes {
            for c in 0..3 {
                bounds.0[c] = bounds.0[c].min(n[c]);
                bounds.1[c] = bounds.1[c].max(n[c]);
            }
        }
        Ok(Self {
            dim,
            npe,
            nodes,
            elements,
            thickness: p.thickness,
            upper_half: slab && span == Span::UpperHalf,
            element_size,
            assembly,
            locator,
            boundary,
            bounds,
        })
    }

    /// Lower and upper corners of the body's box.
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        self.bounds
    }

    /// Number of degrees of freedom.
    pub fn dof_count(&self) -> usize {
        self.nodes.len() * self.dim
    }

    /// Number of elements.
    pub fn element_count(&self) -> usize {
        self.elements.len() / self.npe
    }

    /// Global nodes of element `e`.
    pub fn element(&self, e: usize) -> &[usize] {
        &self.elements[e * self.npe..(e + 1) * self.npe]
    }

    /// Region (layer) of every element.
    pub fn regions(&self) -> &[usize] {
        match &self.assembly {
            Assembly::Plane(a) => a.mesh().regions(),
            Assembly::Slab(a) => a.mesh().regions(),
        }
    }

    /// The linear elastic stiffness matrix with one material per region
    /// (full symmetric storage, no boundary conditions).
    pub fn stiffness(&self, materials: &Materials) -> Result<SparseColMat<usize, f64>, SynthError> {
        Ok(match &self.assembly {
            Assembly::Plane(a) => a.stiffness(materials)?,
            Assembly::Slab(a) => a.stiffness(materials)?,
        })
    }

    /// The out-of-plane factor of 2-D integrals: the slab thickness for the
    /// plane-strain mesh, 1 for the slab.
    pub fn plane_factor(&self) -> f64 {
        if self.dim == 2 { self.thickness } else { 1.0 }
    }

    /// z of the marker face: the top face of the slab, 0 for the plane.
    pub fn marker_z(&self) -> f64 {
        if self.dim == 3 {
            0.5 * self.thickness
        } else {
            0.0
        }
    }

    /// Nodes whose position satisfies `predicate`.
    pub fn nodes_where(&self, predicate: impl Fn([f64; 3]) -> bool) -> Vec<usize> {
        (0..self.nodes.len())
            .filter(|&n| predicate(self.nodes[n]))
            .collect()
    }

    /// Boundary facets (edges in 2-D, faces in 3-D) whose nodes all satisfy
    /// `predicate`.
    pub fn boundary_facets_where(&self, predicate: impl Fn([f64; 3]) -> bool) -> Vec<Vec<usize>> {
        self.boundary
            .iter()
            .filter(|f| f.nodes.iter().all(|&n| predicate(self.nodes[n])))
            .map(|f| f.nodes.clone())
            .collect()
    }

    /// Every element as a patch of nodes (for area integrals over the plane
    /// mesh).
    pub fn element_patches(&self) -> Vec<Vec<usize>> {
        (0..self.element_count())
            .map(|e| self.element(e).to_vec())
            .collect()
    }

    /// Triplets `(row, col, value)` of distributed springs: over each patch
    /// (a simplex of parametric dimension `param_dim` given by its nodes),
    /// $\int N_a N_b\,dA$ times `scale` times the stiffness of each listed
    /// displacement component `(component, stiffness per unit area)`.
    pub fn distributed_springs(
        &self,
        patches: &[Vec<usize>],
        param_dim: usize,
        scale: f64,
        components: &[(usize, f64)],
    ) -> Vec<(usize, usize, f64)> {
        let mut triplets = Vec::new();
        for patch in patches {
            let coordinates: Vec<[f64; 3]> = patch.iter().map(|&n| self.nodes[n]).collect();
            let mass = simplex_mass(&coordinates, param_dim, 2);
            let m = patch.len();
            for a in 0..m {
                for b in 0..m {
                    for &(c, k) in components {
                        triplets.push((
                            patch[a] * self.dim + c,
                            patch[b] * self.dim + c,
                            scale * k * mass[a * m + b],
                        ));
                    }
                }
            }
        }
        triplets
    }

    /// The element containing `point` and the shape values there, if the
    /// point lies in the body (up to a relative tolerance).
    pub fn locate(&self, point: [f64; 3]) -> Option<Location> {
        let (element, xi) = self.locator.find(point, self.dim)?;
        let (shape, _) = values_and_gradients(self.dim, self.npe, &xi[..self.dim]);
        Some(Location { element, shape })
    }

    /// The displacement and its gradient $\partial u_i/\partial X_j$ at
    /// `point` (zero rows and columns beyond the dimension), if inside:
    /// one point location for both, as Newton's method needs them together.
    pub fn value_and_gradient(
        &self,
        point: [f64; 3],
        u: &[f64],
    ) -> Option<([f64; 3], [[f64; 3]; 3])> {
        let (element, xi) = self.locator.find(point, self.dim)?;
        let (shape, reference) = values_and_gradients(self.dim, self.npe, &xi[..self.dim]);
        let inverse = &self.locator.maps[element].1;
        let mut v = [0.0; 3];
        let mut h = [[0.0; 3]; 3];
        for (a, &n) in self.element(element).iter().enumerate() {
            // Physical gradient of N_a: J^-T times its reference gradient.
            let mut g = [0.0; 3];
            for j in 0..self.dim {
                g[j] = (0..self.dim).map(|k| inverse[k][j] * reference[a][k]).sum();
            }
            for i in 0..self.dim {
                v[i] += shape[a] * u[n * self.dim + i];
                for j in 0..self.dim {
                    h[i][j] += u[n * self.dim + i] * g[j];
                }
            }
        }
        Some((v, h))
    }

    /// The displacement at a located point.
    pub fn value(&self, at: &Location, u: &[f64]) -> [f64; 3] {
        let mut v = [0.0; 3];
        for (a, &n) in self.element(at.element).iter().enumerate() {
            for c in 0..self.dim {
                v[c] += at.shape[a] * u[n * self.dim + c];
            }
        }
        v
    }

    /// How many copies of the mesh the phantom is: 2 for the upper half of
    /// the symmetric slab, else 1. A force on a mid-plane point of the
    /// whole slab falls half on each half, so the mesh carries `1 / copies`
    /// of every load, and a reaction summed over the mesh is `1 / copies`
    /// of the whole's.
    pub fn copies(&self) -> f64 {
        if self.upper_half { 2.0 } else { 1.0 }
    }

    /// Adds the mesh's share ([`Body::copies`]) of a point force at a
    /// located point to the load vector, spread to the element nodes by
    /// the shape functions (consistent nodal forces).
    pub fn add_point_force(&self, at: &Location, force: [f64; 3], loads: &mut [f64]) {
        let share = 1.0 / self.copies();
        for (a, &n) in self.element(at.element).iter().enumerate() {
            for c in 0..self.dim {
                loads[n * self.dim + c] += share * at.shape[a] * force[c];
            }
        }
    }
}

/// Point location: a handful of candidate elements, then their
/// barycentric coordinates pick the one holding the point.
struct Locator {
    candidates: Candidates,
    /// Per element: first corner and the inverse of the corner Jacobian,
    /// `xi = inverse * (p - origin)`.
    maps: Vec<([f64; 3], [[f64; 3]; 3])>,
    /// Relative tolerance in reference coordinates.
    tolerance: f64,
}

/// Where the elements that may hold a point are listed.
///
/// Every tensor mesh of the truth subdivides the cells of a grid (the
/// plan's lines and the node planes), whose lines are the distinct
/// coordinates of the element corners; each cell lists the elements
/// whose box overlaps it, so a search tries the simplices of one cell
/// (two on its faces). A locally refined slab's fine lines near one
/// feature would cut every coarse cell of such a grid, so its elements'
/// boxes go into an R-tree instead; on the tensor meshes the R-tree was
/// 7% slower over the paper default's campaign (median of the ratios of
/// five runs side by side, `docs/benchmarks.md`, session 40). A grid of
/// equal buckets was slower still: where the plan is graded towards a
/// face or a needle line a bucket held dozens of element columns
/// through the whole thickness, and the drag of a needle with a radius
/// is located at every point of its rim.
enum Candidates {
    Grid {
        /// Cell boundaries per axis, strictly increasing (one infinite
        /// cell along z in 2-D).
        lines: [Vec<f64>; 3],
        /// Elements per cell, x fastest.
        cells: Vec<Vec<usize>>,
        /// Absolute tolerance of the cell boundaries.
        slack: f64,
    },
    Tree(RTree<GeomWithData<Rectangle<[f64; 3]>, usize>>),
}

impl Locator {
    /// The locator of the elements `elements` (`npe` nodes each) over
    /// `nodes`; on a grid of cells if `on_grid` (the mesh subdivides the
    /// cells of a tensor grid), else on an R-tree.
    fn new(nodes: &[[f64; 3]], elements: &[usize], npe: usize, dim: usize, on_grid: bool) -> Self {
        let extent = (0..dim)
            .map(|c| {
                let (lo, hi) = nodes
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |m, n| {
                        (m.0.min(n[c]), m.1.max(n[c]))
                    });
                hi - lo
            })
            .fold(0.0, f64::max);
        let slack = 1e-9 * extent;
        let corners: Vec<Vec<[f64; 3]>> = elements
            .chunks(npe)
            .map(|element| element[..=dim].iter().map(|&n| nodes[n]).collect())
            .collect();
        let boxes: Vec<([f64; 3], [f64; 3])> = corners
            .iter()
            .map(|corners| {
                let lo = std::array::from_fn(|c| {
                    corners.iter().map(|p| p[c]).fold(f64::INFINITY, f64::min)
                });
                let hi = std::array::from_fn(|c| {
                    corners
                        .iter()
                        .map(|p| p[c])
                        .fold(f64::NEG_INFINITY, f64::max)
                });
                (lo, hi)
            })
            .collect();
        let candidates = if on_grid {
            grid_candidates(&boxes, dim, slack)
        } else {
            let widened = |x: [f64; 3], by: f64| x.map(|v| v + by);
            Candidates::Tree(RTree::bulk_load(
                boxes
                    .iter()
                    .enumerate()
                    .map(|(e, (lo, hi))| {
                        let (lo, hi) = (widened(*lo, -slack), widened(*hi, slack));
                        GeomWithData::new(Rectangle::from_corners(lo, hi), e)
                    })
                    .collect(),
            ))
        };
        let maps = corners
            .iter()
            .map(|corners| {
                let mut jac = [[0.0; 3]; 3];
                for k in 0..3 {
                    jac[k][k] = 1.0;
                }
                for col in 0..dim {
                    for row in 0..dim {
                        jac[row][col] = corners[col + 1][row] - corners[0][row];
                    }
                }
                (corners[0], invert3(&jac))
            })
            .collect();
        Self {
            candidates,
            maps,
            tolerance: 1e-9,
        }
    }

    /// The element holding `p` and its reference coordinates; of several
    /// (on shared faces) the one where `p` lies deepest inside, the first
    /// listed on a tie.
    fn find(&self, p: [f64; 3], dim: usize) -> Option<(usize, [f64; 3])> {
        let mut best: Option<(usize, [f64; 3], f64)> = None;
        let mut consider = |e: usize| {
            let (origin, inverse) = &self.maps[e];
            let d = [p[0] - origin[0], p[1] - origin[1], p[2] - origin[2]];
            let mut xi = [0.0; 3];
            for r in 0..dim {
                xi[r] = (0..dim).map(|c| inverse[r][c] * d[c]).sum();
            }
            let l0 = 1.0 - xi[..dim].iter().sum::<f64>();
            let inside = xi[..dim].iter().copied().fold(l0, f64::min);
            let better = best
                .as_ref()
                .is_none_or(|b| inside > b.2 || (inside == b.2 && e < b.0));
            if better {
                best = Some((e, xi, inside));
            }
        };
        match &self.candidates {
            Candidates::Grid {
                lines,
                cells,
                slack,
            } => {
                // The cells within `slack` of p along each axis: one, or
                // two on a boundary; none if p lies outside the grid.
                let mut range = [(0, 0); 3];
                for (c, r) in range.iter_mut().enumerate() {
                    let count = lines[c].len() - 1;
                    let first = lines[c][1..].partition_point(|&l| l < p[c] - slack);
                    let last = lines[c][..count].partition_point(|&l| l <= p[c] + slack);
                    if first >= last {
                        return None;
                    }
                    *r = (first, last);
                }
                let counts = lines.each_ref().map(|l| l.len() - 1);
                for k in range[2].0..range[2].1 {
                    for j in range[1].0..range[1].1 {
                        for i in range[0].0..range[0].1 {
                            for &e in &cells[(k * counts[1] + j) * counts[0] + i] {
                                consider(e);
                            }
                        }
                    }
                }
            }
            Candidates::Tree(tree) => {
                // A 2-D mesh's nodes, and so its boxes, lie at z = 0.
                let query = if dim == 2 { [p[0], p[1], 0.0] } else { p };
                for candidate in tree.locate_all_at_point(query) {
                    consider(candidate.data);
                }
            }
        }
        best.filter(|b| b.2 >= -self.tolerance)
            .map(|(e, xi, _)| (e, xi))
    }
}

/// The grid of cells between the distinct corner coordinates of the
/// elements with boxes `boxes` (coordinates within `slack` are one line),
/// each cell listing the elements whose box overlaps its interior.
fn grid_candidates(boxes: &[([f64; 3], [f64; 3])], dim: usize, slack: f64) -> Candidates {
    let lines: [Vec<f64>; 3] = std::array::from_fn(|c| {
        if c >= dim {
            return vec![f64::NEG_INFINITY, f64::INFINITY];
        }
        let mut v: Vec<f64> = boxes.iter().flat_map(|(lo, hi)| [lo[c], hi[c]]).collect();
        v.sort_by(f64::total_cmp);
        v.dedup_by(|b, a| *b - *a <= slack);
        v
    });
    let counts: [usize; 3] = std::array::from_fn(|c| lines[c].len() - 1);
    let mut cells = vec![Vec::new(); counts.iter().product()];
    for (e, (lo, hi)) in boxes.iter().enumerate() {
        let mut range = [(0, 0); 3];
        for (c, r) in range.iter_mut().enumerate() {
            let first = lines[c][1..].partition_point(|&l| l <= lo[c] + slack);
            let last = lines[c][..counts[c]].partition_point(|&l| l < hi[c] - slack);
            *r = (first, last.max(first + 1).min(counts[c]));
        }
        for k in range[2].0..range[2].1 {
            for j in range[1].0..range[1].1 {
                for i in range[0].0..range[0].1 {
                    cells[(k * counts[1] + j) * counts[0] + i].push(e);
                }
            }
        }
    }
    Candidates::Grid {
        lines,
        cells,
        slack,
    }
}

/// Inverse of a 3x3 matrix (the padded Jacobian of a straight simplex,
/// never singular for a valid mesh).
pub(crate) fn invert3(m: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    inverse_and_det(m).0
}

/// Inverse (row-major `inv[i][j]`) and determinant of a 3x3 matrix, by
/// cofactors.
pub(crate) fn inverse_and_det(m: &[[f64; 3]; 3]) -> ([[f64; 3]; 3], f64) {
    let c = |r: usize, k: usize| {
        let (r1, r2) = ((r + 1) % 3, (r + 2) % 3);
        let (k1, k2) = ((k + 1) % 3, (k + 2) % 3);
        m[r1][k1] * m[r2][k2] - m[r1][k2] * m[r2][k1]
    };
    let det = m[0][0] * c(0, 0) + m[0][1] * c(0, 1) + m[0][2] * c(0, 2);
    let mut inv = [[0.0; 3]; 3];
    for r in 0..3 {
        for k in 0..3 {
            inv[k][r] = c(r, k) / det;
        }
    }
    (inv, det)
}
