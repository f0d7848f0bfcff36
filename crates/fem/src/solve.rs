//! The linear problem $K u = f$ with Dirichlet conditions and elastic
//! supports, solved by sparse Cholesky ($K_{ff} = LL^T$, faer, with a
//! nested-dissection ordering along the mesh's planes, see `dissect`).
//!
//! [`LinearProblem`] keeps the assembled $K$, the reduced pattern of
//! $K_{ff}$, its symbolic factorisation (computed once) and the numeric
//! factor, so that
//!
//! - new loads cost two triangular solves ([`LinearProblem::solve`],
//!   [`LinearProblem::solve_many`]), and loads on a few dofs whose
//!   solution is wanted near them a part of those
//!   ([`LinearProblem::displacements_near`], see `reach`);
//! - new materials cost one parallel assembly and one numeric factorisation
//!   ([`LinearProblem::factorize`]), reusing pattern and symbolic analysis;
//! - so do new spring stiffnesses of the same supports
//!   ([`LinearProblem::scale_support`]): springs only add values inside the
//!   elements' pattern, so a fit that varies a support's stiffness never
//!   redoes the ordering.
//!
//! Before factorising, the constraints are checked against the rigid-body
//! modes (2 translations and 1 rotation in 2-D, 3 and 3 in 3-D): a mode that
//! no prescribed dof and no support resists makes $K_{ff}$ singular and is
//! reported as [`FemError::Unconstrained`] rather than a garbage solution.

use std::cell::Cell;
use std::mem::MaybeUninit;
use std::sync::Arc;

use faer::dyn_stack::{MemStack, StackReq};
use faer::perm::PermRef;
use faer::reborrow::{IntoConst, ReborrowMut};
use faer::sparse::linalg::cholesky::{
    LltRef, SymbolicCholesky, SymbolicCholeskyRaw, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMat, SparseColMatRef, SymbolicSparseColMat};
use faer::{Conj, MatMut, Side};
use nalgebra::DMatrix;

use crate::assemble::{Assembler, multiply};
use crate::dirichlet::Dirichlet;
use crate::dissect::dissection_order;
use crate::error::FemError;
use crate::material::Materials;
use crate::mesh::Mesh;
use crate::reach::{SupernodeTree, solve_reached};
use crate::support::Support;

/// Displacements and reactions of one solve.
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    /// Nodal displacements, interleaved $(u_x, u_y[, u_z])$ per node.
    pub displacement: Vec<f64>,
    /// Reactions $r = K u - f$: the forces that the constraints apply, zero
    /// at free dofs.
    pub reactions: Vec<f64>,
}

/// A linear elastic problem with a kept factorisation.
///
/// Clones share the symbolic analysis; [`Clone::clone_from`] between two
/// of them copies only values into the storage the target already has.
#[derive(Debug)]
pub struct LinearProblem<const D: usize> {
    assembler: Assembler<D>,
    supports: Vec<Support<D>>,
    dirichlet: Dirichlet,
    /// Free dofs, ascending; `reduced_index[dof]` is the position of a free
    /// dof in this list, `usize::MAX` for constrained dofs.
    free: Vec<usize>,
    reduced_index: Vec<usize>,
    /// Full $K$ (elastic plus springs), no constraints applied.
    stiffness: SparseColMat<usize, f64>,
    /// Per support, its spring matrix as `(position in stiffness values,
    /// value)` pairs, and the factor it is added with.
    springs: Vec<(Vec<(usize, f64)>, f64)>,
    /// Lower triangle of $K_{ff}$ and, per entry, its position in `stiffness`.
    reduced: SparseColMat<usize, f64>,
    gather: Vec<usize>,
    factor: CholeskyFactor,
}

/// A numeric Cholesky factor $K_{ff} = LL^T$ on a symbolic analysis that
/// is computed once and shared by clones.
///
/// faer's `Llt` allocates its factor anew at every numeric factorisation;
/// this keeps the values of $L$ in one vector that a factorisation on the
/// same pattern overwrites. A problem factorised again with new materials
/// then touches no fresh memory: on the default campaign's graded slab the
/// factor is 74 MB, and the kernel's clearing of its new pages had 7.4% of
/// the default diagnosis's profile (`docs/benchmarks.md`, session 18). The
/// arithmetic is faer's own (`factorize_numeric_llt`, `LltRef`), with the
/// same defaults as `Llt`.
#[derive(Debug, Clone)]
pub struct CholeskyFactor {
    analysis: Arc<Analysis>,
    values: Vec<f64>,
    factorized: bool,
}

