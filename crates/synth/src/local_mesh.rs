//! The 3-D slab meshed locally: an octree on the cells of a tensor grid,
//! refined towards the places where the displacement is singular or
//! steep, cut into conforming tetrahedra.
//!
//! Why: on the tensor grids of `slab_mesh` every grid line spans the
//! slab, so refining around one needle's entry refines a whole row,
//! column and layer of it. Session 39 found the slab's in-plane error set
//! by the needle's entry and path (observed orders 1.2 to 1.55 under
//! uniform refinement, the mark of singular points), and no tensor
//! variant beat uniform refinement for its memory; and since the needle's
//! line load is singular in its cross-section, a plan refined in the
//! plane alone and extruded through global node planes leaves flat
//! elements at the line (`docs/truth-world.md`, The 3-D slab).
//!
//! Each cell of the grid is halved along all three axes until it is no
//! larger than
//!
//! $$ h(\text{cell}) = \min_f \max\big(h_f,\; g\, d_f(\text{cell})\big), $$
//!
//! with $h_f$ the finest size at feature $f$ (a needle's path, its entry
//! and its tip, a probe edge, an edge of the clamped back face), $d_f$ the
//! distance from the cell to it and $g$ the grading: cells grow
//! geometrically away from every feature. Cells are then split until no
//! edge or face of one carries corners of its neighbours two levels finer
//! (2:1 balance). A cell none of whose edges carries a neighbour's corner
//! is cut into the six tetrahedra around its diagonal from the corner
//! whose dyadic indices are all even (reflected Kuhn); any other is cut
//! into cones from its centre over its faces, each face a fan from its
//! centre if a corner hangs on one of its edges, else the two triangles
//! on its even-to-odd diagonal. Every face's triangles are thus a
//! function of the face alone, and the tetrahedra conform.
//!
//! With [`Split::Plan`] the cells are halved along x and y only and the
//! distances measured in the plan: every layer of grid cells gets the
//! same quadtree, extruded through the grid's node planes. That suits a
//! singular line through the thickness (a probe's edge, where the strain
//! is uniform along z but for the top face) at a fraction of the octree's
//! cells, and not a needle, whose line load is singular in its
//! cross-section (`docs/truth-world.md`, The 3-D slab, session 42). The
//! same rules make its tetrahedra conform: no edge along z carries a
//! corner, and cells stacked in z have the same plan.
//!
//! Written by hand: the mesh generators on crates.io triangulate given
//! surfaces (tetgen bindings, Delaunay crates) or refine to a global
//! bound; none grades a box from given features while keeping given grid
//! planes as faces.

use std::collections::{HashMap, HashSet};
use std::rc::Rc;

/// A place that wants small elements: an axis-aligned box (a point, a
/// segment along an axis, a rectangle, a block) and the size there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Feature {
    /// Lower corner.
    pub lo: [f64; 3],
    /// Upper corner.
    pub hi: [f64; 3],
    /// Element size wanted on the feature (m).
    pub size: f64,
}

/// How the cells are halved.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Split {
    /// Along all three axes; distances in space.
    Octree,
    /// Along x and y only; distances in the plan.
    Plan,
}

impl Split {
    /// The axes halved and measured.
    fn axes(self) -> usize {
        match self {
            Split::Octree => 3,
            Split::Plan => 2,
        }
    }
}

/// A linear tetrahedral mesh: nodes and positively oriented tetrahedra.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct LocalMesh {
    /// Node coordinates.
    pub nodes: Vec<[f64; 3]>,
    /// Node indices of each tetrahedron.
    pub tetrahedra: Vec<[usize; 4]>,
    /// The longest side of any cell along the axes halved (m).
    pub largest: f64,
}

/// An octree cell: its box and its dyadic index within its grid cell
/// (in units of its own size), whose parities fix its diagonals.
#[derive(Debug, Clone, Copy)]
struct Cell {
    lo: [f64; 3],
    hi: [f64; 3],
    index: [u64; 3],
}

/// The midpoint of a and b, computed alike by every cell sharing an edge
/// or face, so the corners the two sides make compare equal bit for bit.
fn mid(a: f64, b: f64) -> f64 {
    0.5 * (a + b)
}

fn midpoint(p: [f64; 3], q: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|c| mid(p[c], q[c]))
}

type Key = [u64; 3];

