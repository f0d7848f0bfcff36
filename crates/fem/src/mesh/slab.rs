//! Structured tetrahedral mesh of the slab
//! $\[0,w\]\times\[0,d\]\times\[-t/2, t/2\]$: the rectangle's grid in (x, y)
//! extruded through the thickness in equal element layers.
//!
//! Each hexahedral cell is cut into six tetrahedra around its main diagonal
//! (Kuhn's subdivision), identical in every cell, so faces match between
//! neighbours. The top face $z = t/2$ carries the markers; the needle moves
//! in the mid-plane $z = 0$.
//!
//! Loads in the mid-plane and through the whole thickness, on a slab
//! supported alike on both halves, give a displacement symmetric about
//! $z = 0$: $u_x, u_y$ even in $z$, $u_z$ odd. [`SlabMesh::build_symmetric`]
//! makes the bottom half the mirror image of the top, so that its discrete
//! solution is symmetric too, and [`SlabMesh::build_upper_half`] is its top
//! half alone: with $u_z = 0$ held on $z = 0$ and half of the mid-plane
//! loads, the half gives the symmetric mesh's displacement exactly, on
//! about 3/5 of the unknowns for two layers (three node planes of five).

use super::{Mesh, RectangleMesh};
use crate::element::ElementKind;
use crate::error::{FemError, positive};

/// Builder of a tetrahedral slab mesh.
#[derive(Debug, Clone, PartialEq)]
pub struct SlabMesh {
    /// The (x, y) grid, shared with the 2-D model's rectangle.
    pub plan: RectangleMesh,
    /// Slab thickness $t$ (m); z runs over $[-t/2, t/2]$.
    pub thickness: f64,
    /// Number of element layers through the thickness.
    pub layers: usize,
}

impl SlabMesh {
    /// A slab over `plan` with `layers` element layers through `thickness`.
    pub fn new(plan: RectangleMesh, thickness: f64, layers: usize) -> Result<Self, FemError> {
        positive("slab thickness", thickness)?;
        if layers == 0 {
            return Err(FemError::InvalidMesh(
                "a slab needs at least one element layer".into(),
            ));
        }
        Ok(Self {
            plan,
            thickness,
            layers,
        })
    }

    /// z coordinate of the top face (markers).
    pub fn top(&self) -> f64 {
        0.5 * self.thickness
    }

    /// The tetrahedral mesh with elements of `kind` (`Tet4` or `Tet10`), all
    /// in region 0.
    pub fn build(&self, kind: ElementKind) -> Result<Mesh<3>, FemError> {
        check_kind(kind)?;
        let zs: Vec<f64> = (0..=self.layers)
            .map(|k| self.thickness * (k as f64 / self.layers as f64 - 0.5))
            .collect();
        finish(self.kuhn(&zs)?, kind)
    }

    /// The top half $z \in [0, t/2]$ of [`SlabMesh::build_symmetric`]:
    /// `layers / 2` layers (`layers` must be even).
    pub fn build_upper_half(&self, kind: ElementKind) -> Result<Mesh<3>, FemError> {
        check_kind(kind)?;
        finish(self.kuhn(&self.upper_planes()?)?, kind)
    }

    /// The whole slab with its bottom half the mirror image of its top half
    /// in $z = 0$ (`layers` must be even): Kuhn's subdivision above, its
    /// reflection below.
    pub fn build_symmetric(&self, kind: ElementKind) -> Result<Mesh<3>, FemError> {
        check_kind(kind)?;
        let upper = self.kuhn(&self.upper_planes()?)?;
        // Plane k = 0 of the upper half is z = 0; its nodes are shared, and
        // node (i, j, k >= 1) has its mirror at `count + (i, j, k - 1)`.
        let plane = self.plan.x_lines.len() * self.plan.y_lines.len();
        let count = upper.node_count();
        let mut nodes = upper.nodes().to_vec();
        nodes.extend(upper.nodes()[plane..].iter().map(|&[x, y, z]| [x, y, -z]));
        let mirror = |n: usize| if n < plane { n } else { n - plane + count };
        let mut connectivity = upper.connectivity().to_vec();
        for tet in upper.connectivity().chunks_exact(4) {
            // A reflection turns the orientation: swap two vertices back.
            connectivity.extend_from_slice(&[
                mirror(tet[0]),
                mirror(tet[1]),
                mirror(tet[3]),
                mirror(tet[2]),
            ]);
        }
        let regions = vec![0; connectivity.len() / 4];
        finish(
            Mesh::new(ElementKind::Tet4, nodes, connectivity, regions)?,
            kind,
        )
    }