/// A symbolic analysis and, for a supernodal one, its elimination tree of
/// supernodes (for [`LinearProblem::displacements_near`]).
#[derive(Debug)]
struct Analysis {
    symbolic: SymbolicCholesky<usize>,
    tree: Option<SupernodeTree>,
}

impl Analysis {
    fn new(symbolic: SymbolicCholesky<usize>) -> Self {
        let tree = match symbolic.raw() {
            SymbolicCholeskyRaw::Supernodal(supernodal) => Some(SupernodeTree::new(supernodal)),
            SymbolicCholeskyRaw::Simplicial(_) => None,
        };
        Self { symbolic, tree }
    }
}

impl CholeskyFactor {
    /// An unfactorised factor on `analysis`.
    fn new(analysis: Arc<Analysis>) -> Self {
        Self {
            analysis,
            values: Vec::new(),
            factorized: false,
        }
    }

    /// The symbolic analysis (ordering, elimination tree, pattern of $L$).
    pub fn symbolic(&self) -> &SymbolicCholesky<usize> {
        &self.analysis.symbolic
    }

    /// Whether [`CholeskyFactor::factorize`] has succeeded since the last
    /// change.
    pub fn is_factorized(&self) -> bool {
        self.factorized
    }

    /// Factorises `lower`, the lower triangle of a matrix with the pattern
    /// of the symbolic analysis, reusing the storage of the last factor.
    pub fn factorize(&mut self, lower: SparseColMatRef<'_, usize, f64>) -> Result<(), FemError> {
        self.factorized = false;
        let par = faer::get_global_parallelism();
        // Zeroed as faer's `Llt` does for a fresh factor; the pages are the
        // last factor's, so this costs no page faults.
        self.values.clear();
        let symbolic = &self.analysis.symbolic;
        self.values.resize(symbolic.len_val(), 0.0);
        let scratch = symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default());
        with_scratch(scratch, |stack| {
            symbolic.factorize_numeric_llt::<f64>(
                &mut self.values,
                lower,
                Side::Lower,
                Default::default(),
                par,
                stack,
                Default::default(),
            )
        })
        .map_err(|e| FemError::Factorization(format!("{e:?}")))?;
        self.factorized = true;
        Ok(())
    }

    /// Solves $LL^T X = B$ in place, one right-hand side per column of `rhs`.
    pub fn solve_in_place(&self, rhs: MatMut<'_, f64>) -> Result<(), FemError> {
        if !self.factorized {
            return Err(FemError::Factorization(
                "factorize() has not succeeded yet".into(),
            ));
        }
        self.solve_factorized(rhs);
        Ok(())
    }

    fn solve_factorized(&self, rhs: MatMut<'_, f64>) {
        let par = faer::get_global_parallelism();
        let symbolic = &self.analysis.symbolic;
        let scratch = symbolic.solve_in_place_scratch::<f64>(rhs.ncols(), par);
        with_scratch(scratch, |stack| {
            LltRef::new(symbolic, &self.values).solve_in_place_with_conj(Conj::No, rhs, par, stack);
        });
    }
}

thread_local! {
    /// This thread's workspace for faer's factorisations and solves.
    static SCRATCH: Cell<Vec<MaybeUninit<u8>>> = const { Cell::new(Vec::new()) };
    /// This thread's storage for the right-hand sides of
    /// [`LinearProblem::displacements_many`].
    static RIGHT_HAND_SIDES: Cell<Vec<f64>> = const { Cell::new(Vec::new()) };
}