fn key(p: [f64; 3]) -> Key {
    p.map(f64::to_bits)
}

impl Cell {
    /// The longest side along the axes `split` halves.
    fn side(&self, split: Split) -> f64 {
        (0..split.axes())
            .map(|a| self.hi[a] - self.lo[a])
            .fold(0.0, f64::max)
    }

    /// Corner `bits` (bit a set: the upper end along axis a).
    fn corner(&self, bits: usize) -> [f64; 3] {
        std::array::from_fn(|a| {
            if bits >> a & 1 == 1 {
                self.hi[a]
            } else {
                self.lo[a]
            }
        })
    }

    fn centre(&self) -> [f64; 3] {
        midpoint(self.lo, self.hi)
    }

    fn diagonal(&self, split: Split) -> f64 {
        (0..split.axes())
            .map(|a| (self.hi[a] - self.lo[a]).powi(2))
            .sum::<f64>()
            .sqrt()
    }

    fn distance(&self, f: &Feature, split: Split) -> f64 {
        (0..split.axes())
            .map(|a| (f.lo[a] - self.hi[a]).max(self.lo[a] - f.hi[a]).max(0.0))
            .map(|d| d * d)
            .sum::<f64>()
            .sqrt()
    }

    fn split(&self, split: Split, out: &mut Vec<Cell>) {
        let m = self.centre();
        let halved = |a: usize| a < split.axes();
        for bits in 0..1 << split.axes() {
            let upper = |a: usize| bits >> a & 1 == 1;
            out.push(Cell {
                lo: std::array::from_fn(|a| if upper(a) { m[a] } else { self.lo[a] }),
                hi: std::array::from_fn(|a| {
                    if upper(a) || !halved(a) {
                        self.hi[a]
                    } else {
                        m[a]
                    }
                }),
                index: std::array::from_fn(|a| {
                    if halved(a) {
                        2 * self.index[a] + upper(a) as u64
                    } else {
                        self.index[a]
                    }
                }),
            });
        }
    }

    /// The 12 edges as corner bit pairs.
    fn edges() -> impl Iterator<Item = (usize, usize)> {
        (0..8usize).flat_map(|b| {
            (0..3)
                .filter(move |a| b >> a & 1 == 0)
                .map(move |a| (b, b | 1 << a))
        })
    }

    /// The 6 faces: normal axis and corner bits in order round the face.
    fn faces() -> impl Iterator<Item = (usize, [usize; 4])> {
        (0..3).flat_map(|axis| {
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            (0..2).map(move |side| {
                let base = side << axis;
                (
                    axis,
                    [base, base | 1 << u, base | 1 << u | 1 << v, base | 1 << v],
                )
            })
        })
    }
}

/// The mesh over the tensor grid `lines` (sorted, per axis), refined
/// towards `features` with cells at most `grading` times their distance
/// from a feature (and no smaller than its size), halved as `split` says.
pub(crate) fn mesh_locally(
    lines: [&[f64]; 3],
    features: &[Feature],
    grading: f64,
    split: Split,
) -> LocalMesh {
    let mut leaves = refine(grid_cells(lines), features, grading, split);
    let corners = balance(&mut leaves, split);
    tetrahedralise(&leaves, &corners, split)
}

/// The cells of the tensor grid `lines`.
fn grid_cells(lines: [&[f64]; 3]) -> Vec<Cell> {
    let mut cells = Vec::new();
    for z in lines[2].windows(2) {
        for y in lines[1].windows(2) {
            for x in lines[0].windows(2) {
                cells.push(Cell {
                    lo: [x[0], y[0], z[0]],
                    hi: [x[1], y[1], z[1]],
                    index: [0; 3],
                });
            }
        }
    }
    cells
}

