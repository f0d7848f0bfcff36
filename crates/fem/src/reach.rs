//! Triangular solves restricted to the part of a supernodal factor that a
//! sparse right-hand side reaches.
//!
//! With $K_{ff} = LL^T$ in supernodes (column blocks of $L$ with one
//! pattern), the forward solve $Ly = b$ changes $y$ only in the supernodes
//! that hold a nonzero of $b$ and their ancestors in the supernodal
//! elimination tree: a supernode outside that set has no nonzero of $b$ in
//! its subtree, so its $y$ stays zero and it updates nothing. The backward
//! solve $L^T x = y$ gives $x$ in a supernode from $x$ in its ancestors
//! alone (the rows of its pattern). So over an ancestor-closed set $R$ of
//! supernodes that contains every nonzero of $b$,
//! $$ y_s = L_{ss}^{-1}\Big(b_s - \sum_{c \in R,\, c \prec s} L_{sc} y_c\Big),
//! \qquad x_s = L_{ss}^{-T}\Big(y_s - \sum_{a \in R,\, s \prec a} L_{as}^T x_a\Big) $$
//! are the exact solution's entries in $R$, with no work outside it.
//!
//! A needle's load touches the few hundred dofs along its shaft, and its
//! re-placement reads the displacement next to the shaft alone
//! (`needle-diagnose`), while a nested-dissection factor spends most of its
//! entries in subdomains the shaft does not cross. faer solves with the
//! whole factor; this walks faer's supernodes itself (the arithmetic per
//! supernode is faer's dense triangular solve and product), since no
//! crate offers a solve restricted to a reach.

use faer::reborrow::{Reborrow, ReborrowMut};
use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;
use faer::{Accum, Mat, MatMut, MatRef, Par};

/// The supernodal elimination tree of a factor.
#[derive(Debug)]
pub(crate) struct SupernodeTree {
    /// The supernode of each row of the permuted matrix.
    of_row: Vec<usize>,
    /// Each supernode's parent; `None` at a root.
    parent: Vec<Option<usize>>,
    /// The first permuted row of each supernode, and the row count last.
    begin: Vec<usize>,
}

impl SupernodeTree {
    pub fn new(symbolic: &SymbolicSupernodalCholesky<usize>) -> Self {
        let count = symbolic.n_supernodes();
        let mut of_row = vec![0; symbolic.nrows()];
        for s in 0..count {
            of_row[symbolic.supernode_begin()[s]..symbolic.supernode_end()[s]].fill(s);
        }
        // A supernode's parent holds the first row below its diagonal
        // block: the smallest row of its pattern.
        let parent = (0..count)
            .map(|s| {
                let pattern = symbolic.supernode(s).pattern();
                pattern.iter().min().map(|&row| of_row[row])
            })
            .collect();
        let mut begin = symbolic.supernode_begin().to_vec();
        begin.push(symbolic.nrows());
        Self {
            of_row,
            parent,
            begin,
        }
    }

    /// Whether each supernode lies in the ancestor-closed set reached
    /// from the permuted `rows`.
    pub fn reach(&self, rows: impl IntoIterator<Item = usize>) -> Vec<bool> {
        let mut reached = vec![false; self.parent.len()];
        for row in rows {
            let mut next = Some(self.of_row[row]);
            while let Some(s) = next {
                if reached[s] {
                    break;
                }
                reached[s] = true;
                next = self.parent[s];
            }
        }
        reached
    }

    /// The permuted rows of supernode `s`.
    pub fn rows_of(&self, s: usize) -> std::ops::Range<usize> {
        self.begin[s]..self.begin[s + 1]
    }

    /// The supernode of permuted row `row`.
    pub fn supernode_of(&self, row: usize) -> usize {
        self.of_row[row]
    }
}

/// Solves $LL^T X = B$ in place on the supernodes `reached` (an
/// ancestor-closed set, from [`SupernodeTree::reach`]) for a permuted
/// right-hand side `x` whose nonzeros all lie in them; rows outside are
/// neither read nor written.
pub(crate) fn solve_reached(
    symbolic: &SymbolicSupernodalCholesky<usize>,
    values: &[f64],
    reached: &[bool],
    mut x: MatMut<'_, f64>,
) {
    let columns = x.ncols();
    let widest = (0..symbolic.n_supernodes())
        .filter(|&s| reached[s])
        .map(|s| symbolic.supernode(s).pattern().len())
        .max()
        .unwrap_or(0);
    let mut below = Mat::<f64>::zeros(widest, columns);
    let supernode = |s: usize| {
        let start = symbolic.supernode_begin()[s];
        let size = symbolic.supernode_end()[s] - start;
        let pattern = symbolic.supernode(s).pattern();
        let block = &values[symbolic.col_ptr_for_val()[s]..symbolic.col_ptr_for_val()[s + 1]];
        let matrix = MatRef::from_column_major_slice(block, size + pattern.len(), size);
        let (diagonal, off) = matrix.split_at_row(size);
        (start, size, pattern, diagonal, off)
    };
    for s in (0..symbolic.n_supernodes()).filter(|&s| reached[s]) {
        let (start, size, pattern, diagonal, off) = supernode(s);
        let mut top = x.rb_mut().subrows_mut(start, size);
        faer::linalg::triangular_solve::solve_lower_triangular_in_place(
            diagonal,
            top.rb_mut(),
            Par::Seq,
        );
        let mut update = below.as_mut().subrows_mut(0, pattern.len());
        faer::linalg::matmul::matmul(
            update.rb_mut(),
            Accum::Replace,
            off,
            top.rb(),
            1.0,
            Par::Seq,
        );
        for j in 0..columns {
            let (update, mut target) = (update.rb().col(j), x.rb_mut().col_mut(j));
            for (k, &row) in pattern.iter().enumerate() {
                target[row] -= update[k];
            }
        }
    }
    for s in (0..symbolic.n_supernodes()).rev().filter(|&s| reached[s]) {
        let (start, size, pattern, diagonal, off) = supernode(s);
        let mut gathered = below.as_mut().subrows_mut(0, pattern.len());
        for j in 0..columns {
            let (source, mut target) = (x.rb().col(j), gathered.rb_mut().col_mut(j));
            for (k, &row) in pattern.iter().enumerate() {
                target[k] = source[row];
            }
        }
        let mut top = x.rb_mut().subrows_mut(start, size);
        faer::linalg::matmul::matmul(
            top.rb_mut(),
            Accum::Add,
            off.transpose(),
            gathered.rb(),
            -1.0,
            Par::Seq,
        );
        faer::linalg::triangular_solve::solve_upper_triangular_in_place(
            diagonal.transpose(),
            top.rb_mut(),
            Par::Seq,
        );
    }
}