/// Runs `work` on this thread's workspace, grown to `requirement`.
///
/// A fresh workspace per call is mapped anew by the allocator once it is
/// large (a slab's solve of forty loads), and the kernel clears its pages:
/// in the default diagnosis, fresh pages cost 14 to 19 s of system time,
/// and this workspace was a fifth of their faults (`docs/benchmarks.md`,
/// session 29). The workspace is taken out while in use, so a call nested
/// in `work` (rayon runs other jobs on a thread that waits in a join) gets
/// one of its own instead of aliasing it.
fn with_scratch<R>(requirement: StackReq, work: impl FnOnce(&mut MemStack) -> R) -> R {
    let bytes = requirement.unaligned_bytes_required();
    let mut buffer = SCRATCH.take();
    if buffer.len() < bytes {
        buffer.resize(bytes, MaybeUninit::uninit());
    }
    let out = work(MemStack::new(&mut buffer[..bytes]));
    SCRATCH.set(buffer);
    out
}

impl<const D: usize> Clone for LinearProblem<D> {
    fn clone(&self) -> Self {
        Self {
            assembler: self.assembler.clone(),
            supports: self.supports.clone(),
            dirichlet: self.dirichlet.clone(),
            free: self.free.clone(),
            reduced_index: self.reduced_index.clone(),
            stiffness: self.stiffness.clone(),
            springs: self.springs.clone(),
            reduced: self.reduced.clone(),
            gather: self.gather.clone(),
            factor: self.factor.clone(),
        }
    }

    /// Between clones of one problem (the same symbolic analysis), copies
    /// the values that may differ (supports' stiffnesses, prescribed
    /// values, $K$, $K_{ff}$ and the factor) into `self`'s storage: mesh,
    /// patterns and dof maps cannot differ, since no method changes them.
    /// A caller that factorises many materials in turn (the diagnosis: a
    /// 74 MB factor on the default campaign's slab) then reuses the pages
    /// of a problem it is done with instead of clearing new ones.
    fn clone_from(&mut self, source: &Self) {
        if !Arc::ptr_eq(&self.factor.analysis, &source.factor.analysis) {
            *self = source.clone();
            return;
        }
        self.supports.clone_from(&source.supports);
        self.dirichlet.clone_from(&source.dirichlet);
        self.stiffness
            .val_mut()
            .copy_from_slice(source.stiffness.val());
        for (mine, theirs) in self.springs.iter_mut().zip(&source.springs) {
            mine.1 = theirs.1;
        }
        self.reduced.val_mut().copy_from_slice(source.reduced.val());
        self.factor.values.clone_from(&source.factor.values);
        self.factor.factorized = source.factor.factorized;
    }
}

impl<const D: usize> LinearProblem<D> {
    /// Sets up the problem: checks constraints and supports, builds the
    /// reduced pattern and the symbolic factorisation. Call
    /// [`LinearProblem::factorize`] before solving.
    pub fn new(
        assembler: Assembler<D>,
        supports: Vec<Support<D>>,
        dirichlet: Dirichlet,
    ) -> Result<Self, FemError> {
        let mesh = assembler.mesh();
        let dof_count = mesh.dof_count();
        if let Some((dof, _)) = dirichlet.iter().find(|&(d, _)| d >= dof_count) {
            return Err(FemError::DofOutOfRange {
                context: "Dirichlet condition",
                dof,
                dof_count,
            });
        }
        let mut total = (!supports.is_empty()).then(|| assembler.pattern().zeros());
        let mut springs = Vec::with_capacity(supports.len());
        for support in &supports {
            let mut s = assembler.pattern().zeros();
            support.add_to(mesh, assembler.formulation(), assembler.pattern(), &mut s)?;
            if let Some(total) = total.as_mut() {
                for (t, v) in total.val_mut().iter_mut().zip(s.val()) {
                    *t += v;
                }
            }
            let entries = s
                .val()
                .iter()
                .enumerate()
                .filter(|(_, v)| **v != 0.0)
                .map(|(k, &v)| (k, v))
                .collect();
            springs.push((entries, 1.0));
        }
        let free_modes = free_rigid_modes(mesh, &dirichlet, total.as_ref());
        if free_modes > 0 {
            return Err(FemError::Unconstrained { free_modes });
        }
        let free: Vec<usize> = (0..dof_count).filter(|&d| !dirichlet.contains(d)).collect();
        let mut reduced_index = vec![usize::MAX; dof_count];
        for (k, &d) in free.iter().enumerate() {
            reduced_index[d] = k;
        }
        let stiffness = assembler.pattern().zeros();
        let full = stiffness.symbolic();
        let mut col_ptr = Vec::with_capacity(free.len() + 1);
        let mut row_idx = Vec::new();
        let mut gather = Vec::new();
        col_ptr.push(0);
        for (jr, &j) in free.iter().enumerate() {
            for p in full.col_ptr()[j]..full.col_ptr()[j + 1] {
                let ir = reduced_index[full.row_idx()[p]];
                if ir != usize::MAX && ir >= jr {
                    row_idx.push(ir);
                    gather.push(p);
                }
            }
            col_ptr.push(row_idx.len());
        }
        let reduced_symbolic =
            SymbolicSparseColMat::new_checked(free.len(), free.len(), col_ptr, None, row_idx);
        let order = dissection_order(mesh, assembler.pattern(), &reduced_index);
        let mut inverse = vec![0; order.len()];
        for (position, &k) in order.iter().enumerate() {
            inverse[k] = position;
        }
        let symbolic = factorize_symbolic_cholesky(
            reduced_symbolic.as_ref(),
            Side::Lower,
            SymmetricOrdering::Custom(PermRef::new_checked(&order, &inverse, order.len())),
            Default::default(),
        )
        .map_err(|e| FemError::Factorization(format!("symbolic analysis: {e:?}")))?;
        let reduced = SparseColMat::new(reduced_symbolic, vec![0.0; gather.len()]);
        Ok(Self {
            assembler,
            supports,
            dirichlet,
            free,
            reduced_index,
            stiffness,
            springs,
            reduced,
            gather,
            factor: CholeskyFactor::new(Arc::new(Analysis::new(symbolic))),
        })
    }

