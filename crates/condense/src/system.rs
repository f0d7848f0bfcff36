//! The condensed system: the state of the reduced relation x_W = S y_W and the
//! constructor that condenses the full model onto a set of working nodes.

use std::collections::HashMap;
use std::sync::Arc;

use crate::capacitance::Capacitance;
use crate::dense::Dense;
use crate::{CondenseError, FullModel};

/// Which variable of one working coordinate is prescribed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Condition {
    /// The force is given; the displacement is solved for (the default: a
    /// working node starts force-free).
    Force,
    /// The displacement is given; the (reaction) force is solved for.
    Displacement,
}

/// How the O(N^2) updates of exchanges and slip rotations are applied.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UpdatePolicy {
    /// Every update is applied to the dense matrix at once (one streaming pass
    /// over the N x N matrix per exchange).
    Immediate,
    /// Updates are kept as a low-rank buffer `S = S_b + U W^T` (the capacitance /
    /// Woodbury form) and folded into `S_b` by one matrix product when
    /// `max_pending` rank-one terms have accumulated: an event costs O(N k),
    /// the fold O(N^2 k) once per `k` events, at matrix-product speed.
    Buffered {
        /// Rank of the buffer before it is folded (at least 1).
        max_pending: usize,
    },
    /// `S` is never formed: the system keeps `G = A^T K_W^{-1} A` and the
    /// Cholesky factor of `G[σ, σ]` (σ the displacement-given coordinates) and
    /// solves `G[σ, σ] f_σ = y_σ - G[σ, τ] y_τ` at each query. An exchange
    /// costs O(|σ|^2) (joining σ) or O(|σ|^3 / 6) (leaving), a rotation O(d N)
    /// plus a refactorisation, a node addition O(d N), a query of `m`
    /// unknowns O((|σ| + m) N), or O((|σ| + m) l) when only `l` coordinates
    /// carry a force: the fastest form while σ (the needle's coordinates)
    /// stays small against `N`. See `docs/condense.md`.
    Capacitance,
}

/// The condensed reduced system of the working nodes.
///
/// Working coordinate `k = slot * d + axis` belongs to the node in `slot`
/// (see [`CondensedSystem::coordinate`]). Each coordinate lives in its node's
/// local frame (`u_global = R_node u_local`) and has a [`Condition`]. With `y`
/// the prescribed values and `x` the unknowns (displacement for force-given,
/// force for displacement-given coordinates), the system holds `S` with
/// `x = S y` (equation (7): `S = (K_W^{-1})'`). Nodes outside the working set
/// are force-free.
///
/// `S` is the principal pivot transform, on the displacement-given set σ, of
/// `G = A^T K_W^{-1} A` (A the block-diagonal node rotations); it is therefore
/// sign-symmetric, `S_ij = s_i s_j S_ji` with `s = -1` on σ, which lets every row
/// be read from the matching contiguous column.
#[derive(Debug, Clone)]
pub struct CondensedSystem {
    pub(crate) model: Arc<FullModel>,
    pub(crate) dim: usize,
    /// Working node in each slot.
    pub(crate) nodes: Vec<usize>,
    pub(crate) slot_of: HashMap<usize, usize>,
    /// Free-dof index (in the full model) of each working coordinate.
    pub(crate) free_of_coord: Vec<usize>,
    /// `S_b`: with the pending buffer, `S = S_b + U W^T`; in the capacitance
    /// form, `G = A^T K_W^{-1} A` itself.
    pub(crate) base: Dense,
    pub(crate) pending_u: Dense,
    pub(crate) pending_w: Dense,
    pub(crate) pending: usize,
    pub(crate) policy: UpdatePolicy,
    pub(crate) displacement_given: Vec<bool>,
    /// Rotation of each slot (local -> global); the top-left `d x d` block is used.
    pub(crate) frames: Vec<Frame>,
    /// Prescribed value `y` of each coordinate, in the node frame.
    pub(crate) prescribed: Vec<f64>,
    /// Prefetched solves: node -> `d` columns of `K^{-1}` over the free dofs.
    pub(crate) cache: HashMap<usize, Vec<f64>>,
    pub(crate) scratch: Scratch,
    /// Factor of `G[σ, σ]` (capacitance form only; empty otherwise).
    pub(crate) capacitance: Capacitance,
}

/// Preallocated work vectors, so that an exchange or a query allocates nothing.
#[derive(Debug, Clone, Default)]
pub(crate) struct Scratch {
    pub(crate) column: Vec<f64>,
    pub(crate) row: Vec<f64>,
    pub(crate) signed_prescribed: Vec<f64>,
    pub(crate) projected: Vec<f64>,
    pub(crate) block: Vec<f64>,
}

/// A node rotation, `u_global = R u_local`; in 2-D only the top-left 2x2 block is used.
pub type Frame = [[f64; 3]; 3];

pub(crate) const IDENTITY_FRAME: Frame = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