/// The leaves of the octrees on `cells` split until no side exceeds
/// $\min_f \max(h_f, g\,d_f)$.
fn refine(cells: Vec<Cell>, features: &[Feature], grading: f64, split: Split) -> Vec<Cell> {
    let wanted_from = |c: &Cell, f: &Feature| f.size.max(grading * c.distance(f, split));
    let all: Rc<[usize]> = (0..features.len()).collect();
    let mut pending: Vec<_> = cells.into_iter().map(|c| (c, all.clone())).collect();
    let mut leaves = Vec::with_capacity(pending.len());
    while let Some((cell, candidates)) = pending.pop() {
        let wanted = candidates
            .iter()
            .map(|&f| wanted_from(&cell, &features[f]))
            .fold(f64::INFINITY, f64::min);
        // A side within rounding of the wanted size is not split again.
        if cell.side(split) <= wanted * (1.0 + 1e-9) {
            leaves.push(cell);
            continue;
        }
        // A child is no farther than d_f + the cell's diagonal from a
        // feature f at distance d_f from the cell, so it wants no more
        // than `bound`; a feature that wants more than that of the whole
        // cell (and no child is nearer to it) cannot set a child's size
        // and is dropped for the children. The leaves are the same (unit
        // test below), and a cell's cost grows with the features near
        // it, not with all of them.
        let diagonal = cell.diagonal(split);
        let bound = candidates
            .iter()
            .map(|&f| {
                let f = &features[f];
                f.size.max(grading * (cell.distance(f, split) + diagonal))
            })
            .fold(f64::INFINITY, f64::min);
        let kept: Rc<[usize]> = candidates
            .iter()
            .copied()
            .filter(|&f| wanted_from(&cell, &features[f]) <= bound)
            .collect();
        let mut children = Vec::with_capacity(8);
        cell.split(split, &mut children);
        pending.extend(children.into_iter().map(|c| (c, kept.clone())));
    }
    leaves
}

/// Splits `leaves` until no edge carries a neighbour's corner at its
/// quarter and no face one at the centre of its quarter; returns the set
/// of all corners.
fn balance(leaves: &mut Vec<Cell>, split: Split) -> HashSet<Key> {
    loop {
        let corners: HashSet<Key> = leaves
            .iter()
            .flat_map(|c| (0..8).map(|b| key(c.corner(b))))
            .collect();
        let has = |p: [f64; 3]| corners.contains(&key(p));
        let mut next = Vec::with_capacity(leaves.len());
        let mut changed = false;
        for cell in leaves.iter() {
            let deep_edge = Cell::edges().any(|(a, b)| {
                let (p, q) = (cell.corner(a), cell.corner(b));
                let m = midpoint(p, q);
                has(m) && (has(midpoint(p, m)) || has(midpoint(m, q)))
            });
            let deep_face = || {
                Cell::faces().any(|(_, ring)| {
                    let c = midpoint(cell.corner(ring[0]), cell.corner(ring[2]));
                    has(c) && ring.iter().any(|&b| has(midpoint(cell.corner(b), c)))
                })
            };
            if deep_edge || deep_face() {
                changed = true;
                cell.split(split, &mut next);
            } else {
                next.push(*cell);
            }
        }
        *leaves = next;
        if !changed {
            return corners;
        }
    }
}