    /// Assembles $K(E,\nu)$ for `materials` (reusing storage and pattern),
    /// adds the supports, and computes the numeric Cholesky factor of
    /// $K_{ff}$ reusing the symbolic analysis and the last factor's storage.
    pub fn factorize(&mut self, materials: &Materials) -> Result<(), FemError> {
        self.factor.factorized = false;
        self.assembler
            .stiffness_into(materials, &mut self.stiffness)?;
        let values = self.stiffness.val_mut();
        for (entries, factor) in &self.springs {
            for &(k, v) in entries {
                values[k] += factor * v;
            }
        }
        let values = self.stiffness.val();
        for (r, &p) in self.reduced.val_mut().iter_mut().zip(&self.gather) {
            *r = values[p];
        }
        if self.reduced.val().iter().any(|v| !v.is_finite()) {
            return Err(FemError::NonFinite("stiffness matrix"));
        }
        self.factor.factorize(self.reduced.as_ref())
    }

    /// The assembler (mesh, formulation, pattern).
    pub fn assembler(&self) -> &Assembler<D> {
        &self.assembler
    }

    /// The mesh.
    pub fn mesh(&self) -> &Mesh<D> {
        self.assembler.mesh()
    }

    /// The supports.
    pub fn supports(&self) -> &[Support<D>] {
        &self.supports
    }

    /// Multiplies the stiffness of support `index` (in the order given to
    /// [`LinearProblem::new`]) by `factor` > 0, from the next
    /// [`LinearProblem::factorize`] on. Pattern and symbolic analysis are
    /// kept (a clone of a problem shares the latter), and
    /// [`LinearProblem::supports`] reports the new stiffness.
    pub fn scale_support(&mut self, index: usize, factor: f64) -> Result<(), FemError> {
        if !(factor.is_finite() && factor > 0.0) {
            return Err(FemError::InvalidValue {
                field: "support stiffness factor",
                value: factor,
                reason: "must be finite and positive",
            });
        }
        let count = self.supports.len();
        let (Some(support), Some(springs)) =
            (self.supports.get_mut(index), self.springs.get_mut(index))
        else {
            return Err(FemError::InvalidValue {
                field: "support index",
                value: index as f64,
                reason: if count == 0 {
                    "the problem has no supports"
                } else {
                    "beyond the problem's supports"
                },
            });
        };
        match support {
            Support::Boundary { stiffness, .. } | Support::Foundation { stiffness } => {
                for k in stiffness.iter_mut() {
                    *k *= factor;
                }
            }
        }
        springs.1 *= factor;
        self.factor.factorized = false;
        Ok(())
    }

