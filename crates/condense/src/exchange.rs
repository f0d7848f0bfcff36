//! Exchange a displacement and a force variable: equation (8), the principal
//! pivot transform on one index, as a rank-one update.

use crate::{CondenseError, CondensedSystem, Condition};

impl CondensedSystem {
    /// Sets the [`Condition`] of `(node, axis)`, exchanging the two variables of
    /// that coordinate if it changes (see [`CondensedSystem::exchange`]). The
    /// newly prescribed variable keeps its current value, so the state does not
    /// jump.
    pub fn set_condition(
        &mut self,
        node: usize,
        axis: usize,
        condition: Condition,
    ) -> Result<(), CondenseError> {
        let coordinate = self.coordinate(node, axis)?;
        if self.condition(coordinate) != condition {
            self.exchange(coordinate)?;
        }
        Ok(())
    }

    /// Exchanges `x_i` and `y_i` (equation (8) of the paper): a force-given
    /// coordinate becomes displacement-given or back, in O(N^2) (or O(N k)
    /// buffered) instead of re-inverting.
    ///
    /// With `p = S_ii` the pivot, solving row `i` of `x = S y` for `y_i` gives
    /// $$ S'_{ii} = 1/p,\quad S'_{ij} = -S_{ij}/p,\quad S'_{ki} = S_{ki}/p,\quad
    ///    S'_{kj} = S_{kj} - S_{ki} S_{ij}/p \quad (k, j \ne i), $$
    /// that is the rank-one update
    /// $$ S' = S - \frac{\mathbf c_i \mathbf r_i^T}{p}, \quad
    ///    \mathbf c_i = S e_i + e_i,\quad \mathbf r_i = S^T e_i - e_i, $$
    /// i.e. the paper's (8) with `[c_i]_i = p + 1` and `[r_i]_i = p - 1`. The
    /// printed `[c_i]_i = [r_i]_i = p - 1` gives `S'_ii = 2 - 1/p`, which is no
    /// exchange under any sign convention (see `docs/condense.md`). The row is read from the column through
    /// the sign symmetry `S_ij = s_i s_j S_ji`, so only contiguous memory is
    /// streamed. The newly prescribed variable takes the current value of the
    /// old unknown (continuity).
    ///
    /// For a positive definite model every pivot is positive (`S` stays a
    /// P-matrix); a non-positive pivot means the mixed problem is ill-posed and
    /// is reported as [`CondenseError::SingularPivot`].
    ///
    /// In the capacitance form `S` is not stored: `i` joins or leaves σ and
    /// the factor of `G[σ, σ]` is bordered (pivot `S_ii` as above) or
    /// refactorised instead (see [`UpdatePolicy::Capacitance`]).
    ///
    /// [`UpdatePolicy::Capacitance`]: crate::UpdatePolicy::Capacitance
    pub fn exchange(&mut self, i: usize) -> Result<(), CondenseError> {
        self.check_coordinate(i)?;
        if self.is_capacitance() {
            return self.exchange_capacitance(i);
        }
        let mut column = std::mem::take(&mut self.scratch.column);
        let mut row = std::mem::take(&mut self.scratch.row);
        self.current_column_into(i, &mut column);
        let pivot = column[i];
        if !(pivot > 0.0 && pivot.is_finite()) {
            self.scratch.column = column;
            self.scratch.row = row;
            return Err(CondenseError::SingularPivot {
                coordinate: i,
                pivot,
            });
        }
        let sign_i = self.sign(i);
        // Current x_i = row_i . y, which becomes the prescribed y_i.
        let mut unknown = 0.0;
        for (j, (&c, r)) in column.iter().zip(row.iter_mut()).enumerate() {
            let s_ij = sign_i * self.sign(j) * c;
            unknown += s_ij * self.prescribed[j];
            *r = s_ij;
        }
        row[i] -= 1.0;
        column[i] += 1.0;
        let scale = -1.0 / pivot;
        for c in column.iter_mut() {
            *c *= scale;
        }
        self.add_rank_one(&column, &row);
        self.displacement_given[i] = !self.displacement_given[i];
        self.prescribed[i] = unknown;
        self.scratch.column = column;
        self.scratch.row = row;
        Ok(())
    }
}