/// Tetrahedra of every leaf (see the module docs), positively oriented.
fn tetrahedralise(leaves: &[Cell], corners: &HashSet<Key>, split: Split) -> LocalMesh {
    let mut index: HashMap<Key, usize> = HashMap::new();
    let mut nodes = Vec::new();
    let mut node = |p: [f64; 3]| {
        *index.entry(key(p)).or_insert_with(|| {
            nodes.push(p);
            nodes.len() - 1
        })
    };
    let mut tetrahedra = Vec::with_capacity(6 * leaves.len());
    let mut largest: f64 = 0.0;
    for cell in leaves {
        largest = largest.max(cell.side(split));
        let hanging = Cell::edges()
            .any(|(a, b)| corners.contains(&key(midpoint(cell.corner(a), cell.corner(b)))));
        if !hanging {
            // Kuhn's six around the diagonal from the all-even corner.
            let even = (0..3).fold(0, |bits, a| bits | ((cell.index[a] & 1) as usize) << a);
            for order in [
                [0, 1, 2],
                [0, 2, 1],
                [1, 0, 2],
                [1, 2, 0],
                [2, 0, 1],
                [2, 1, 0],
            ] {
                let mut bits = even;
                let mut tet = [node(cell.corner(bits)); 4];
                for (k, &a) in order.iter().enumerate() {
                    bits ^= 1 << a;
                    tet[k + 1] = node(cell.corner(bits));
                }
                tetrahedra.push(tet);
            }
            continue;
        }
        let centre = node(cell.centre());
        for (axis, ring) in Cell::faces() {
            let c: [[f64; 3]; 4] = ring.map(|b| cell.corner(b));
            let mut points = Vec::with_capacity(8);
            for k in 0..4 {
                points.push(c[k]);
                let m = midpoint(c[k], c[(k + 1) % 4]);
                if corners.contains(&key(m)) {
                    points.push(m);
                }
            }
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let bit = |k: usize, a: usize| (ring[k] >> a & 1) as u64;
            let mut cut = |c: [[f64; 3]; 4], at: [[u64; 2]; 4]| {
                let [pa, ps, pb, pt] = diagonal_cut(at).map(|k| node(c[k]));
                tetrahedra.push([centre, pa, ps, pb]);
                tetrahedra.push([centre, pa, pb, pt]);
            };
            if points.len() == 4 {
                cut(
                    c,
                    std::array::from_fn(|k| [cell.index[u] + bit(k, u), cell.index[v] + bit(k, v)]),
                );
            } else if split == Split::Plan && axis != 2 {
                // A side face beside a finer column: its two halves, as
                // the finer cells cut theirs (the corners hang at the
                // middle of its top and bottom edges, not at its centre).
                let h = if u == 2 { v } else { u };
                let m = mid(cell.lo[h], cell.hi[h]);
                for half in 0..2u64 {
                    let mut c = c;
                    for (k, corner) in c.iter_mut().enumerate() {
                        corner[h] = match (half, bit(k, h)) {
                            (0, 0) => cell.lo[h],
                            (1, 1) => cell.hi[h],
                            _ => m,
                        };
                    }
                    let index = |k: usize, a: usize| {
                        if a == h {
                            2 * cell.index[h] + half + bit(k, h)
                        } else {
                            cell.index[a] + bit(k, a)
                        }
                    };
                    cut(c, std::array::from_fn(|k| [index(k, u), index(k, v)]));
                }
            } else {
                let face_centre = node(midpoint(c[0], c[2]));
                for k in 0..points.len() {
                    let (p, q) = (points[k], points[(k + 1) % points.len()]);
                    tetrahedra.push([centre, face_centre, node(p), node(q)]);
                }
            }
        }
    }
    for tet in &mut tetrahedra {
        if signed_volume(&nodes, tet) < 0.0 {
            tet.swap(2, 3);
        }
    }
    LocalMesh {
        nodes,
        tetrahedra,
        largest,
    }
}

/// The corners of a rectangle, given in order round it with their
/// in-plane dyadic indices `at`, reordered as (a, s, b, t): its diagonal
/// a-b joins the corners whose indices are both even and both odd, so
/// two cells sharing the face cut it alike.
fn diagonal_cut(at: [[u64; 2]; 4]) -> [usize; 4] {
    let even = |k: usize| at[k].iter().all(|i| i.is_multiple_of(2));
    let a = (0..4).find(|&k| even(k)).expect("one corner is even");
    [a, (a + 1) % 4, (a + 2) % 4, (a + 3) % 4]
}

/// Six times the signed volume of the tetrahedron `tet`.
pub(crate) fn signed_volume(nodes: &[[f64; 3]], tet: &[usize; 4]) -> f64 {
    let c = tet.map(|n| nodes[n]);
    let d = |k: usize| [0, 1, 2].map(|i| c[k][i] - c[0][i]);
    let (a, b, w) = (d(1), d(2), d(3));
    a[0] * (b[1] * w[2] - b[2] * w[1]) - a[1] * (b[0] * w[2] - b[2] * w[0])
        + a[2] * (b[0] * w[1] - b[1] * w[0])
}