    /// The Dirichlet conditions.
    pub fn dirichlet(&self) -> &Dirichlet {
        &self.dirichlet
    }

    /// Changes prescribed values of already-constrained dofs (no
    /// refactorisation needed); an unconstrained `dof` is an error.
    pub fn set_prescribed(&mut self, dof: usize, value: f64) -> Result<(), FemError> {
        if !self.dirichlet.contains(dof) {
            return Err(FemError::DofOutOfRange {
                context: "set_prescribed on a free dof",
                dof,
                dof_count: self.stiffness.nrows(),
            });
        }
        self.dirichlet.set(dof, value)?;
        Ok(())
    }

    /// The full assembled stiffness $K$ (elastic plus supports), before
    /// constraints, in full symmetric storage (valid after `factorize`).
    pub fn stiffness(&self) -> &SparseColMat<usize, f64> {
        &self.stiffness
    }

    /// The lower triangle of the reduced matrix $K_{ff}$ (free dofs in
    /// ascending order, see [`LinearProblem::free_dofs`]).
    pub fn reduced_stiffness(&self) -> &SparseColMat<usize, f64> {
        &self.reduced
    }

    /// The Cholesky factor of $K_{ff}$ (after `factorize`).
    pub fn factorization(&self) -> Option<&CholeskyFactor> {
        self.factor.is_factorized().then_some(&self.factor)
    }

    /// A new, unfactorised factor on the symbolic analysis of $K_{ff}$
    /// (shared, not recomputed): for another matrix of the same pattern,
    /// such as a tangent stiffness.
    pub fn new_factor(&self) -> CholeskyFactor {
        CholeskyFactor::new(Arc::clone(&self.factor.analysis))
    }

    /// Free dofs in ascending order: row `k` of the reduced system is dof
    /// `free_dofs()[k]`.
    pub fn free_dofs(&self) -> &[usize] {
        &self.free
    }

    /// Position of `dof` in the reduced system, `None` if constrained.
    pub fn reduced_index(&self, dof: usize) -> Option<usize> {
        self.reduced_index
            .get(dof)
            .copied()
            .filter(|&k| k != usize::MAX)
    }

    fn factor(&self) -> Result<&CholeskyFactor, FemError> {
        self.factorization()
            .ok_or_else(|| FemError::Factorization("factorize() has not succeeded yet".into()))
    }

    /// Solves $K_{ff} X = B$ in place for reduced right-hand sides (one per
    /// column of `rhs`, `free_dofs().len()` rows).
    pub fn solve_reduced_in_place(&self, rhs: MatMut<'_, f64>) -> Result<(), FemError> {
        if rhs.nrows() != self.free.len() {
            return Err(FemError::DimensionMismatch {
                context: "reduced right-hand side",
                expected: self.free.len(),
                actual: rhs.nrows(),
            });
        }
        solve_split(self.factor()?, rhs);
        Ok(())
    }

    /// Solves for the displacement under nodal loads `loads` (full,
    /// interleaved, length `dof_count`) with the prescribed values, and
    /// returns displacements and reactions.
    pub fn solve(&self, loads: &[f64]) -> Result<Solution, FemError> {
        let mut solutions = self.solve_many(&[loads])?;
        Ok(solutions.remove(0))
    }

    /// Solves several load cases at once (one factorisation, one blocked
    /// triangular solve), with the reactions of each.
    pub fn solve_many(&self, loads: &[&[f64]]) -> Result<Vec<Solution>, FemError> {
        let displacements = self.displacements_many(loads)?;
        let dof_count = self.stiffness.nrows();
        Ok(displacements
            .into_iter()
            .zip(loads)
            .map(|(u, f)| {
                let ku = multiply(&self.stiffness, &u);
                let mut reactions = vec![0.0; dof_count];
                for (d, _) in self.dirichlet.iter() {
                    reactions[d] = ku[d] - f[d];
                }
                Solution {
                    displacement: u,
                    reactions,
                }
            })
            .collect())
    }

