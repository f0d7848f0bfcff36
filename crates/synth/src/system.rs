//! A linear system $K u = f$ with some displacement components held
//! (fixed or prescribed), factorised once by sparse Cholesky so that every
//! further load case is a back-substitution.
//!
//! With $u = (u_f, u_p)$ split into free and held components and $u_p$
//! prescribed, $K_{ff} u_f = f_f - K_{fp} u_p$; the reactions are
//! $r = K u - f$ on the held components.

use std::sync::Arc;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::perm::PermRef;
use faer::sparse::linalg::cholesky::{
    LdltRef, LltRef, SymbolicCholesky, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::sparse::{
    Argsort, Pair, SparseColMat, SparseColMatRef, SymbolicSparseColMat, SymbolicSparseColMatRef,
    Triplet,
};
use faer::{Conj, Par, Side, get_global_parallelism};

use crate::error::SynthError;
use crate::ordering::{nested_dissection, vertices_of};

/// The total stiffness (elastic plus springs) in full storage.
pub(crate) struct Stiffness {
    matrix: SparseColMat<usize, f64>,
}

impl Stiffness {
    /// `elastic` plus the spring `triplets` (duplicates are summed).
    pub fn new(
        elastic: &SparseColMat<usize, f64>,
        triplets: &[(usize, usize, f64)],
    ) -> Result<Self, SynthError> {
        if triplets.is_empty() {
            return Ok(Self {
                matrix: elastic.clone(),
            });
        }
        let n = elastic.nrows();
        let mut all = Vec::with_capacity(elastic.compute_nnz() + triplets.len());
        for j in 0..n {
            for (i, v) in elastic.row_idx_of_col(j).zip(elastic.val_of_col(j)) {
                all.push(Triplet::new(i, j, *v));
            }
        }
        all.extend(triplets.iter().map(|&(i, j, v)| Triplet::new(i, j, v)));
        let matrix = SparseColMat::try_new_from_triplets(n, n, &all).map_err(|e| {
            SynthError::Factorisation {
                what: "the stiffness matrix".into(),
                reason: format!("{e:?}"),
            }
        })?;
        Ok(Self { matrix })
    }

    /// $K u$.
    pub fn multiply(&self, u: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; u.len()];
        for j in 0..self.matrix.ncols() {
            let uj = u[j];
            if uj != 0.0 {
                for (i, v) in self.matrix.row_idx_of_col(j).zip(self.matrix.val_of_col(j)) {
                    out[i] += v * uj;
                }
            }
        }
        out
    }

    /// The entry $K_{ii}$ (zero where the pattern has none).
    pub fn diagonal(&self, i: usize) -> f64 {
        self.matrix
            .row_idx_of_col(i)
            .zip(self.matrix.val_of_col(i))
            .find(|&(row, _)| row == i)
            .map_or(0.0, |(_, v)| *v)
    }
}

/// The pattern of a matrix assembled again and again from entries listed
/// in the same order (a Newton tangent, element by element): sorted once,
/// so that each assembly only sums the listed values into place.
pub(crate) struct Layout {
    symbolic: SymbolicSparseColMat<usize>,
    order: Argsort<usize>,
    entries: usize,
}

impl Layout {
    /// The pattern of an `n` x `n` matrix with entries at `positions`
    /// (row, column), duplicates allowed.
    pub fn new(n: usize, positions: &[(usize, usize)]) -> Result<Self, SynthError> {
        let pairs: Vec<Pair<usize, usize>> = positions
            .iter()
            .map(|&(row, col)| Pair { row, col })
            .collect();
        let (symbolic, order) =
            SymbolicSparseColMat::try_new_from_indices(n, n, &pairs).map_err(|e| {
                SynthError::Factorisation {
                    what: "the tangent's sparsity".into(),
                    reason: format!("{e:?}"),
                }
            })?;
        Ok(Self {
            symbolic,
            order,
            entries: positions.len(),
        })
    }

    /// The analysis of the free block of matrices of this pattern.
    pub fn analyse(&self, held: &[bool], what: &str) -> Result<Analysis, SynthError> {
        Analysis::new(self.symbolic.as_ref(), held, what)
    }

    /// Number of positions listed.
    pub fn entry_count(&self) -> usize {
        self.entries
    }

    /// The matrix with `values[k]` summed at `positions[k]`.
    pub fn assemble(&self, values: &[f64]) -> Result<Stiffness, SynthError> {
        let failed = |reason: String| SynthError::Factorisation {
            what: "the tangent matrix".into(),
            reason,
        };
        if values.len() != self.entries {
            return Err(failed(format!(
                "{} values for {} positions",
                values.len(),
                self.entries
            )));
        }
        let matrix = SparseColMat::new_from_argsort(self.symbolic.clone(), &self.order, values)
            .map_err(|e| failed(format!("{e:?}")))?;
        Ok(Stiffness { matrix })
    }
}

