//! Structured tetrahedral mesh of the slab
//! $\[0,w\]\times\[0,d\]\times\[-t/2, t/2\]$: the rectangle's grid in (x, y)
//! extruded through the thickness in equal element layers.
//!
//! Each hexahedral cell is cut into six tetrahedra around its main diagonal
//! (Kuhn's subdivision), identical in every cell, so faces match between
//! neighbours. The top face $z = t/2$ carries the markers; the needle moves
//! in the mid-plane $z = 0$.

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
        if kind.dimension() != 3 {
            return Err(FemError::InvalidMesh(format!(
                "a slab is meshed with tetrahedra, not {kind:?}"
            )));
        }
        let xs = &self.plan.x_lines;
        let ys = &self.plan.y_lines;
        let zs: Vec<f64> = (0..=self.layers)
            .map(|k| self.thickness * (k as f64 / self.layers as f64 - 0.5))
            .collect();
        let (nx, ny) = (xs.len(), ys.len());
        let id = |i: usize, j: usize, k: usize| (k * ny + j) * nx + i;
        let mut nodes = Vec::with_capacity(nx * ny * zs.len());
        for &z in &zs {
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
        let mut connectivity = Vec::with_capacity(24 * (nx - 1) * (ny - 1) * self.layers);
        for k in 0..self.layers {
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
        let linear = Mesh::new(ElementKind::Tet4, nodes, connectivity, regions)?;
        if kind == ElementKind::Tet4 {
            Ok(linear)
        } else {
            linear.to_quadratic()
        }
    }
}

fn signed_volume(nodes: &[[f64; 3]], tet: &[usize; 4]) -> f64 {
    let p = nodes[tet[0]];
    let d = |n: usize| [nodes[n][0] - p[0], nodes[n][1] - p[1], nodes[n][2] - p[2]];
    let (a, b, c) = (d(tet[1]), d(tet[2]), d(tet[3]));
    a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
        + a[2] * (b[0] * c[1] - b[1] * c[0])
}
