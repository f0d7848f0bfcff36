//! Locating points in a mesh and interpolating nodal fields there.
//!
//! A uniform bucket grid over the mesh's bounding box lists, per cell, the
//! elements whose bounding boxes overlap it; a query tests only those
//! elements, each with the inverse of its corner Jacobian made once when
//! the locator is built. Inside an element the reference coordinates
//! $\xi$ come from the corner (barycentric) coordinates, which is exact
//! for straight-sided elements (all meshes built by this crate; curved
//! isoparametric elements are not supported by the locator). A field is
//! then interpolated as
//! $u(x) = \sum_a N_a(\xi)\,u_a$, and these weights form a sparse linear
//! operator $H$ with $u(\text{markers}) = H u$: the "displacement at the
//! markers" map used in least squares.
//!
//! In 3-D, markers on the top face are located by their 3-D position
//! $(x, y, t/2)$, which lies on the boundary of the top elements; see
//! [`Locator::locate_on_plane`].

use faer::sparse::{SparseColMat, Triplet};
use nalgebra::{SMatrix, SVector};

use crate::element::shape;
use crate::element::stiffness::determinant_and_inverse;
use crate::error::FemError;
use crate::mesh::Mesh;

/// A located point: the element containing it and its reference coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Location<const D: usize> {
    /// Element index.
    pub element: usize,
    /// Reference coordinates $\xi$ in the element.
    pub reference: [f64; D],
}

/// Interpolation weights at one point: `(node, N_a)` pairs (they sum to 1).
pub type NodeWeights = Vec<(usize, f64)>;

/// Point locator over a mesh (borrows it).
#[derive(Debug, Clone)]
pub struct Locator<'a, const D: usize> {
    mesh: &'a Mesh<D>,
    origin: [f64; D],
    cell_size: [f64; D],
    cells: [usize; D],
    /// CSR of grid cell to candidate elements.
    offsets: Vec<usize>,
    elements: Vec<usize>,
    /// Per element, its first corner $x_0$ and the inverse of its corner
    /// Jacobian (`None` if degenerate): made once, since a query tests
    /// several elements and a needle's placement makes thousands of
    /// queries on one locator.
    maps: Vec<([f64; D], Option<SMatrix<f64, D, D>>)>,
    tolerance: f64,
}

impl<'a, const D: usize> Locator<'a, D> {
    /// Builds the bucket grid (about one cell per element).
    pub fn new(mesh: &'a Mesh<D>) -> Self {
        let (lo, hi) = mesh.bounding_box();
        let element_count = mesh.element_count().max(1);
        let mut extent = [0.0; D];
        for i in 0..D {
            extent[i] = (hi[i] - lo[i]).max(f64::MIN_POSITIVE);
        }
        // Cell counts proportional to the box extents with ~one element per cell.
        let volume: f64 = extent.iter().product();
        let edge = (volume / element_count as f64).powf(1.0 / D as f64);
        let mut cells = [1usize; D];
        let mut cell_size = [0.0; D];
        for i in 0..D {
            cells[i] = ((extent[i] / edge).ceil() as usize).clamp(1, 4096);
            cell_size[i] = extent[i] / cells[i] as f64;
        }
        let corners = mesh.kind().corner_count();
        let total: usize = cells.iter().product();
        let mut lists: Vec<Vec<usize>> = vec![Vec::new(); total];
        for e in 0..mesh.element_count() {
            let mut bmin = [f64::INFINITY; D];
            let mut bmax = [f64::NEG_INFINITY; D];
            for &n in &mesh.element(e)[..corners] {
                let p = mesh.node(n);
                for i in 0..D {
                    bmin[i] = bmin[i].min(p[i]);
                    bmax[i] = bmax[i].max(p[i]);
                }
            }
            let mut low = [0; D];
            let mut high = [0; D];
            for i in 0..D {
                low[i] = cell_index(bmin[i], lo[i], cell_size[i], cells[i]);
                high[i] = cell_index(bmax[i], lo[i], cell_size[i], cells[i]);
            }
            for_each_cell(&low, &high, |cell| lists[flat(&cell, &cells)].push(e));
        }
        let mut offsets = Vec::with_capacity(total + 1);
        offsets.push(0);
        for list in &lists {
            offsets.push(offsets.last().unwrap_or(&0) + list.len());
        }
        let elements = lists.into_iter().flatten().collect();
        let maps = (0..mesh.element_count())
            .map(|e| {
                let nodes = mesh.element(e);
                let x0 = mesh.node(nodes[0]);
                let jacobian =
                    SMatrix::<f64, D, D>::from_fn(|i, j| mesh.node(nodes[j + 1])[i] - x0[i]);
                let (determinant, inverse) = determinant_and_inverse(&jacobian);
                (x0, (determinant != 0.0).then_some(inverse))
            })
            .collect();
        Self {
            mesh,
            origin: lo,
            cell_size,
            cells,
            offsets,
            elements,
            maps,
            tolerance: 1e-9,
        }
    }