/// The analysis of $K_{ff}$ for one sparsity pattern of $K$ and one set
/// of held components: which dofs are free, the pattern of the lower free
/// block, where each of its entries sits among $K$'s stored values, and
/// the fill-reducing ordering (nested dissection, [`crate::ordering`])
/// and symbolic Cholesky factor.
///
/// A Newton solve refactorises a tangent whose pattern never changes, so
/// it analyses once and refactorises many times
/// ([`Factorised::with_analysis`]); the analysis (the ordering, the
/// elimination tree) is otherwise redone with every factor.
pub(crate) struct Analysis {
    /// Reduced index of each dof, `usize::MAX` when held.
    reduced: Vec<usize>,
    free: Vec<usize>,
    /// $K$'s column pointers and row indices, to check that a matrix
    /// factorised with this analysis has the pattern it was made for.
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    /// The lower free block's pattern (columns sorted) ...
    lower: SymbolicSparseColMat<usize>,
    /// ... and, for each of its entries, the index of the value in $K$.
    gather: Vec<usize>,
    symbolic: SymbolicCholesky<usize>,
}

impl Analysis {
    /// Analyses the free block of a matrix of pattern `k`; `held[dof]`
    /// marks the components that are fixed or prescribed.
    fn new(
        k: SymbolicSparseColMatRef<'_, usize>,
        held: &[bool],
        what: &str,
    ) -> Result<Self, SynthError> {
        let n = k.ncols();
        let mut reduced = vec![usize::MAX; n];
        let mut free = Vec::new();
        for dof in 0..n {
            if !held[dof] {
                reduced[dof] = free.len();
                free.push(dof);
            }
        }
        // Free dofs keep their order, so each column of the lower free
        // block is a sorted filter of the column of K: no triplet sort.
        let m = free.len();
        let mut col_ptr = Vec::with_capacity(m + 1);
        let mut row_idx = Vec::new();
        let mut gather = Vec::new();
        col_ptr.push(0);
        for &j in &free {
            let rj = reduced[j];
            for (position, i) in k.col_range(j).zip(k.row_idx_of_col(j)) {
                let ri = reduced[i];
                if ri != usize::MAX && ri >= rj {
                    row_idx.push(ri);
                    gather.push(position);
                }
            }
            col_ptr.push(row_idx.len());
        }
        let lower = SymbolicSparseColMat::new_checked(m, m, col_ptr, None, row_idx);
        let failed = |reason: String| SynthError::Factorisation {
            what: what.to_string(),
            reason,
        };
        let ordering = nested_dissection(lower.as_ref(), &vertices_of(k, &free)).map_err(failed)?;
        let permutation = PermRef::new_checked(&ordering.forward, &ordering.inverse, m);
        let symbolic = factorize_symbolic_cholesky(
            lower.as_ref(),
            Side::Lower,
            SymmetricOrdering::Custom(permutation),
            Default::default(),
        )
        .map_err(|e| failed(format!("{e:?}")))?;
        Ok(Self {
            reduced,
            free,
            col_ptr: k.col_ptr().to_vec(),
            row_idx: k.row_idx().to_vec(),
            lower,
            gather,
            symbolic,
        })
    }

    /// Whether `stiffness` has the pattern this analysis was made for.
    fn fits(&self, stiffness: &Stiffness) -> bool {
        let k = stiffness.matrix.symbolic();
        k.col_ptr() == self.col_ptr.as_slice() && k.row_idx() == self.row_idx.as_slice()
    }
}

/// $K_{ff}$ factorised for one set of held components.
///
/// The factorisation may run in parallel; the solves run on the calling
/// thread. A solve streams the whole factor $L$ (some 150 MB for the
/// default slab) through memory twice, whatever the number of right-hand
/// sides, and is bound by memory bandwidth: splitting it over threads
/// saves no time on a shared machine and costs their synchronisation,
/// while the callers already solve for all trials at once and compute the
/// load placements in parallel.
pub(crate) struct Factorised {
    analysis: Arc<Analysis>,
    values: Vec<f64>,
    pivots: Pivots,
}

/// The signs the factorisation's pivots may take.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Pivots {
    /// Positive: $K_{ff} = L L^T$ (a stiffness; fails if not positive
    /// definite).
    Positive,
    /// Any nonzero sign: $K_{ff} = L D L^T$ without pivoting (a tangent
    /// that compressive stress made indefinite).
    AnySign,
}

