//! Factorise the full model once: the sparse Cholesky factor of the free-dof
//! stiffness matrix, from which every column of the compliance is one pair of
//! triangular solves.

use faer::linalg::solvers::Solve;
use faer::sparse::{SparseColMat, Triplet};
use faer::{Mat, Side};
use rayon::prelude::*;

use crate::CondenseError;

/// Right-hand sides solved together: enough to amortise the walk over the
/// factor, small enough to spread over threads.
const COLUMNS_PER_TASK: usize = 12;

/// The factorised full model: a stiffness matrix with its fixed dofs removed,
/// Cholesky-factorised, and the node -> dof layout (`dofs_per_node` interleaved
/// dofs per node: node `n` owns dofs `n*d .. n*d + d`).
#[derive(Debug, Clone)]
pub struct FullModel {
    dofs_per_node: usize,
    n_nodes: usize,
    /// Global dof -> index among the free dofs.
    free_index: Vec<Option<usize>>,
    n_free: usize,
    llt: faer::sparse::linalg::solvers::Llt<usize, f64>,
}

impl FullModel {
    /// Removes the `fixed_dofs` (zero displacement) from `stiffness` and factorises
    /// the rest. Only the lower triangle of `stiffness` is read.
    pub fn factor(
        stiffness: &SparseColMat<usize, f64>,
        dofs_per_node: usize,
        fixed_dofs: &[usize],
    ) -> Result<Self, CondenseError> {
        let (rows, cols) = (stiffness.nrows(), stiffness.ncols());
        if rows != cols {
            return Err(CondenseError::NotSquare { rows, cols });
        }
        if !(2..=3).contains(&dofs_per_node) {
            return Err(CondenseError::Dimension(dofs_per_node));
        }
        if rows % dofs_per_node != 0 {
            return Err(CondenseError::Layout {
                dofs: rows,
                dofs_per_node,
            });
        }
        let mut is_fixed = vec![false; rows];
        for &dof in fixed_dofs {
            if dof >= rows {
                return Err(CondenseError::FixedDofOutOfRange { dof, n_dofs: rows });
            }
            is_fixed[dof] = true;
        }
        let mut free_index = vec![None; rows];
        let mut n_free = 0;
        for (dof, fixed) in is_fixed.iter().enumerate() {
            if !fixed {
                free_index[dof] = Some(n_free);
                n_free += 1;
            }
        }
        if n_free == 0 {
            return Err(CondenseError::NothingFree);
        }
        let mut triplets = Vec::with_capacity(stiffness.compute_nnz());
        for col in 0..cols {
            let Some(j) = free_index[col] else { continue };
            let rows_of_col = stiffness.row_idx_of_col_raw(col);
            for (&row, &value) in rows_of_col.iter().zip(stiffness.val_of_col(col)) {
                if let Some(i) = free_index[row]
                    && i >= j
                {
                    triplets.push(Triplet::new(i, j, value));
                }
            }
        }
        let reduced = SparseColMat::<usize, f64>::try_new_from_triplets(n_free, n_free, &triplets)
            .map_err(|e| CondenseError::NotPositiveDefinite(format!("{e:?}")))?;
        let llt = reduced
            .sp_cholesky(Side::Lower)
            .map_err(|e| CondenseError::NotPositiveDefinite(e.to_string()))?;
        Ok(Self {
            dofs_per_node,
            n_nodes: rows / dofs_per_node,
            free_index,
            n_free,
            llt,
        })
    }

    /// Dofs per node (2 or 3).
    pub fn dofs_per_node(&self) -> usize {
        self.dofs_per_node
    }

    /// Number of nodes of the mesh.
    pub fn n_nodes(&self) -> usize {
        self.n_nodes
    }

    /// Number of free (unconstrained) dofs.
    pub fn n_free(&self) -> usize {
        self.n_free
    }

    /// Index of a global dof among the free dofs, `None` if it is fixed.
    pub fn free_index(&self, dof: usize) -> Option<usize> {
        self.free_index.get(dof).copied().flatten()
    }

    /// Checks that `node` exists and has no fixed dof.
    pub fn check_free_node(&self, node: usize) -> Result<(), CondenseError> {
        if node >= self.n_nodes {
            return Err(CondenseError::NodeOutOfRange {
                node,
                n_nodes: self.n_nodes,
            });
        }
        let d = self.dofs_per_node;
        if (0..d).any(|a| self.free_index[node * d + a].is_none()) {
            return Err(CondenseError::NodeFixed { node });
        }
        Ok(())
    }

    /// Columns `K^{-1} e_dof` (over the free dofs) for the given global free
    /// dofs, solved in parallel (rayon) in blocks of a few right-hand sides.
    /// Column `k` of the result belongs to `free_dofs[k]` (indices among the free dofs).
    pub fn solve_unit_columns(&self, free_dofs: &[usize]) -> Mat<f64> {
        let n = self.n_free;
        let blocks: Vec<Mat<f64>> = free_dofs
            .par_chunks(COLUMNS_PER_TASK)
            .map(|chunk| {
                let mut rhs = Mat::<f64>::zeros(n, chunk.len());
                for (k, &i) in chunk.iter().enumerate() {
                    rhs[(i, k)] = 1.0;
                }
                self.llt.solve_in_place(rhs.as_mut());
                rhs
            })
            .collect();
        let mut out = Mat::<f64>::zeros(n, free_dofs.len());
        for (b, block) in blocks.iter().enumerate() {
            let start = b * COLUMNS_PER_TASK;
            out.as_mut()
                .subcols_mut(start, block.ncols())
                .copy_from(block.as_ref());
        }
        out
    }

    /// Solves `K u = f` over the free dofs (a full sparse re-solve; used as the
    /// reference cost the condensed system is compared with).
    pub fn solve(&self, rhs: &mut [f64]) -> Result<(), CondenseError> {
        if rhs.len() != self.n_free {
            return Err(CondenseError::Length {
                what: "right-hand side",
                got: rhs.len(),
                expected: self.n_free,
            });
        }
        let n = rhs.len();
        self.llt
            .solve_in_place(faer::MatMut::from_column_major_slice_mut(rhs, n, 1));
        Ok(())
    }
}
