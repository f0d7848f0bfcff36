//! Promotion of a linear mesh to the quadratic element with the same
//! corners: one new node at the midpoint of every edge, shared by all the
//! elements around that edge, so the quadratic mesh is conforming.

use std::collections::HashMap;

use super::Mesh;
use crate::error::FemError;

impl<const D: usize> Mesh<D> {
    /// The quadratic mesh (T3 to T6, Tet4 to Tet10) with straight edges;
    /// a quadratic mesh is returned unchanged. Nodes are renumbered
    /// spatially (see [`Mesh::renumber_spatially`]).
    pub fn to_quadratic(&self) -> Result<Self, FemError> {
        let linear = self.kind();
        let quadratic = linear.quadratic();
        if quadratic == linear {
            return Ok(self.clone());
        }
        let mut nodes = self.nodes().to_vec();
        let mut midpoints: HashMap<(usize, usize), usize> = HashMap::new();
        let mut connectivity = Vec::with_capacity(self.element_count() * quadratic.node_count());
        for e in 0..self.element_count() {
            let corners = self.element(e).to_vec();
            connectivity.extend_from_slice(&corners);
            for &(a, b) in quadratic.edges() {
                let (p, q) = (corners[a], corners[b]);
                let key = (p.min(q), p.max(q));
                let index = *midpoints.entry(key).or_insert_with(|| {
                    let mut mid = [0.0; D];
                    for i in 0..D {
                        mid[i] = 0.5 * (nodes[p][i] + nodes[q][i]);
                    }
                    nodes.push(mid);
                    nodes.len() - 1
                });
                connectivity.push(index);
            }
        }
        let mut mesh = Mesh::new(quadratic, nodes, connectivity, self.regions().to_vec())?;
        mesh.renumber_spatially();
        Ok(mesh)
    }
}
