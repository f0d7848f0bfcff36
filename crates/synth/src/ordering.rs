//! The fill-reducing ordering of the truth's sparse Cholesky factors:
//! nested dissection by METIS, on the graph of the mesh's nodes.
//!
//! Nested dissection splits the graph by a small vertex separator,
//! orders both halves first, recursively, and the separator last, so
//! that eliminating one half never fills the other. On a 3-D mesh of $n$
//! nodes it bounds the factor at $O(n^{4/3})$ entries. faer's default,
//! approximate minimum degree, decides locally and fills more on the
//! truth's slabs: the fine paper default's probe slab (820,915 free
//! unknowns) has 469 M factor entries with this ordering and 825 M with
//! AMD, the paper default's slab (74,984) 29.4 M against 48.7 M
//! (`docs/benchmarks.md`, session 43).
//!
//! Why METIS, and why through `metis-sys`: no maintained pure-Rust crate
//! computes multilevel vertex separators, and a hand-written
//! level-structure dissection filled more than AMD here (session 39). The
//! `metis` crate wraps partitioning but not `METIS_NodeND`, so this module
//! makes that one foreign call itself; it is the workspace's only
//! `unsafe` code.
//!
//! The graph is compressed before it is handed over: consecutive unknowns
//! whose columns of $K$ have the same pattern (the components of one
//! node) form one vertex, weighted by their count, and stay consecutive
//! in the ordering.

use std::sync::{Mutex, PoisonError};

use faer::sparse::SymbolicSparseColMatRef;

/// METIS keeps its random generator in one process-wide state (GKlib's
/// `mt`) and seeds it at the start of every call, so that a graph always
/// gets the same ordering. Two calls at once would race on that state,
/// and the orderings, hence the truth's round-off, would depend on the
/// threads' timing: calls take turns.
static METIS_TURN: Mutex<()> = Mutex::new(());

/// A permutation of the unknowns: `forward[new] = old`, `inverse[old] = new`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Ordering {
    pub forward: Vec<usize>,
    pub inverse: Vec<usize>,
}

/// Orders the unknowns of the symmetric matrix whose lower triangle has
/// pattern `lower` (each column's rows sorted, the diagonal included),
/// where `vertex[r]` is the graph vertex of unknown `r`: vertices are
/// numbered from 0 in order of their first unknown and each vertex's
/// unknowns are consecutive. Fails, with METIS's status, only if METIS
/// does.
pub(crate) fn nested_dissection(
    lower: SymbolicSparseColMatRef<'_, usize>,
    vertex: &[usize],
) -> Result<Ordering, String> {
    let m = lower.ncols();
    assert_eq!(vertex.len(), m, "one vertex per unknown");
    let vertices = vertex.last().map_or(0, |&v| v + 1);
    let mut first = vec![usize::MAX; vertices];
    for (r, &v) in vertex.iter().enumerate().rev() {
        first[v] = r;
    }
    // Every order of two vertices fills alike, and METIS wants one at least.
    if vertices < 3 {
        let identity: Vec<usize> = (0..m).collect();
        return Ok(Ordering {
            forward: identity.clone(),
            inverse: identity,
        });
    }
    let index =
        |n: usize| i32::try_from(n).map_err(|_| format!("{n} exceeds METIS's 32-bit indices"));
    let mut count = index(vertices)?;
    // A vertex's first unknown is the lowest of its unknowns, so the
    // lower column of that unknown reaches every later neighbour; each
    // edge is found once, from its earlier end. Rows are sorted, so
    // repeated neighbours are adjacent.
    let mut edges: Vec<(u32, u32)> = Vec::new();
    for (v, &r) in first.iter().enumerate() {
        let mut last = v;
        for i in lower.row_idx_of_col(r) {
            let w = vertex[i];
            if w != last && w > v {
                edges.push((v as u32, w as u32));
                last = w;
            }
        }
    }
    let mut degree = vec![0usize; vertices];
    for &(a, b) in &edges {
        degree[a as usize] += 1;
        degree[b as usize] += 1;
    }
    let mut xadj = Vec::with_capacity(vertices + 1);
    xadj.push(0i32);
    let mut total = 0usize;
    for d in &degree {
        total += d;
        xadj.push(index(total)?);
    }
    let mut fill: Vec<usize> = xadj[..vertices].iter().map(|&x| x as usize).collect();
    let mut adjncy = vec![0i32; total];
    for &(a, b) in &edges {
        adjncy[fill[a as usize]] = b as i32;
        fill[a as usize] += 1;
        adjncy[fill[b as usize]] = a as i32;
        fill[b as usize] += 1;
    }
    drop(edges);
    let mut weight = vec![0i32; vertices];
    for &v in vertex {
        weight[v] += 1;
    }
    let mut perm = vec![0i32; vertices];
    let mut iperm = vec![0i32; vertices];
    let mut options = [0i32; metis_sys::METIS_NOPTIONS as usize];
    let _turn = METIS_TURN.lock().unwrap_or_else(PoisonError::into_inner);
    // SAFETY: `options` has the METIS_NOPTIONS entries METIS reads and
    // writes; METIS_SetDefaultOptions touches nothing else.
    #[allow(unsafe_code)]
    let status = unsafe { metis_sys::METIS_SetDefaultOptions(options.as_mut_ptr()) };
    if status != metis_sys::rstatus_et_METIS_OK {
        return Err(format!("METIS_SetDefaultOptions returned {status}"));
    }
    // SAFETY: `count` is the number of vertices; `xadj` has count + 1
    // entries, increasing from 0 to `adjncy.len()`, and every entry of
    // `adjncy` is a vertex below `count` other than its row (a symmetric
    // graph without self-loops, as METIS requires); `weight`, `perm` and
    // `iperm` have `count` entries and `options` METIS_NOPTIONS. METIS
    // reads the graph and writes only `perm` and `iperm`, and keeps no
    // pointer after it returns. No other call runs meanwhile (`_turn`).
    #[allow(unsafe_code)]
    let status = unsafe {
        metis_sys::METIS_NodeND(
            &mut count,
            xadj.as_mut_ptr(),
            adjncy.as_mut_ptr(),
            weight.as_mut_ptr(),
            options.as_mut_ptr(),
            perm.as_mut_ptr(),
            iperm.as_mut_ptr(),
        )
    };
    if status != metis_sys::rstatus_et_METIS_OK {
        return Err(format!("METIS_NodeND returned {status}"));
    }
    let mut forward = Vec::with_capacity(m);
    for &v in &perm {
        let start = first[v as usize];
        forward.extend((start..m).take_while(|&r| vertex[r] == v as usize));
    }
    let mut inverse = vec![usize::MAX; m];
    for (new, &old) in forward.iter().enumerate() {
        inverse[old] = new;
    }
    if forward.len() != m || inverse.contains(&usize::MAX) {
        return Err("METIS returned an ordering that is not a permutation".into());
    }
    Ok(Ordering { forward, inverse })
}