    /// The mesh.
    pub fn mesh(&self) -> &'a Mesh<D> {
        self.mesh
    }

    /// Candidate elements whose bounding boxes overlap the box `[lo, hi]`.
    pub fn candidates(&self, lo: [f64; D], hi: [f64; D]) -> Vec<usize> {
        let (low, high) = (self.cell_of(lo), self.cell_of(hi));
        let mut out = Vec::new();
        for_each_cell(&low, &high, |cell| {
            let c = flat(&cell, &self.cells);
            out.extend_from_slice(&self.elements[self.offsets[c]..self.offsets[c + 1]]);
        });
        out.sort_unstable();
        out.dedup();
        out
    }

    /// The grid cell holding `point` (clamped to the grid).
    fn cell_of(&self, point: [f64; D]) -> [usize; D] {
        let mut cell = [0; D];
        for i in 0..D {
            cell[i] = cell_index(point[i], self.origin[i], self.cell_size[i], self.cells[i]);
        }
        cell
    }

    /// Barycentric coordinates $[L_0..L_D]$ of `point` in element `e`
    /// (from its corners).
    pub fn barycentric(&self, e: usize, point: [f64; D]) -> [f64; 4] {
        let (x0, inverse) = &self.maps[e];
        let rhs = SVector::<f64, D>::from_fn(|i, _| point[i] - x0[i]);
        let xi = match inverse {
            Some(inverse) => inverse * rhs,
            None => SVector::from_element(f64::NAN),
        };
        shape::barycentric(&xi)
    }

    /// The element containing `point` (within a relative tolerance of
    /// $10^{-9}$ in barycentric coordinates), or `None` if outside.
    pub fn locate(&self, point: [f64; D]) -> Option<Location<D>> {
        if point.iter().any(|x| !x.is_finite()) {
            return None;
        }
        // A point lies in one grid cell, whose list is sorted and unique:
        // the candidates of the box [point, point] without building them.
        let c = flat(&self.cell_of(point), &self.cells);
        let mut best: Option<(f64, usize, [f64; 4])> = None;
        for &e in &self.elements[self.offsets[c]..self.offsets[c + 1]] {
            let l = self.barycentric(e, point);
            let worst = l[..=D].iter().copied().fold(f64::INFINITY, f64::min);
            if worst.is_finite() && best.is_none_or(|(w, _, _)| worst > w) {
                best = Some((worst, e, l));
            }
        }
        let (worst, element, l) = best?;
        if worst < -self.tolerance {
            return None;
        }
        let mut reference = [0.0; D];
        reference.copy_from_slice(&l[1..=D]);
        Some(Location { element, reference })
    }

    /// Locates a point of a plane of constant coordinate (e.g. the top face
    /// $z = t/2$ of a slab): `in_plane` gives the first `D-1` coordinates and
    /// `level` the last.
    pub fn locate_on_plane(&self, in_plane: &[f64], level: f64) -> Option<Location<D>> {
        let mut point = [level; D];
        point[..D - 1].copy_from_slice(&in_plane[..D - 1]);
        self.locate(point)
    }

    /// Shape-function weights of the nodes of the element containing `point`.
    pub fn weights(&self, point: [f64; D]) -> Option<NodeWeights> {
        let location = self.locate(point)?;
        Some(weights_at(self.mesh, &location))
    }

    /// Interpolates a nodal vector field (interleaved dofs) at `point`.
    pub fn interpolate(&self, field: &[f64], point: [f64; D]) -> Result<[f64; D], FemError> {
        if field.len() != self.mesh.dof_count() {
            return Err(FemError::DimensionMismatch {
                context: "interpolated field",
                expected: self.mesh.dof_count(),
                actual: field.len(),
            });
        }
        let weights = self
            .weights(point)
            .ok_or_else(|| FemError::PointOutsideMesh {
                index: 0,
                coordinates: point.to_vec(),
            })?;
        let mut value = [0.0; D];
        for (n, w) in weights {
            for i in 0..D {
                value[i] += w * field[n * D + i];
            }
        }
        Ok(value)
    }

    /// The sparse interpolation operator $H$: row `p * components.len() + k`
    /// gives component `components[k]` of the displacement at `points[p]`
    /// from the full interleaved dof vector (so $u_{\text{markers}} = H u$).
    /// For markers on a slab's top face pass points with $z = t/2$ and
    /// `components = [0, 1]`.
    pub fn interpolation_matrix(
        &self,
        points: &[[f64; D]],
        components: &[usize],
    ) -> Result<SparseColMat<usize, f64>, FemError> {
        if let Some(&c) = components.iter().find(|&&c| c >= D) {
            return Err(FemError::DofOutOfRange {
                context: "interpolation component",
                dof: c,
                dof_count: D,
            });
        }
        let mut triplets = Vec::new();
        for (p, &point) in points.iter().enumerate() {
            let weights = self
                .weights(point)
                .ok_or_else(|| FemError::PointOutsideMesh {
                    index: p,
                    coordinates: point.to_vec(),
                })?;
            for (k, &c) in components.iter().enumerate() {
                for &(n, w) in &weights {
                    triplets.push(Triplet::new(p * components.len() + k, n * D + c, w));
                }
            }
        }
        SparseColMat::try_new_from_triplets(
            points.len() * components.len(),
            self.mesh.dof_count(),
            &triplets,
        )
        .map_err(|e| FemError::InvalidMesh(format!("building the interpolation matrix: {e:?}")))
    }
}