    /// The displacements alone of several load cases (no reactions: one
    /// sparse product per case less than [`LinearProblem::solve_many`]).
    pub fn displacements_many(&self, loads: &[&[f64]]) -> Result<Vec<Vec<f64>>, FemError> {
        let (prescribed, lift) = self.lift_of(loads)?;
        let factor = self.factor()?;
        let free = self.free.len();
        // This thread's kept storage (see `with_scratch`): on the default
        // campaign's slab the 40 right-hand sides of one call take 12 MB.
        // Every value is written below before it is read: no zeroing.
        let mut storage = RIGHT_HAND_SIDES.take();
        storage.resize(free * loads.len(), 0.0);
        storage.truncate(free * loads.len());
        if free > 0 {
            for (column, f) in storage.chunks_exact_mut(free).zip(loads) {
                for (value, &d) in column.iter_mut().zip(&self.free) {
                    *value = f[d] - lift.as_ref().map_or(0.0, |l| l[d]);
                }
            }
            solve_split(
                factor,
                MatMut::from_column_major_slice_mut(&mut storage, free, loads.len()),
            );
        }
        // The prescribed values are finite (`Dirichlet` refuses others).
        let finite = storage.iter().all(|v| v.is_finite());
        let out = (0..loads.len())
            .map(|c| {
                let mut u = prescribed.clone();
                for (&value, &d) in storage[c * free..(c + 1) * free].iter().zip(&self.free) {
                    u[d] = value;
                }
                u
            })
            .collect();
        RIGHT_HAND_SIDES.set(storage);
        if !finite {
            return Err(FemError::NonFinite("displacement solution"));
        }
        Ok(out)
    }

    /// The displacements of several load cases at the dofs `wanted`, and
    /// at every other dof the solve reaches; `NaN` at the free dofs it
    /// does not.
    ///
    /// The triangular solves run over the supernodes of the factor that
    /// hold a nonzero of a load (after the lift of the prescribed values)
    /// or a wanted dof, and their ancestors (see `reach`): for loads on a
    /// few dofs, whose solution is wanted near them, a fraction of the
    /// whole solve. The entries computed are those of
    /// [`LinearProblem::displacements_many`] up to rounding. A factor too
    /// small for faer's supernodal layout is solved whole, every entry
    /// computed.
    pub fn displacements_near(
        &self,
        loads: &[&[f64]],
        wanted: &[usize],
    ) -> Result<Vec<Vec<f64>>, FemError> {
        let dof_count = self.stiffness.nrows();
        if let Some(&dof) = wanted.iter().find(|&&d| d >= dof_count) {
            return Err(FemError::DofOutOfRange {
                context: "wanted dof",
                dof,
                dof_count,
            });
        }
        let factor = self.factor()?;
        let symbolic = factor.symbolic();
        let (Some(tree), SymbolicCholeskyRaw::Supernodal(supernodal)) =
            (&factor.analysis.tree, symbolic.raw())
        else {
            return self.displacements_many(loads);
        };
        let (prescribed, lift) = self.lift_of(loads)?;
        // The row of the permuted system of reduced index `k`.
        let inverse = symbolic.perm().map(|p| p.arrays().1);
        let row_of = |k: usize| inverse.map_or(k, |inverse| inverse[k]);
        let mut entries = Vec::new();
        for (c, f) in loads.iter().enumerate() {
            for (k, &d) in self.free.iter().enumerate() {
                let row = row_of(k);
                let load = f[d] - lift.as_ref().map_or(0.0, |l| l[d]);
                if load != 0.0 {
                    entries.push((row, c, load));
                }
            }
        }
        let wanted_rows = wanted
            .iter()
            .filter_map(|&d| self.reduced_index(d).map(row_of));
        let reached = tree.reach(entries.iter().map(|&(row, _, _)| row).chain(wanted_rows));
        // This thread's kept storage (see `displacements_many`); the solve
        // reads and writes the reached rows alone, so only they are zeroed.
        let free = self.free.len();
        let mut storage = RIGHT_HAND_SIDES.take();
        storage.resize(free * loads.len(), 0.0);
        let mut x = MatMut::from_column_major_slice_mut(
            &mut storage[..free * loads.len()],
            free,
            loads.len(),
        );
        for (s, _) in reached.iter().enumerate().filter(|(_, r)| **r) {
            let span = tree.rows_of(s);
            for c in 0..loads.len() {
                x.rb_mut()
                    .col_mut(c)
                    .subrows_mut(span.start, span.len())
                    .fill(0.0);
            }
        }
        for &(row, c, load) in &entries {
            x[(row, c)] = load;
        }
        solve_reached(supernodal, &factor.values, &reached, x.rb_mut());
        let x = x.into_const();
        let mut finite = true;
        let out = (0..loads.len())
            .map(|c| {
                let mut u = prescribed.clone();
                let column = x.col(c);
                for (k, &d) in self.free.iter().enumerate() {
                    let row = row_of(k);
                    u[d] = if reached[tree.supernode_of(row)] {
                        finite &= column[row].is_finite();
                        column[row]
                    } else {
                        f64::NAN
                    };
                }
                u
            })
            .collect();
        RIGHT_HAND_SIDES.set(storage);
        if !finite {
            return Err(FemError::NonFinite("displacement solution"));
        }
        Ok(out)
    }