/// The graph vertex of each free unknown (`free`, increasing, indices of
/// $K$'s columns), for [`nested_dissection`]: consecutive free unknowns
/// whose columns of `k` have the same rows share one.
pub(crate) fn vertices_of(k: SymbolicSparseColMatRef<'_, usize>, free: &[usize]) -> Vec<usize> {
    let mut vertex = Vec::with_capacity(free.len());
    for (r, &j) in free.iter().enumerate() {
        let same = r > 0 && k.row_idx_of_col_raw(free[r - 1]) == k.row_idx_of_col_raw(j);
        vertex.push(match (vertex.last(), same) {
            (Some(&v), true) => v,
            (Some(&v), false) => v + 1,
            (None, _) => 0,
        });
    }
    vertex
}

#[cfg(test)]
mod tests {
    use faer::Side;
    use faer::perm::PermRef;
    use faer::sparse::SymbolicSparseColMat;
    use faer::sparse::linalg::cholesky::{SymmetricOrdering, factorize_symbolic_cholesky};

    use super::*;

    /// The full and lower patterns of a matrix with `dofs` unknowns per
    /// node on the graph `neighbours` (each node's list, without itself),
    /// every node block full, as the assembly stores them.
    fn patterns(
        neighbours: &[Vec<usize>],
        dofs: usize,
    ) -> (SymbolicSparseColMat<usize>, SymbolicSparseColMat<usize>) {
        let n = neighbours.len() * dofs;
        let (mut full, mut lower) = (vec![0], vec![0]);
        let (mut full_rows, mut lower_rows) = (Vec::new(), Vec::new());
        for (node, around) in neighbours.iter().enumerate() {
            let mut nodes: Vec<usize> = around.iter().copied().chain([node]).collect();
            nodes.sort_unstable();
            nodes.dedup();
            let rows: Vec<usize> = nodes
                .iter()
                .flat_map(|&q| (0..dofs).map(move |c| q * dofs + c))
                .collect();
            for c in 0..dofs {
                let j = node * dofs + c;
                full_rows.extend(&rows);
                full.push(full_rows.len());
                lower_rows.extend(rows.iter().filter(|&&i| i >= j));
                lower.push(lower_rows.len());
            }
        }
        (
            SymbolicSparseColMat::new_checked(n, n, full, None, full_rows),
            SymbolicSparseColMat::new_checked(n, n, lower, None, lower_rows),
        )
    }

    /// A `side`^3 grid of nodes, each joined to its 26 neighbours (the
    /// pattern of trilinear bricks).
    fn cube(side: usize) -> Vec<Vec<usize>> {
        let at = |i: usize, j: usize, k: usize| (k * side + j) * side + i;
        let mut neighbours = vec![Vec::new(); side * side * side];
        for k in 0..side {
            for j in 0..side {
                for i in 0..side {
                    for (di, dj, dk) in (0..27).map(|s| (s % 3, s / 3 % 3, s / 9)) {
                        let (p, q, r) = (
                            (i + di).wrapping_sub(1),
                            (j + dj).wrapping_sub(1),
                            (k + dk).wrapping_sub(1),
                        );
                        if p < side && q < side && r < side && (p, q, r) != (i, j, k) {
                            neighbours[at(i, j, k)].push(at(p, q, r));
                        }
                    }
                }
            }
        }
        neighbours
    }