/// Shape-function weights `(node, N_a(xi))` at a location.
pub fn weights_at<const D: usize>(mesh: &Mesh<D>, location: &Location<D>) -> NodeWeights {
    let nodes = mesh.element(location.element);
    let xi = &location.reference;
    let values = shape::values_and_gradients(D, mesh.kind().node_count(), xi).0;
    nodes.iter().copied().zip(values).collect()
}

fn cell_index(x: f64, origin: f64, size: f64, count: usize) -> usize {
    let i = ((x - origin) / size).floor();
    if i.is_nan() || i < 0.0 {
        0
    } else {
        (i as usize).min(count - 1)
    }
}

fn flat<const D: usize>(cell: &[usize; D], cells: &[usize; D]) -> usize {
    let mut index = 0;
    for i in (0..D).rev() {
        index = index * cells[i] + cell[i];
    }
    index
}

fn for_each_cell<const D: usize>(
    low: &[usize; D],
    high: &[usize; D],
    mut visit: impl FnMut([usize; D]),
) {
    let mut cell = *low;
    loop {
        visit(cell);
        let mut axis = 0;
        loop {
            if axis == D {
                return;
            }
            if cell[axis] < high[axis] {
                cell[axis] += 1;
                break;
            }
            cell[axis] = low[axis];
            axis += 1;
        }
    }
}