impl CondensedSystem {
    /// Condenses `model` onto `working_nodes`: `K_W^{-1}` is built column by
    /// column from sparse Cholesky solves (in parallel), all frames global, all
    /// coordinates force-given with zero force.
    pub fn new(
        model: Arc<FullModel>,
        working_nodes: &[usize],
        policy: UpdatePolicy,
    ) -> Result<Self, CondenseError> {
        let d = model.dofs_per_node();
        let mut slot_of = HashMap::with_capacity(working_nodes.len());
        for (slot, &node) in working_nodes.iter().enumerate() {
            model.check_free_node(node)?;
            if slot_of.insert(node, slot).is_some() {
                return Err(CondenseError::AlreadyWorking { node });
            }
        }
        let free_of_coord: Vec<usize> = working_nodes
            .iter()
            .flat_map(|&node| (0..d).map(move |a| node * d + a))
            .map(|dof| model.free_index(dof).expect("checked free"))
            .collect();
        let n = free_of_coord.len();
        let mut base = Dense::zeros(n, n, n, n);
        fill_compliance(&model, &free_of_coord, &mut base);
        let max_pending = match policy {
            UpdatePolicy::Immediate | UpdatePolicy::Capacitance => 0,
            UpdatePolicy::Buffered { max_pending } => max_pending.max(1),
        };
        let policy = match policy {
            UpdatePolicy::Buffered { .. } => UpdatePolicy::Buffered { max_pending },
            other => other,
        };
        let mut system = Self {
            model,
            dim: d,
            nodes: working_nodes.to_vec(),
            slot_of,
            free_of_coord,
            base,
            pending_u: Dense::zeros(n, max_pending, n, max_pending),
            pending_w: Dense::zeros(n, max_pending, n, max_pending),
            pending: 0,
            policy,
            displacement_given: vec![false; n],
            frames: vec![IDENTITY_FRAME; working_nodes.len()],
            prescribed: vec![0.0; n],
            cache: HashMap::new(),
            scratch: Scratch::default(),
            capacitance: Capacitance::default(),
        };
        system.size_scratch();
        Ok(system)
    }

    /// Preallocates room for `extra_nodes` more working nodes, so that the
    /// additions of a haptic loop never reallocate the N x N matrices.
    pub fn reserve(&mut self, extra_nodes: usize) {
        let capacity = self.len() + extra_nodes * self.dim;
        self.base.reserve(capacity, capacity);
        let k = self.pending_u.cols();
        self.pending_u.reserve(capacity, k);
        self.pending_w.reserve(capacity, k);
    }

    /// Number of working coordinates `N` (nodes times dofs per node).
    pub fn len(&self) -> usize {
        self.free_of_coord.len()
    }

    /// True when there is no working node.
    pub fn is_empty(&self) -> bool {
        self.free_of_coord.is_empty()
    }

    /// Dofs per node (2 or 3).
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// The factorised full model.
    pub fn model(&self) -> &Arc<FullModel> {
        &self.model
    }

    /// Working nodes in slot order (coordinate `slot * d + axis`).
    pub fn working_nodes(&self) -> &[usize] {
        &self.nodes
    }

    /// True if `node` is in the working set.
    pub fn is_working(&self, node: usize) -> bool {
        self.slot_of.contains_key(&node)
    }

    /// Working coordinate of `(node, axis)`.
    pub fn coordinate(&self, node: usize, axis: usize) -> Result<usize, CondenseError> {
        if axis >= self.dim {
            return Err(CondenseError::AxisOutOfRange {
                axis,
                dim: self.dim,
            });
        }
        Ok(self.slot(node)? * self.dim + axis)
    }

    /// Condition of a working coordinate.
    pub fn condition(&self, coordinate: usize) -> Condition {
        if self.displacement_given[coordinate] {
            Condition::Displacement
        } else {
            Condition::Force
        }
    }

    /// Prescribed values `y` (force or displacement per coordinate, node frames).
    pub fn prescribed(&self) -> &[f64] {
        &self.prescribed
    }

    /// Sets the prescribed value of one coordinate (a force if its condition is
    /// [`Condition::Force`], a displacement otherwise), in its node frame.
    pub fn set_prescribed(&mut self, coordinate: usize, value: f64) -> Result<(), CondenseError> {
        self.check_coordinate(coordinate)?;
        self.prescribed[coordinate] = value;
        Ok(())
    }

    /// Local frame of a working node (`u_global = R u_local`).
    pub fn frame(&self, node: usize) -> Result<Frame, CondenseError> {
        Ok(self.frames[self.slot(node)?])
    }

    /// Number of rank-one terms waiting in the buffer (always 0 with
    /// [`UpdatePolicy::Immediate`]).
    pub fn pending(&self) -> usize {
        self.pending
    }

