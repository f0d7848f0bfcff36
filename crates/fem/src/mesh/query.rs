//! Node and facet look-ups that other crates need: nodes on a face of the
//! phantom, nodes near a point or along a line, and boundary facets (edges in
//! 2-D, triangles in 3-D) for tractions and elastic supports.

use std::collections::HashMap;

use serde::{Deserialize, Serialize};

use super::Mesh;

/// A face of the phantom's bounding box, in the bundle's frame: x across,
/// y the insertion direction, z through the thickness.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Face {
    /// $x = 0$.
    Left,
    /// $x = $ width.
    Right,
    /// $y = 0$, where the needle enters.
    Front,
    /// $y = $ depth.
    Back,
    /// $z = -t/2$ (3-D only).
    Bottom,
    /// $z = +t/2$, the marker face (3-D only).
    Top,
}

impl Face {
    /// The axis normal to the face and whether it is the max side.
    pub fn axis_and_side(self) -> (usize, bool) {
        match self {
            Face::Left => (0, false),
            Face::Right => (0, true),
            Face::Front => (1, false),
            Face::Back => (1, true),
            Face::Bottom => (2, false),
            Face::Top => (2, true),
        }
    }
}

/// A boundary facet: an element edge (2-D) or face (3-D) that belongs to
/// exactly one element.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BoundaryFacet {
    /// The element that owns the facet.
    pub element: usize,
    /// Global node indices, corners first (a 2- or 3-node edge, a 3- or
    /// 6-node triangle).
    pub nodes: Vec<usize>,
}

impl<const D: usize> Mesh<D> {
    /// A length scale for geometric tolerances: $10^{-9}$ times the
    /// bounding-box diagonal.
    pub fn tolerance(&self) -> f64 {
        let (lo, hi) = self.bounding_box();
        1e-9 * (0..D).map(|i| (hi[i] - lo[i]).powi(2)).sum::<f64>().sqrt()
    }

    /// Nodes whose coordinates satisfy `predicate`, ascending.
    pub fn nodes_where(&self, predicate: impl Fn([f64; D]) -> bool) -> Vec<usize> {
        (0..self.node_count())
            .filter(|&n| predicate(self.node(n)))
            .collect()
    }

    /// Nodes on a face of the bounding box (within [`Mesh::tolerance`]).
    /// `Bottom`/`Top` of a 2-D mesh give no nodes.
    pub fn nodes_on_face(&self, face: Face) -> Vec<usize> {
        let (axis, max_side) = face.axis_and_side();
        if axis >= D {
            return Vec::new();
        }
        let (lo, hi) = self.bounding_box();
        let value = if max_side { hi[axis] } else { lo[axis] };
        let tol = self.tolerance();
        self.nodes_where(|p| (p[axis] - value).abs() <= tol)
    }

    /// The node nearest to `point` (ties: lowest index). `None` for an
    /// empty mesh.
    pub fn nearest_node(&self, point: [f64; D]) -> Option<usize> {
        (0..self.node_count())
            .map(|n| (n, distance_squared(&self.node(n), &point)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(n, _)| n)
    }

    /// Nodes within `radius` of the segment from `start` to `end`, ordered
    /// by their projection along the segment (e.g. the nodes on a needle
    /// path).
    pub fn nodes_along_segment(&self, start: [f64; D], end: [f64; D], radius: f64) -> Vec<usize> {
        let mut direction = [0.0; D];
        for i in 0..D {
            direction[i] = end[i] - start[i];
        }
        let length2: f64 = direction.iter().map(|d| d * d).sum();
        let mut hits: Vec<(usize, f64)> = Vec::new();
        for n in 0..self.node_count() {
            let p = self.node(n);
            let t = if length2 > 0.0 {
                ((0..D)
                    .map(|i| (p[i] - start[i]) * direction[i])
                    .sum::<f64>()
                    / length2)
                    .clamp(0.0, 1.0)
            } else {
                0.0
            };
            let mut closest = [0.0; D];
            for i in 0..D {
                closest[i] = start[i] + t * direction[i];
            }
            if distance_squared(&p, &closest) <= radius * radius {
                hits.push((n, t));
            }
        }
        hits.sort_by(|a, b| a.1.total_cmp(&b.1));
        hits.into_iter().map(|(n, _)| n).collect()
    }

    /// All boundary facets (edges in 2-D, triangles in 3-D).
    pub fn boundary_facets(&self) -> Vec<BoundaryFacet> {
        let local = self.kind().facets();
        let corners = self.kind().dimension();
        let mut seen: HashMap<Vec<usize>, (usize, Vec<usize>, usize)> = HashMap::new();
        for e in 0..self.element_count() {
            let element = self.element(e);
            for facet in &local {
                let nodes: Vec<usize> = facet.iter().map(|&a| element[a]).collect();
                let mut key = nodes[..corners].to_vec();
                key.sort_unstable();
                seen.entry(key)
                    .and_modify(|entry| entry.2 += 1)
                    .or_insert((e, nodes, 1));
            }
        }
        let mut facets: Vec<BoundaryFacet> = seen
            .into_values()
            .filter(|(_, _, count)| *count == 1)
            .map(|(element, nodes, _)| BoundaryFacet { element, nodes })
            .collect();
        facets.sort_by(|a, b| (a.element, &a.nodes).cmp(&(b.element, &b.nodes)));
        facets
    }

    /// Boundary facets whose nodes all lie on `face`.
    pub fn facets_on_face(&self, face: Face) -> Vec<BoundaryFacet> {
        let on_face: std::collections::HashSet<usize> =
            self.nodes_on_face(face).into_iter().collect();
        self.boundary_facets()
            .into_iter()
            .filter(|f| f.nodes.iter().all(|n| on_face.contains(n)))
            .collect()
    }

    /// Boundary facets whose nodes all satisfy `predicate` (e.g. a segment
    /// of the boundary).
    pub fn facets_where(&self, predicate: impl Fn([f64; D]) -> bool) -> Vec<BoundaryFacet> {
        self.boundary_facets()
            .into_iter()
            .filter(|f| f.nodes.iter().all(|&n| predicate(self.node(n))))
            .collect()
    }
}

fn distance_squared<const D: usize>(a: &[f64; D], b: &[f64; D]) -> f64 {
    (0..D).map(|i| (a[i] - b[i]).powi(2)).sum()
}