impl Factorised {
    /// Factorises the free block of `stiffness` as $L L^T$; `held[dof]`
    /// marks the components that are fixed or prescribed.
    pub fn new(stiffness: &Stiffness, held: &[bool], what: &str) -> Result<Self, SynthError> {
        let analysis = Arc::new(Analysis::new(stiffness.matrix.symbolic(), held, what)?);
        Self::with_analysis(&analysis, stiffness, what, Pivots::Positive)
    }

    /// Factorises the free block of `stiffness`, whose pattern `analysis`
    /// was made for, with pivots of the given signs.
    pub fn with_analysis(
        analysis: &Arc<Analysis>,
        stiffness: &Stiffness,
        what: &str,
        pivots: Pivots,
    ) -> Result<Self, SynthError> {
        let failed = |reason: String| SynthError::Factorisation {
            what: what.to_string(),
            reason,
        };
        if !analysis.fits(stiffness) {
            return Err(failed(
                "the matrix's sparsity differs from the one analysed".into(),
            ));
        }
        let k = stiffness.matrix.val();
        let values: Vec<f64> = analysis.gather.iter().map(|&at| k[at]).collect();
        let lower = SparseColMatRef::new(analysis.lower.as_ref(), &values);
        let symbolic = &analysis.symbolic;
        let mut factor = vec![0.0; symbolic.len_val()];
        let par = get_global_parallelism();
        let scratch = match pivots {
            Pivots::Positive => {
                symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default())
            }
            Pivots::AnySign => {
                symbolic.factorize_numeric_ldlt_scratch::<f64>(par, Default::default())
            }
        };
        let mut scratch = MemBuffer::try_new(scratch).map_err(|e| failed(format!("{e:?}")))?;
        let stack = MemStack::new(&mut scratch);
        let side = Side::Lower;
        // The same arguments for either factorisation: only the pivots'
        // sign rule differs.
        let outcome = match pivots {
            Pivots::Positive => symbolic
                .factorize_numeric_llt(
                    &mut factor,
                    lower,
                    side,
                    Default::default(),
                    par,
                    stack,
                    Default::default(),
                )
                .map(|_| ())
                .map_err(|e| format!("{e:?}")),
            Pivots::AnySign => symbolic
                .factorize_numeric_ldlt(
                    &mut factor,
                    lower,
                    side,
                    Default::default(),
                    par,
                    stack,
                    Default::default(),
                )
                .map(|_| ())
                .map_err(|e| format!("{e:?}")),
        };
        outcome.map_err(failed)?;
        Ok(Self {
            analysis: Arc::clone(analysis),
            values: factor,
            pivots,
        })
    }

    /// The number of components, held ones included.
    pub fn size(&self) -> usize {
        self.analysis.reduced.len()
    }

    /// Solves for several load vectors at once (full size; entries on held
    /// components are ignored) with the held components at zero.
    pub fn solve(&self, loads: &[&[f64]]) -> Vec<Vec<f64>> {
        let m = self.analysis.free.len();
        let mut rhs = faer::Mat::<f64>::zeros(m, loads.len());
        for (c, f) in loads.iter().enumerate() {
            for (r, &dof) in self.analysis.free.iter().enumerate() {
                rhs[(r, c)] = f[dof];
            }
        }
        let mut scratch = MemBuffer::new(
            self.analysis
                .symbolic
                .solve_in_place_scratch::<f64>(loads.len(), Par::Seq),
        );
        let stack = MemStack::new(&mut scratch);
        match self.pivots {
            Pivots::Positive => LltRef::new(&self.analysis.symbolic, &self.values)
                .solve_in_place_with_conj(Conj::No, rhs.as_mut(), Par::Seq, stack),
            Pivots::AnySign => LdltRef::new(&self.analysis.symbolic, &self.values)
                .solve_in_place_with_conj(Conj::No, rhs.as_mut(), Par::Seq, stack),
        }
        loads
            .iter()
            .enumerate()
            .map(|(c, f)| {
                let mut u = vec![0.0; f.len()];
                for (r, &dof) in self.analysis.free.iter().enumerate() {
                    u[dof] = rhs[(r, c)];
                }
                u
            })
            .collect()
    }

    /// Solves with the held components at `prescribed` (zero where not
    /// given) and no other load: $u_f = -K_{ff}^{-1} K_{fp} u_p$.
    pub fn solve_prescribed(&self, stiffness: &Stiffness, prescribed: &[f64]) -> Vec<f64> {
        let mut held_part = vec![0.0; prescribed.len()];
        for (dof, &v) in prescribed.iter().enumerate() {
            if self.analysis.reduced[dof] == usize::MAX {
                held_part[dof] = v;
            }
        }
        let load: Vec<f64> = stiffness.multiply(&held_part).iter().map(|v| -v).collect();
        let mut u = self
            .solve(&[&load])
            .pop()
            .expect("one load gives one solution");
        for (dof, &v) in held_part.iter().enumerate() {
            if self.analysis.reduced[dof] == usize::MAX {
                u[dof] = v;
            }
        }
        u
    }
}

