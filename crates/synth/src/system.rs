//! A linear system $K u = f$ with some displacement components held
//! (fixed or prescribed), factorised once by sparse Cholesky so that every
//! further load case is a back-substitution.
//!
//! With $u = (u_f, u_p)$ split into free and held components and $u_p$
//! prescribed, $K_{ff} u_f = f_f - K_{fp} u_p$; the reactions are
//! $r = K u - f$ on the held components.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::{
    LdltRef, LltRef, SymbolicCholesky, factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMat, SymbolicSparseColMat, Triplet};
use faer::{Conj, Par, Side, get_global_parallelism};

use crate::error::SynthError;

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

    /// A matrix of `n` dofs from triplets alone (duplicates are summed).
    pub fn from_triplets(n: usize, triplets: &[(usize, usize, f64)]) -> Result<Self, SynthError> {
        let all: Vec<Triplet<usize, usize, f64>> = triplets
            .iter()
            .map(|&(i, j, v)| Triplet::new(i, j, v))
            .collect();
        let matrix = SparseColMat::try_new_from_triplets(n, n, &all).map_err(|e| {
            SynthError::Factorisation {
                what: "the tangent matrix".into(),
                reason: format!("{e:?}"),
            }
        })?;
        Ok(Self { matrix })
    }

    /// Number of degrees of freedom.
    pub fn dof_count(&self) -> usize {
        self.matrix.nrows()
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
    /// Reduced index of each dof, `usize::MAX` when held.
    reduced: Vec<usize>,
    free: Vec<usize>,
    /// Boxed: the symbolic structure is large and `Factorised` is moved
    /// about inside enums.
    symbolic: Box<SymbolicCholesky<usize>>,
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
        Self::with_pivots(stiffness, held, what, Pivots::Positive)
    }

    /// [`Factorised::new`] with pivots of the given signs.
    pub fn with_pivots(
        stiffness: &Stiffness,
        held: &[bool],
        what: &str,
        pivots: Pivots,
    ) -> Result<Self, SynthError> {
        let n = stiffness.dof_count();
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
        let k = &stiffness.matrix;
        let failed = |reason: String| SynthError::Factorisation {
            what: what.to_string(),
            reason,
        };
        let m = free.len();
        let mut col_ptr = Vec::with_capacity(m + 1);
        let mut row_idx = Vec::new();
        let mut values = Vec::new();
        col_ptr.push(0);
        for &j in &free {
            let rj = reduced[j];
            for (i, v) in k.row_idx_of_col(j).zip(k.val_of_col(j)) {
                let ri = reduced[i];
                if ri != usize::MAX && ri >= rj {
                    row_idx.push(ri);
                    values.push(*v);
                }
            }
            col_ptr.push(row_idx.len());
        }
        let symbolic = SymbolicSparseColMat::new_checked(m, m, col_ptr, None, row_idx);
        let matrix = SparseColMat::new(symbolic, values);
        let symbolic = factorize_symbolic_cholesky(
            matrix.symbolic(),
            Side::Lower,
            Default::default(),
            Default::default(),
        )
        .map_err(|e| failed(format!("{e:?}")))?;
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
        let (a, side) = (matrix.as_ref(), Side::Lower);
        // The same arguments for either factorisation: only the pivots'
        // sign rule differs.
        let outcome = match pivots {
            Pivots::Positive => symbolic
                .factorize_numeric_llt(
                    &mut factor,
                    a,
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
                    a,
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
            reduced,
            free,
            symbolic: Box::new(symbolic),
            values: factor,
            pivots,
        })
    }

    /// Solves for several load vectors at once (full size; entries on held
    /// components are ignored) with the held components at zero.
    pub fn solve(&self, loads: &[&[f64]]) -> Vec<Vec<f64>> {
        let m = self.free.len();
        let mut rhs = faer::Mat::<f64>::zeros(m, loads.len());
        for (c, f) in loads.iter().enumerate() {
            for (r, &dof) in self.free.iter().enumerate() {
                rhs[(r, c)] = f[dof];
            }
        }
        let mut scratch = MemBuffer::new(
            self.symbolic
                .solve_in_place_scratch::<f64>(loads.len(), Par::Seq),
        );
        let stack = MemStack::new(&mut scratch);
        match self.pivots {
            Pivots::Positive => LltRef::new(&self.symbolic, &self.values).solve_in_place_with_conj(
                Conj::No,
                rhs.as_mut(),
                Par::Seq,
                stack,
            ),
            Pivots::AnySign => LdltRef::new(&self.symbolic, &self.values).solve_in_place_with_conj(
                Conj::No,
                rhs.as_mut(),
                Par::Seq,
                stack,
            ),
        }
        loads
            .iter()
            .enumerate()
            .map(|(c, f)| {
                let mut u = vec![0.0; f.len()];
                for (r, &dof) in self.free.iter().enumerate() {
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
            if self.reduced[dof] == usize::MAX {
                held_part[dof] = v;
            }
        }
        let load: Vec<f64> = stiffness.multiply(&held_part).iter().map(|v| -v).collect();
        let mut u = self
            .solve(&[&load])
            .pop()
            .expect("one load gives one solution");
        for (dof, &v) in held_part.iter().enumerate() {
            if self.reduced[dof] == usize::MAX {
                u[dof] = v;
            }
        }
        u
    }
}