    /// Checks `loads` and returns the prescribed displacements (zero at
    /// free dofs) and, unless they are all zero, their lift $K u_c$, whose
    /// free part the loads' right-hand sides subtract.
    fn lift_of(&self, loads: &[&[f64]]) -> Result<(Vec<f64>, Option<Vec<f64>>), FemError> {
        let dof_count = self.stiffness.nrows();
        for f in loads {
            if f.len() != dof_count {
                return Err(FemError::DimensionMismatch {
                    context: "load vector",
                    expected: dof_count,
                    actual: f.len(),
                });
            }
            if let Some(&value) = f.iter().find(|v| !v.is_finite()) {
                return Err(FemError::InvalidValue {
                    field: "load vector",
                    value,
                    reason: "must be finite",
                });
            }
        }
        let mut prescribed = vec![0.0; dof_count];
        for (d, v) in self.dirichlet.iter() {
            prescribed[d] = v;
        }
        let lift = (self.dirichlet.iter().any(|(_, v)| v != 0.0))
            .then(|| multiply(&self.stiffness, &prescribed));
        Ok((prescribed, lift))
    }

    /// Nodal forces $f = K u$ that hold the body at displacement `u`.
    pub fn nodal_forces(&self, displacement: &[f64]) -> Result<Vec<f64>, FemError> {
        if displacement.len() != self.stiffness.nrows() {
            return Err(FemError::DimensionMismatch {
                context: "displacement",
                expected: self.stiffness.nrows(),
                actual: displacement.len(),
            });
        }
        Ok(multiply(&self.stiffness, displacement))
    }
}

/// Fewest right-hand sides given a thread of their own: narrower blocks
/// make poor use of the blocked kernels. A judgement, not a tuned value.
const MIN_COLUMNS_PER_THREAD: usize = 4;

/// Fewest right-hand sides per block when the caller is itself a thread
/// of the pool (see [`solve_split`]).
const MIN_COLUMNS_PER_SHARED_BLOCK: usize = 8;

/// Solves $LL^T X = B$ in place, the columns of `rhs` split into one
/// block per thread; the solve of one column never reads another, so the
/// blocks are independent, and they get the other cores even where faer's
/// own parallelism is off (the diagnosis turns it off: inside parallel fits
/// it cost CPU time). Called from outside the rayon pool (a fit's trial
/// point, one factorisation's many loads), whose threads then have nothing
/// else to do, a block may be as narrow as [`MIN_COLUMNS_PER_THREAD`].
/// Called from a thread of the pool (finite-difference columns, candidate
/// refits), the caller is parallel already: each block is a pass over the
/// whole factor and wider blocks use the kernels better, so blocks are at
/// least [`MIN_COLUMNS_PER_SHARED_BLOCK`] wide. They are split by
/// `rayon::join`, which runs the second on the calling thread too unless
/// an idle thread takes it: when one candidate's refit is the last work
/// of a ranking, the other core helps with its solves instead of waiting.
/// Blocks of 4 on every call had cost about a fifth more CPU time
/// (session 16), and one block per call inside the pool (sessions 16 to
/// 32) left that core idle; on the default diagnosis, blocks of 8 took
/// about 5% off the wall time for 5% more CPU time (`docs/benchmarks.md`,
/// session 33).
fn solve_split(factor: &CholeskyFactor, rhs: MatMut<'_, f64>) {
    let per_block = match rayon::current_thread_index() {
        Some(_) => MIN_COLUMNS_PER_SHARED_BLOCK,
        None => MIN_COLUMNS_PER_THREAD,
    };
    let blocks = rayon::current_num_threads().min(rhs.ncols() / per_block);
    solve_blocks(factor, rhs, blocks.max(1));
}