    /// The current `S` as a dense matrix (an O(N^2) copy, for inspection and
    /// tests; O(N^2 |σ|) in the capacitance form, which never stores `S`).
    pub fn current_matrix(&self) -> faer::Mat<f64> {
        if self.is_capacitance() {
            let n = self.len();
            let mut out = faer::Mat::<f64>::zeros(n, n);
            let mut column = vec![0.0; n];
            for j in 0..n {
                self.capacitance_column_into(j, &mut column);
                for (i, &v) in column.iter().enumerate() {
                    out[(i, j)] = v;
                }
            }
            return out;
        }
        let mut out = self.base.as_ref().to_owned();
        if self.pending > 0 {
            faer::linalg::matmul::matmul(
                out.as_mut(),
                faer::Accum::Add,
                self.pending_u.as_ref().subcols(0, self.pending),
                self.pending_w.as_ref().subcols(0, self.pending).transpose(),
                1.0,
                faer::Par::Seq,
            );
        }
        out
    }

    pub(crate) fn check_coordinate(&self, coordinate: usize) -> Result<(), CondenseError> {
        if coordinate >= self.len() {
            return Err(CondenseError::CoordinateOutOfRange {
                coordinate,
                len: self.len(),
            });
        }
        Ok(())
    }

    pub(crate) fn slot(&self, node: usize) -> Result<usize, CondenseError> {
        self.slot_of
            .get(&node)
            .copied()
            .ok_or(CondenseError::NotWorking { node })
    }

    /// `s_j`: -1 on displacement-given coordinates, +1 otherwise.
    pub(crate) fn sign(&self, j: usize) -> f64 {
        if self.displacement_given[j] {
            -1.0
        } else {
            1.0
        }
    }

    /// Column `j` of the current `S` into `out`: `S_b[:, j] + U W[j, :]^T`.
    pub(crate) fn current_column_into(&self, j: usize, out: &mut [f64]) {
        if self.is_capacitance() {
            self.capacitance_column_into(j, out);
            return;
        }
        out.copy_from_slice(self.base.col(j));
        let k = self.pending;
        if k > 0 {
            let n = out.len();
            faer::linalg::matmul::matmul(
                faer::MatMut::from_column_major_slice_mut(out, n, 1),
                faer::Accum::Add,
                self.pending_u.as_ref().subcols(0, k),
                self.pending_w
                    .as_ref()
                    .subrows(j, 1)
                    .subcols(0, k)
                    .transpose(),
                1.0,
                faer::Par::Seq,
            );
        }
    }

    /// Adds `column * row^T` to the current `S`: into the buffer when buffered,
    /// else streamed over the columns of `S_b`.
    pub(crate) fn add_rank_one(&mut self, column: &[f64], row: &[f64]) {
        match self.policy {
            UpdatePolicy::Immediate => self.base.add_outer(column, row),
            // Exchanges and rotations of the capacitance form change G or the
            // factor, never S by a rank-one term.
            UpdatePolicy::Capacitance => {
                unreachable!("no rank-one update of S in the capacitance form")
            }
            UpdatePolicy::Buffered { max_pending } => {
                if self.pending == max_pending {
                    self.fold();
                }
                let l = self.pending;
                self.pending_u.col_mut(l).copy_from_slice(column);
                self.pending_w.col_mut(l).copy_from_slice(row);
                self.pending += 1;
            }
        }
    }

    /// Folds the pending buffer into `S_b`: `S_b += U W^T`, one matrix product.
    pub fn fold(&mut self) {
        if self.pending == 0 {
            return;
        }
        let k = self.pending;
        let (u, w) = (&self.pending_u, &self.pending_w);
        faer::linalg::matmul::matmul(
            self.base.as_mut(),
            faer::Accum::Add,
            u.as_ref().subcols(0, k),
            w.as_ref().subcols(0, k).transpose(),
            1.0,
            faer::Par::Seq,
        );
        self.pending = 0;
    }

    /// Sizes the scratch vectors for the current `N` (allocates only on growth).
    pub(crate) fn size_scratch(&mut self) {
        let n = self.len();
        let d = self.dim;
        let s = &mut self.scratch;
        s.column.resize(n, 0.0);
        s.row.resize(n, 0.0);
        s.signed_prescribed.resize(n, 0.0);
        s.projected.resize(self.pending_u.cols().max(1), 0.0);
        s.block.resize(4 * n * d, 0.0);
    }
}

/// Writes `K_W^{-1}` (global frame) of the working coordinates `free_of_coord`
/// into `target` (already `N x N`), column by column from parallel sparse solves.
pub(crate) fn fill_compliance(model: &FullModel, free_of_coord: &[usize], target: &mut Dense) {
    let columns = model.solve_unit_columns(free_of_coord);
    for j in 0..free_of_coord.len() {
        let col = target.col_mut(j);
        for (i, &f) in free_of_coord.iter().enumerate() {
            col[i] = columns[(f, j)];
        }
    }
    // K^{-1} is symmetric; the solves agree with it only to round-off, and the
    // sign symmetry the updates rely on wants it exact.
    for j in 0..free_of_coord.len() {
        for i in 0..j {
            let mean = 0.5 * (target.get(i, j) + target.get(j, i));
            target.set(i, j, mean);
            target.set(j, i, mean);
        }
    }
}