    /// The node planes of the top half, from $z = 0$ up.
    fn upper_planes(&self) -> Result<Vec<f64>, FemError> {
        if !self.layers.is_multiple_of(2) {
            return Err(FemError::InvalidMesh(format!(
                "a slab mirrored in its mid-plane needs an even number of layers, not {}",
                self.layers
            )));
        }
        let half = self.layers / 2;
        Ok((0..=half)
            .map(|k| 0.5 * self.thickness * k as f64 / half as f64)
            .collect())
    }

    /// The Tet4 mesh of the plan's grid through the node planes `zs`
    /// (ascending), Kuhn's subdivision in every cell.
    fn kuhn(&self, zs: &[f64]) -> Result<Mesh<3>, FemError> {
        let xs = &self.plan.x_lines;
        let ys = &self.plan.y_lines;
        let layers = zs.len() - 1;
        let (nx, ny) = (xs.len(), ys.len());
        let id = |i: usize, j: usize, k: usize| (k * ny + j) * nx + i;
        let mut nodes = Vec::with_capacity(nx * ny * zs.len());
        for &z in zs {
            for &y in ys {
                for &x in xs {
                    nodes.push([x, y, z]);
                }
            }
        }
        let permutations = [
            [0, 1, 2],
            [0, 2, 1],
            [1, 0, 2],
            [1, 2, 0],
            [2, 0, 1],
            [2, 1, 0],
        ];
        let mut connectivity = Vec::with_capacity(24 * (nx - 1) * (ny - 1) * layers);
        for k in 0..layers {
            for j in 0..ny - 1 {
                for i in 0..nx - 1 {
                    for perm in &permutations {
                        let mut corner = [i, j, k];
                        let mut tet = [id(i, j, k); 4];
                        for (step, &axis) in perm.iter().enumerate() {
                            corner[axis] += 1;
                            tet[step + 1] = id(corner[0], corner[1], corner[2]);
                        }
                        if signed_volume(&nodes, &tet) < 0.0 {
                            tet.swap(2, 3);
                        }
                        connectivity.extend_from_slice(&tet);
                    }
                }
            }
        }
        let regions = vec![0; connectivity.len() / 4];
        Mesh::new(ElementKind::Tet4, nodes, connectivity, regions)
    }
}

fn check_kind(kind: ElementKind) -> Result<(), FemError> {
    if kind.dimension() == 3 {
        Ok(())
    } else {
        Err(FemError::InvalidMesh(format!(
            "a slab is meshed with tetrahedra, not {kind:?}"
        )))
    }
}

/// The Tet4 mesh `linear` as elements of `kind`.
fn finish(linear: Mesh<3>, kind: ElementKind) -> Result<Mesh<3>, FemError> {
    if kind == ElementKind::Tet4 {
        Ok(linear)
    } else {
        linear.to_quadratic()
    }
}

fn signed_volume(nodes: &[[f64; 3]], tet: &[usize; 4]) -> f64 {
    let p = nodes[tet[0]];
    let d = |n: usize| [nodes[n][0] - p[0], nodes[n][1] - p[1], nodes[n][2] - p[2]];
    let (a, b, c) = (d(tet[1]), d(tet[2]), d(tet[3]));
    a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
        + a[2] * (b[0] * c[1] - b[1] * c[0])
}