/// The mesh and its mirror image in $z = 0$, joined on that plane.
pub(crate) fn mirrored(upper: &LocalMesh) -> LocalMesh {
    let mut index: HashMap<Key, usize> = HashMap::new();
    let mut nodes = upper.nodes.clone();
    for (n, p) in nodes.iter().enumerate() {
        index.insert(key(*p), n);
    }
    let image: Vec<usize> = upper
        .nodes
        .iter()
        .map(|p| {
            let q = [p[0], p[1], -p[2]];
            if p[2] == 0.0 {
                return index[&key(*p)];
            }
            nodes.push(q);
            nodes.len() - 1
        })
        .collect();
    let mut tetrahedra = upper.tetrahedra.clone();
    // The mirror reverses orientation; swapping two nodes restores it.
    tetrahedra.extend(
        upper
            .tetrahedra
            .iter()
            .map(|t| [image[t[0]], image[t[1]], image[t[3]], image[t[2]]]),
    );
    LocalMesh {
        nodes,
        tetrahedra,
        largest: upper.largest,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SPLITS: [Split; 2] = [Split::Octree, Split::Plan];

    /// A 2 x 1 x 1 box on a grid of unequal cells, two layers thick,
    /// refined towards a point on its lower face and a segment inside.
    const LINES: [&[f64]; 3] = [&[0.0, 1.0, 1.25, 2.0], &[0.0, 0.5, 1.0], &[0.0, 0.375, 1.0]];

    fn example(split: Split) -> (LocalMesh, Vec<Feature>, f64) {
        let features = vec![
            Feature {
                lo: [0.5, 0.0, 0.0],
                hi: [0.5, 0.0, 0.0],
                size: 1.0 / 32.0,
            },
            Feature {
                lo: [1.25, 0.0, 0.5],
                hi: [1.25, 0.75, 0.5],
                size: 1.0 / 16.0,
            },
        ];
        let grading = 0.5;
        let mesh = mesh_locally(LINES, &features, grading, split);
        (mesh, features, grading)
    }

    fn faces_shared(mesh: &LocalMesh) -> HashMap<[usize; 3], usize> {
        let mut faces = HashMap::new();
        for t in &mesh.tetrahedra {
            for skip in 0..4 {
                let mut face = [0; 3];
                let mut k = 0;
                for (i, &n) in t.iter().enumerate() {
                    if i != skip {
                        face[k] = n;
                        k += 1;
                    }
                }
                face.sort_unstable();
                *faces.entry(face).or_insert(0) += 1;
            }
        }
        faces
    }

    fn check_fills_box(mesh: &LocalMesh, lo: [f64; 3], hi: [f64; 3]) {
        let volumes: Vec<f64> = mesh
            .tetrahedra
            .iter()
            .map(|t| signed_volume(&mesh.nodes, t) / 6.0)
            .collect();
        assert!(volumes.iter().all(|&v| v > 0.0));
        let box_volume: f64 = (0..3).map(|a| hi[a] - lo[a]).product();
        let sum: f64 = volumes.iter().sum();
        assert!((sum - box_volume).abs() < 1e-12 * box_volume, "{sum}");
        // Conforming: every face is shared by two tetrahedra or lies on
        // the box.
        for (face, shared) in faces_shared(mesh) {
            let p = face.map(|n| mesh.nodes[n]);
            let on_box =
                (0..3).any(|c| p.iter().all(|q| q[c] == lo[c]) || p.iter().all(|q| q[c] == hi[c]));
            assert_eq!(shared, if on_box { 1 } else { 2 }, "{p:?}");
        }
    }

    #[test]
    fn the_tetrahedra_fill_the_box_and_conform() {
        for split in SPLITS {
            let (mesh, _, _) = example(split);
            check_fills_box(&mesh, [0.0; 3], [2.0, 1.0, 1.0]);
            let mirror = mirrored(&mesh);
            check_fills_box(&mirror, [0.0, 0.0, -1.0], [2.0, 1.0, 1.0]);
            assert_eq!(mirror.tetrahedra.len(), 2 * mesh.tetrahedra.len());
            for p in &mirror.nodes {
                let image = key([p[0], p[1], 0.0 - p[2]]);
                assert!(mirror.nodes.iter().any(|q| key(*q) == image), "{p:?}");
            }
        }
    }

    #[test]
    fn a_plan_split_keeps_the_node_planes_and_one_plan_in_every_layer() {
        let planes = [0.0, 0.375, 1.0];
        let (mesh, _, _) = example(Split::Plan);
        for t in &mesh.tetrahedra {
            let z = t.map(|n| mesh.nodes[n][2]);
            let (lo, hi) = (
                z.iter().copied().fold(f64::INFINITY, f64::min),
                z.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            );
            assert!(
                planes.windows(2).any(|w| w[0] <= lo && hi <= w[1]),
                "a tetrahedron from z = {lo} to {hi} crosses a node plane"
            );
        }
        let plan_at = |z: f64| {
            let mut points: Vec<[u64; 2]> = mesh
                .nodes
                .iter()
                .filter(|p| p[2] == z)
                .map(|p| [p[0].to_bits(), p[1].to_bits()])
                .collect();
            points.sort_unstable();
            points
        };
        let bottom = plan_at(planes[0]);
        assert!(
            bottom.len() > 12,
            "the plan is refined: {} corners",
            bottom.len()
        );
        for z in &planes[1..] {
            assert_eq!(plan_at(*z), bottom, "the plan at z = {z}");
        }
        // Fewer cells than the octree, which halves the layers too.
        let (octree, _, _) = example(Split::Octree);
        assert!(mesh.tetrahedra.len() < octree.tetrahedra.len());
    }

    #[test]
    fn the_cells_shrink_to_the_feature_size_and_grow_with_distance() {
        for split in SPLITS {
            cells_shrink_to_the_feature_size_and_grow_with_distance(split);
        }
    }

    fn cells_shrink_to_the_feature_size_and_grow_with_distance(split: Split) {
        let (mesh, features, grading) = example(split);
        for t in &mesh.tetrahedra {
            let p = t.map(|n| mesh.nodes[n]);
            let lo = [0, 1, 2].map(|c| p.iter().map(|q| q[c]).fold(f64::INFINITY, f64::min));
            let hi = [0, 1, 2].map(|c| p.iter().map(|q| q[c]).fold(f64::NEG_INFINITY, f64::max));
            let tet = Cell {
                lo,
                hi,
                index: [0; 3],
            };
            let size = tet.side(split);
            assert!(size <= mesh.largest);
            for f in &features {
                // A tetrahedron lies in its cell, no farther from a
                // feature and no larger than the cell, which obeys the
                // size wanted.
                let d = tet.distance(f, split);
                assert!(
                    size <= f.size.max(grading * d) * (1.0 + 1e-9),
                    "{lo:?} {hi:?}"
                );
            }
        }
        // Halving stops within a factor of two of the size wanted (before
        // the balance, which may split further).
        let leaves = refine(grid_cells(LINES), &features, grading, split);
        for f in &features {
            let finest = leaves
                .iter()
                .filter(|c| c.distance(f, split) == 0.0)
                .map(|c| c.side(split))
                .fold(f64::INFINITY, f64::min);
            assert!(
                finest <= f.size && finest > 0.5 * f.size,
                "{finest} for {f:?}"
            );
        }
    }

    /// The refinement without dropping features: every cell split until no
    /// side exceeds the size every feature wants of it.
    fn refine_without_pruning(
        cells: Vec<Cell>,
        features: &[Feature],
        grading: f64,
        split: Split,
    ) -> Vec<Cell> {
        let mut pending = cells;
        let mut leaves = Vec::new();
        while let Some(cell) = pending.pop() {
            let wanted = features
                .iter()
                .map(|f| f.size.max(grading * cell.distance(f, split)))
                .fold(f64::INFINITY, f64::min);
            if cell.side(split) > wanted * (1.0 + 1e-9) {
                cell.split(split, &mut pending);
            } else {
                leaves.push(cell);
            }
        }
        leaves
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(24))]

        /// Dropping the features that cannot set a child's size leaves the
        /// same leaves, in the same order, for any scatter of features.
        #[test]
        fn pruning_the_features_leaves_the_same_cells(
            boxes in proptest::collection::vec(
                ([0.0..2.0f64, 0.0..1.0f64, 0.0..1.0f64], [0.0..0.3f64, 0.0..0.3f64, 0.0..0.3f64], 3..7u32),
                1..40,
            ),
            grading in 0.25..4.0f64,
            in_plan in proptest::bool::ANY,
        ) {
            let split = if in_plan { Split::Plan } else { Split::Octree };
            let features: Vec<Feature> = boxes
                .iter()
                .map(|&(lo, extent, level)| Feature {
                    lo,
                    hi: std::array::from_fn(|a| lo[a] + extent[a]),
                    size: 0.5f64.powi(level as i32),
                })
                .collect();
            let cells = grid_cells(LINES);
            let pruned = refine(cells.clone(), &features, grading, split);
            let plain = refine_without_pruning(cells, &features, grading, split);
            proptest::prop_assert_eq!(pruned.len(), plain.len());
            for (a, b) in pruned.iter().zip(&plain) {
                proptest::prop_assert!(a.lo == b.lo && a.hi == b.hi && a.index == b.index);
            }
        }
    }
}