fn solve_blocks(factor: &CholeskyFactor, rhs: MatMut<'_, f64>, blocks: usize) {
    if blocks < 2 {
        factor.solve_factorized(rhs);
        return;
    }
    let left_blocks = blocks / 2;
    let split = rhs.ncols() * left_blocks / blocks;
    let (left, right) = rhs.split_at_col_mut(split);
    rayon::join(
        || solve_blocks(factor, left, left_blocks),
        || solve_blocks(factor, right, blocks - left_blocks),
    );
}

/// Number of rigid-body modes of the mesh that neither the prescribed dofs
/// nor the springs resist. With the modes $R$ (centred and scaled to unit
/// size), a mode $R a$ is free iff $R_c a = 0$ and $a^T R^T K_s R a = 0$;
/// counts the near-zero eigenvalues of the sum of the two (normalised)
/// Gram matrices.
fn free_rigid_modes<const D: usize>(
    mesh: &Mesh<D>,
    dirichlet: &Dirichlet,
    springs: Option<&SparseColMat<usize, f64>>,
) -> usize {
    let modes = rigid_body_modes(mesh);
    let m = modes.len();
    let mut constrained = DMatrix::<f64>::zeros(m, m);
    for (d, _) in dirichlet.iter() {
        for a in 0..m {
            for b in 0..m {
                constrained[(a, b)] += modes[a][d] * modes[b][d];
            }
        }
    }
    let mut energy = DMatrix::<f64>::zeros(m, m);
    if let Some(s) = springs {
        let images: Vec<Vec<f64>> = modes.iter().map(|r| multiply(s, r)).collect();
        for a in 0..m {
            for b in 0..m {
                energy[(a, b)] = modes[a].iter().zip(&images[b]).map(|(x, y)| x * y).sum();
            }
        }
    }
    let normalise = |g: DMatrix<f64>| {
        let trace = g.trace();
        if trace > 0.0 { g / trace } else { g }
    };
    let gram = normalise(constrained) + normalise(energy);
    let eigenvalues = gram.symmetric_eigenvalues();
    let largest = eigenvalues.iter().copied().fold(0.0, f64::max);
    eigenvalues
        .iter()
        .filter(|&&l| l <= 1e-12 * largest.max(f64::MIN_POSITIVE) || largest == 0.0)
        .count()
}

/// The rigid-body modes of a mesh as full dof vectors: translations along
/// each axis and infinitesimal rotations about the bounding-box centre,
/// scaled by the box size so all modes have unit-order entries.
pub fn rigid_body_modes<const D: usize>(mesh: &Mesh<D>) -> Vec<Vec<f64>> {
    let (lo, hi) = mesh.bounding_box();
    let mut centre = [0.0; D];
    let mut size: f64 = 0.0;
    for i in 0..D {
        centre[i] = 0.5 * (lo[i] + hi[i]);
        size = size.max(hi[i] - lo[i]);
    }
    let size = if size > 0.0 { size } else { 1.0 };
    let n = mesh.node_count();
    let mut modes = Vec::new();
    for axis in 0..D {
        let mut t = vec![0.0; D * n];
        for k in 0..n {
            t[k * D + axis] = 1.0;
        }
        modes.push(t);
    }
    // Rotation in the plane of axes (p, q): u_p = -x_q, u_q = x_p.
    let planes: &[(usize, usize)] = if D == 2 {
        &[(0, 1)]
    } else {
        &[(0, 1), (1, 2), (2, 0)]
    };
    for &(p, q) in planes {
        let mut r = vec![0.0; D * n];
        for k in 0..n {
            let x = mesh.node(k);
            r[k * D + p] = -(x[q] - centre[q]) / size;
            r[k * D + q] = (x[p] - centre[p]) / size;
        }
        modes.push(r);
    }
    modes
}
