//! Fill-reducing ordering of a problem's free dofs by geometric nested
//! dissection.
//!
//! A set of nodes is cut by a plane $x_a = c$ of one axis: the nodes on
//! the plane, and those below it with a neighbour above it, form a vertex
//! separator $S$ (no element joins a node below the plane outside $S$ to
//! one above it). Both sides are ordered first, each by the same rule, and
//! $S$ last, so eliminating either side fills in nothing on the other.
//! Every mesh built here is a grid cut into simplices whose nodes lie on
//! the grid's planes, and a plane of nodes is then an exact separator of
//! the smallest size: the cut tries the node coordinates next to the
//! median on every axis and keeps the smallest separator (weighted by how
//! unevenly it splits). Sets of [`LEAF_NODES`] nodes or fewer, or that no
//! plane splits, keep their order.
//!
//! faer orders by approximate minimum degree only (or by an ordering given
//! to it), and the graph partitioners in Rust are young or heavy (METIS
//! itself is a C library); a cut along the mesh's own planes needs only
//! its coordinates. On the meshes of the default campaign's diagnosis its
//! factors have as many entries as minimum degree's on the upper half
//! slab (9.19 M against 9.20 M), 23% fewer on the whole slab under a
//! foundation (30.5 M against 39.5 M, METIS's own count) and 15 to 23%
//! fewer on the plane bodies, and its wider supernodes factorise faster
//! at equal fill; the diagnosis took 0.81 to 0.87 of the time
//! (`docs/benchmarks.md`, session 32). Earlier tries (sessions 10 to 22)
//! cut across the longest axis only, down to larger leaves, and filled
//! the half slab more than minimum degree. Any
//! permutation gives the same solution up to rounding; only fill and
//! speed depend on it.

use crate::assemble::StiffnessPattern;
use crate::mesh::Mesh;

/// Largest set of nodes that is not cut further. On the slabs, leaves of
/// 2 to 8 nodes gave fills within 1% of each other, leaves of 40 nodes 2
/// to 7% more.
const LEAF_NODES: usize = 6;

/// Coordinates tried on each side of an axis's median.
const CUTS_EACH_SIDE: usize = 2;

/// The free dofs of `mesh` in elimination order: `order[k]` is the
/// reduced index (`reduced_index[dof]`, `usize::MAX` for a constrained
/// dof) of the dof eliminated `k`-th. A node's dofs stay together;
/// `pattern` gives the nodes' neighbours.
pub(crate) fn dissection_order<const D: usize>(
    mesh: &Mesh<D>,
    pattern: &StiffnessPattern,
    reduced_index: &[usize],
) -> Vec<usize> {
    let mut nodes = Vec::with_capacity(mesh.node_count());
    let mut dissection = Dissection {
        coordinates: mesh.nodes(),
        pattern,
        in_set: vec![0; mesh.node_count()],
        stamp: 0,
    };
    dissection.order((0..mesh.node_count()).collect(), &mut nodes);
    nodes
        .iter()
        .flat_map(|&n| (0..D).map(move |i| reduced_index[D * n + i]))
        .filter(|&k| k != usize::MAX)
        .collect()
}

struct Dissection<'a, const D: usize> {
    coordinates: &'a [[f64; D]],
    pattern: &'a StiffnessPattern,
    /// `in_set[n] == stamp` marks the nodes of the set being cut.
    in_set: Vec<u64>,
    stamp: u64,
}

/// A cut of a set: nodes below, above and on the separator.
struct Cut {
    below: Vec<usize>,
    above: Vec<usize>,
    separator: Vec<usize>,
}