    fn assert_permutation_of_whole_vertices(ordering: &Ordering, vertex: &[usize]) {
        let m = vertex.len();
        let mut seen = vec![false; m];
        for (new, &old) in ordering.forward.iter().enumerate() {
            assert!(!seen[old], "unknown {old} ordered twice");
            seen[old] = true;
            assert_eq!(ordering.inverse[old], new);
        }
        assert_eq!(ordering.forward.len(), m);
        // A vertex's unknowns stay together and in their order.
        for pair in ordering.forward.windows(2) {
            if vertex[pair[0]] == vertex[pair[1]] {
                assert_eq!(pair[1], pair[0] + 1);
            }
        }
        for (r, &v) in vertex.iter().enumerate().skip(1) {
            if v == vertex[r - 1] {
                assert_eq!(ordering.inverse[r], ordering.inverse[r - 1] + 1);
            }
        }
    }

    #[test]
    fn the_components_of_a_node_form_one_vertex() {
        let (full, _) = patterns(&cube(3), 3);
        let free: Vec<usize> = (0..full.ncols()).collect();
        let vertex = vertices_of(full.as_ref(), &free);
        assert_eq!(vertex, (0..81).map(|r| r / 3).collect::<Vec<_>>());
        // A held component leaves the others of its node together.
        let free: Vec<usize> = (0..81).filter(|&d| d % 3 != 2 || d / 3 % 2 == 0).collect();
        let vertex = vertices_of(full.as_ref(), &free);
        let nodes: Vec<usize> = free.iter().map(|&d| d / 3).collect();
        assert_eq!(vertex, nodes);
    }

    /// The fill that nested dissection exists for: on a 3-D grid of
    /// bricks it leaves fewer entries in the Cholesky factor than faer's
    /// approximate minimum degree.
    #[test]
    fn nested_dissection_fills_less_than_minimum_degree_on_a_cube_of_bricks() {
        let (full, lower) = patterns(&cube(14), 3);
        let free: Vec<usize> = (0..full.ncols()).collect();
        let vertex = vertices_of(full.as_ref(), &free);
        let ordering = nested_dissection(lower.as_ref(), &vertex).unwrap();
        assert_permutation_of_whole_vertices(&ordering, &vertex);
        let m = free.len();
        let entries = |order: SymmetricOrdering<'_, usize>| {
            factorize_symbolic_cholesky(lower.as_ref(), Side::Lower, order, Default::default())
                .unwrap()
                .len_val()
        };
        let dissected = entries(SymmetricOrdering::Custom(PermRef::new_checked(
            &ordering.forward,
            &ordering.inverse,
            m,
        )));
        let minimum_degree = entries(SymmetricOrdering::Amd);
        println!("factor entries: nested dissection {dissected}, AMD {minimum_degree}");
        assert!(
            dissected < minimum_degree,
            "{dissected} against {minimum_degree}"
        );
    }

    /// METIS's random generator is process-wide: orderings made on many
    /// threads at once must equal the one made alone.
    #[test]
    fn orderings_made_at_once_on_many_threads_equal_the_one_made_alone() {
        let (full, lower) = patterns(&cube(9), 3);
        let free: Vec<usize> = (0..full.ncols()).collect();
        let vertex = vertices_of(full.as_ref(), &free);
        let alone = nested_dissection(lower.as_ref(), &vertex).unwrap();
        let at_once: Vec<Ordering> = std::thread::scope(|scope| {
            let threads: Vec<_> = (0..8)
                .map(|_| scope.spawn(|| nested_dissection(lower.as_ref(), &vertex).unwrap()))
                .collect();
            threads.into_iter().map(|t| t.join().unwrap()).collect()
        });
        for ordering in at_once {
            assert_eq!(ordering, alone);
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(32))]
        /// On any graph, connected or not, the ordering is a permutation
        /// that keeps each node's components together.
        #[test]
        fn the_ordering_is_a_permutation_of_whole_nodes(
            nodes in 1usize..60,
            edges in proptest::collection::vec((0usize..60, 0usize..60), 0..200),
            dofs in 1usize..4,
        ) {
            let mut neighbours = vec![Vec::new(); nodes];
            for (a, b) in edges {
                let (a, b) = (a % nodes, b % nodes);
                if a != b {
                    neighbours[a].push(b);
                    neighbours[b].push(a);
                }
            }
            let (full, lower) = patterns(&neighbours, dofs);
            let free: Vec<usize> = (0..full.ncols()).collect();
            let vertex = vertices_of(full.as_ref(), &free);
            let ordering = nested_dissection(lower.as_ref(), &vertex).unwrap();
            assert_permutation_of_whole_vertices(&ordering, &vertex);
        }
    }
}
