//! Read the solution: the few needle unknowns every haptic tick (O(m N)), or
//! every unknown for the graphics (O(N^2)).

use crate::dense::dot;
use crate::{CondenseError, CondensedSystem};

/// Displacement and force of one working node, in its local frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NodeState {
    /// Displacement components (the first `d` are meaningful).
    pub displacement: [f64; 3],
    /// Force applied to the tissue at the node (the first `d` are meaningful).
    pub force: [f64; 3],
}

impl CondensedSystem {
    /// The unknown `x_i` of one coordinate (its displacement if force-given, its
    /// reaction force if displacement-given): row `i` of `S` times `y`, read from
    /// column `i` through the sign symmetry. O(N + N k).
    pub fn unknown(&mut self, i: usize) -> f64 {
        if self.is_capacitance() {
            let mut value = [0.0];
            self.unknowns_capacitance(&[i], &mut value);
            return value[0];
        }
        let mut column = std::mem::take(&mut self.scratch.column);
        self.current_column_into(i, &mut column);
        let sign_i = self.sign(i);
        let value: f64 = column
            .iter()
            .zip(&self.prescribed)
            .enumerate()
            .map(|(j, (c, y))| self.sign(j) * c * y)
            .sum();
        self.scratch.column = column;
        sign_i * value
    }

    /// The unknowns of the given coordinates into `out`: the per-tick query
    /// (forces on the needle nodes). With `ỹ = s ∘ y`,
    /// `x_i = s_i (S_b[:, i] · ỹ + W[i, :] · (U^T ỹ))`: O(m N + N k) for
    /// `m` coordinates and `k` pending updates, no allocation (in the
    /// capacitance form: see [`UpdatePolicy::Capacitance`]).
    ///
    /// [`UpdatePolicy::Capacitance`]: crate::UpdatePolicy::Capacitance
    pub fn unknowns_into(
        &mut self,
        coordinates: &[usize],
        out: &mut [f64],
    ) -> Result<(), CondenseError> {
        if out.len() != coordinates.len() {
            return Err(CondenseError::Length {
                what: "output",
                got: out.len(),
                expected: coordinates.len(),
            });
        }
        for &i in coordinates {
            self.check_coordinate(i)?;
        }
        if self.is_capacitance() {
            self.unknowns_capacitance(coordinates, out);
            return Ok(());
        }
        let mut signed = std::mem::take(&mut self.scratch.signed_prescribed);
        for (j, (s, y)) in signed.iter_mut().zip(&self.prescribed).enumerate() {
            *s = if self.displacement_given[j] { -y } else { *y };
        }
        let mut projected = std::mem::take(&mut self.scratch.projected);
        for l in 0..self.pending {
            projected[l] = dot(self.pending_u.col(l), &signed);
        }
        for (o, &i) in out.iter_mut().zip(coordinates) {
            let mut value = dot(self.base.col(i), &signed);
            for l in 0..self.pending {
                value += self.pending_w.get(i, l) * projected[l];
            }
            *o = self.sign(i) * value;
        }
        self.scratch.signed_prescribed = signed;
        self.scratch.projected = projected;
        Ok(())
    }

    /// Every unknown, `x = S y = S_b y + U (W^T y)`: the graphics-rate query, O(N^2).
    pub fn unknowns_all_into(&self, out: &mut [f64]) -> Result<(), CondenseError> {
        let n = self.len();
        if out.len() != n {
            return Err(CondenseError::Length {
                what: "output",
                got: out.len(),
                expected: n,
            });
        }
        if self.is_capacitance() {
            self.unknowns_all_capacitance(out);
            return Ok(());
        }
        out.fill(0.0);
        for (j, &y) in self.prescribed.iter().enumerate() {
            if y != 0.0 {
                for (o, s) in out.iter_mut().zip(self.base.col(j)) {
                    *o += s * y;
                }
            }
        }
        for l in 0..self.pending {
            let weight = dot(self.pending_w.col(l), &self.prescribed);
            for (o, u) in out.iter_mut().zip(self.pending_u.col(l)) {
                *o += weight * u;
            }
        }
        Ok(())
    }

    /// Displacement and force of a working node in its local frame (prescribed
    /// or solved, whichever each coordinate has). O(d N).
    pub fn node_state(&mut self, node: usize) -> Result<NodeState, CondenseError> {
        let d = self.dim;
        let b0 = self.slot(node)? * d;
        let mut state = NodeState {
            displacement: [0.0; 3],
            force: [0.0; 3],
        };
        for a in 0..d {
            let unknown = self.unknown(b0 + a);
            let given = self.prescribed[b0 + a];
            if self.displacement_given[b0 + a] {
                state.displacement[a] = given;
                state.force[a] = unknown;
            } else {
                state.displacement[a] = unknown;
                state.force[a] = given;
            }
        }
        Ok(state)
    }

    /// Sum of the forces the given working nodes apply to the tissue, in the
    /// global frame (the needle force is its negative). O(m d N).
    pub fn total_force(&mut self, nodes: &[usize]) -> Result<[f64; 3], CondenseError> {
        let d = self.dim;
        let mut total = [0.0; 3];
        for &node in nodes {
            let state = self.node_state(node)?;
            let frame = self.frames[self.slot(node)?];
            for r in 0..d {
                total[r] += (0..d).map(|c| frame[r][c] * state.force[c]).sum::<f64>();
            }
        }
        Ok(total)
    }
}