impl<const D: usize> Dissection<'_, D> {
    /// Appends `set` to `out` in nested-dissection order.
    fn order(&mut self, set: Vec<usize>, out: &mut Vec<usize>) {
        if set.len() <= LEAF_NODES {
            out.extend(set);
            return;
        }
        self.stamp += 1;
        for &n in &set {
            self.in_set[n] = self.stamp;
        }
        let Some((axis, plane)) = self.best_plane(&set) else {
            out.extend(set);
            return;
        };
        let cut = self.cut(&set, axis, plane);
        drop(set);
        self.order(cut.below, out);
        self.order(cut.above, out);
        out.extend(cut.separator);
    }

    /// The plane with the smallest separator times $1 +$ the imbalance of
    /// the two sides (relative to the set), among the node coordinates
    /// next to each axis's median; none if no plane leaves nodes on both
    /// sides.
    fn best_plane(&self, set: &[usize]) -> Option<(usize, f64)> {
        let mut best: Option<(f64, usize, f64)> = None;
        for axis in 0..D {
            let mut values: Vec<f64> = set.iter().map(|&n| self.coordinates[n][axis]).collect();
            values.sort_unstable_by(f64::total_cmp);
            let median = values[values.len() / 2];
            values.dedup();
            let at = values.partition_point(|&v| v < median);
            let first = at.saturating_sub(CUTS_EACH_SIDE).max(1);
            let last = (at + CUTS_EACH_SIDE + 1).min(values.len().saturating_sub(1));
            for &plane in values.get(first..last).unwrap_or_default() {
                let [below, above, separator] = self.sizes(set, axis, plane);
                if below == 0 || above == 0 {
                    continue;
                }
                let imbalance = below.abs_diff(above) as f64 / set.len() as f64;
                let score = separator as f64 * (1.0 + imbalance);
                if best.is_none_or(|(s, _, _)| score < s) {
                    best = Some((score, axis, plane));
                }
            }
        }
        best.map(|(_, axis, plane)| (axis, plane))
    }

    /// Whether node `n`, below or on the plane, belongs to its separator.
    fn on_separator(&self, n: usize, axis: usize, plane: f64) -> bool {
        let x = self.coordinates[n][axis];
        x == plane
            || self
                .pattern
                .neighbours(n)
                .iter()
                .any(|&m| self.in_set[m] == self.stamp && self.coordinates[m][axis] > plane)
    }

    /// The sizes of [`Dissection::cut`]'s three parts.
    fn sizes(&self, set: &[usize], axis: usize, plane: f64) -> [usize; 3] {
        let mut sizes = [0; 3];
        for &n in set {
            let part = if self.coordinates[n][axis] > plane {
                1
            } else if self.on_separator(n, axis, plane) {
                2
            } else {
                0
            };
            sizes[part] += 1;
        }
        sizes
    }

    fn cut(&self, set: &[usize], axis: usize, plane: f64) -> Cut {
        let mut cut = Cut {
            below: Vec::new(),
            above: Vec::new(),
            separator: Vec::new(),
        };
        for &n in set {
            if self.coordinates[n][axis] > plane {
                cut.above.push(n);
            } else if self.on_separator(n, axis, plane) {
                cut.separator.push(n);
            } else {
                cut.below.push(n);
            }
        }
        cut
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::element::ElementKind;
    use crate::mesh::RectangleMesh;

    #[test]
    fn every_free_dof_appears_once_and_constrained_ones_never() {
        let mesh = RectangleMesh::uniform(1.0, 2.0, 5, 9)
            .unwrap()
            .build(ElementKind::Tri6)
            .unwrap();
        // Every third dof constrained.
        let mut reduced_index = vec![usize::MAX; mesh.dof_count()];
        let mut free = 0;
        for (dof, slot) in reduced_index.iter_mut().enumerate() {
            if dof % 3 != 0 {
                *slot = free;
                free += 1;
            }
        }
        let mut order = dissection_order(&mesh, &StiffnessPattern::new(&mesh), &reduced_index);
        assert_eq!(order.len(), free);
        order.sort_unstable();
        assert!(order.iter().enumerate().all(|(k, &r)| k == r));
    }

    #[test]
    fn the_first_cut_is_the_middle_line_and_is_eliminated_last() {
        let mesh = RectangleMesh::uniform(1.0, 1.0, 8, 8)
            .unwrap()
            .build(ElementKind::Tri6)
            .unwrap();
        let reduced_index: Vec<usize> = (0..mesh.dof_count()).collect();
        let pattern = StiffnessPattern::new(&mesh);
        let dissection = Dissection {
            coordinates: mesh.nodes(),
            pattern: &pattern,
            in_set: vec![1; mesh.node_count()],
            stamp: 1,
        };
        let all: Vec<usize> = (0..mesh.node_count()).collect();
        let (axis, plane) = dissection.best_plane(&all).unwrap();
        let cut = dissection.cut(&all, axis, plane);
        // A 17 x 17 grid of nodes: the middle line of 17 separates it.
        assert_eq!(cut.separator.len(), 17);
        assert_eq!(cut.below.len(), cut.above.len());
        let above: std::collections::HashSet<usize> = cut.above.iter().copied().collect();
        for &n in &cut.below {
            assert!(pattern.neighbours(n).iter().all(|m| !above.contains(m)));
        }
        // The separator comes last in the whole order.
        let order = dissection_order(&mesh, &pattern, &reduced_index);
        let tail: std::collections::HashSet<usize> = order[order.len() - 2 * 17..]
            .iter()
            .map(|&k| k / 2)
            .collect();
        let separator: std::collections::HashSet<usize> = cut.separator.iter().copied().collect();
        assert_eq!(tail, separator);
    }
}