#[cfg(test)]
mod tests {
    use faer::sparse::SparseColMat;

    use super::*;

    /// A chain of `n` unit masses on springs of stiffness `k[e]` between
    /// neighbours, as element entries (2 x 2 blocks, duplicates at shared
    /// nodes), plus a spring to ground at node 0.
    fn chain(k: &[f64]) -> (usize, Vec<(usize, usize)>, Vec<f64>) {
        let mut positions = Vec::new();
        let mut values = Vec::new();
        for (e, &ke) in k.iter().enumerate() {
            for (r, s, sign) in [(0, 0, 1.0), (0, 1, -1.0), (1, 0, -1.0), (1, 1, 1.0)] {
                positions.push((e + r, e + s));
                values.push(sign * ke);
            }
        }
        positions.push((0, 0));
        values.push(1.0);
        (k.len() + 1, positions, values)
    }

    fn triplets(positions: &[(usize, usize)], values: &[f64]) -> Vec<(usize, usize, f64)> {
        positions
            .iter()
            .zip(values)
            .map(|(&(i, j), &v)| (i, j, v))
            .collect()
    }

    fn empty(n: usize) -> SparseColMat<usize, f64> {
        SparseColMat::try_new_from_triplets(n, n, &[]).unwrap()
    }

    #[test]
    fn a_layout_sums_its_values_as_triplets_do() {
        let (n, positions, values) = chain(&[3.0, 1.0, 2.0, 5.0]);
        let layout = Layout::new(n, &positions).unwrap();
        let assembled = layout.assemble(&values).unwrap();
        let direct = Stiffness::new(&empty(n), &triplets(&positions, &values)).unwrap();
        for seed in 0..3 {
            let v: Vec<f64> = (0..n)
                .map(|i| ((i * 7 + seed * 3) % 5) as f64 - 2.0)
                .collect();
            assert_eq!(assembled.multiply(&v), direct.multiply(&v));
        }
        assert!(layout.assemble(&values[1..]).is_err());
    }

    /// A factor made with an analysis shared across matrices of one
    /// pattern solves as a factor analysed afresh: the same ordering, the
    /// same arithmetic.
    #[test]
    fn a_shared_analysis_factorises_as_a_fresh_one() {
        let (n, positions, _) = chain(&[1.0; 6]);
        let layout = Layout::new(n, &positions).unwrap();
        let mut held = vec![false; n];
        held[n - 1] = true;
        let analysis = Arc::new(layout.analyse(&held, "chain").unwrap());
        for stiffnesses in [
            [3.0, 1.0, 2.0, 5.0, 0.5, 4.0],
            [1.0, 9.0, 0.2, 1.0, 7.0, 2.0],
        ] {
            let (_, _, values) = chain(&stiffnesses);
            let k = layout.assemble(&values).unwrap();
            let shared =
                Factorised::with_analysis(&analysis, &k, "chain", Pivots::Positive).unwrap();
            let fresh = Factorised::new(&k, &held, "chain").unwrap();
            let load: Vec<f64> = (0..n).map(|i| 1.0 + i as f64).collect();
            let (a, b) = (shared.solve(&[&load]), fresh.solve(&[&load]));
            assert_eq!(a, b);
            // And it is a solution: K u = f on the free components.
            let ku = k.multiply(&a[0]);
            for dof in 0..n - 1 {
                assert!((ku[dof] - load[dof]).abs() < 1e-12 * 30.0, "{dof}");
            }
        }
    }

    #[test]
    fn an_analysis_refuses_a_matrix_of_another_pattern() {
        let (n, positions, values) = chain(&[1.0, 2.0, 3.0]);
        let analysis = Arc::new(
            Layout::new(n, &positions)
                .unwrap()
                .analyse(&[false; 4], "chain")
                .unwrap(),
        );
        let mut more = triplets(&positions, &values);
        more.push((0, 3, 0.1));
        more.push((3, 0, 0.1));
        let other = Stiffness::new(&empty(n), &more).unwrap();
        let refused = Factorised::with_analysis(&analysis, &other, "chain", Pivots::Positive);
        match refused {
            Err(SynthError::Factorisation { what, reason }) => {
                assert_eq!(what, "chain");
                assert!(reason.contains("sparsity"), "{reason}");
            }
            Err(e) => panic!("wrong error: {e}"),
            Ok(_) => panic!("a matrix of another pattern was factorised"),
        }
    }
}
