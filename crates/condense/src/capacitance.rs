//! The capacitance form ([`UpdatePolicy::Capacitance`]): `S` is never formed.
//!
//! The system keeps `G = A^T K_W^{-1} A` (symmetric positive definite, node
//! frames) and the Cholesky factor `L L^T = G[σ, σ]` of its small block on the
//! displacement-given set σ. With `τ` the force-given coordinates and `y` the
//! prescribed values, the forces on σ solve
//! $$ G_{σσ} f_σ = y_σ - G_{στ} y_τ , $$
//! and the displacements of τ are `u_τ = G_{τ:} f` with `f = (f_σ, y_τ)`. This
//! is `x = S y` for `S = PPT_σ(G)` (equation (7)), evaluated instead of stored:
//!
//! - an exchange (equation (8)) moves one index in or out of σ: a bordered
//!   Cholesky step `l = L^{-1} G[σ, i]`, pivot `S_ii = G_ii - l·l`, in
//!   O(|σ|^2), or a refactorisation of `G[σ, σ]` in O(|σ|^3 / 6) when it leaves;
//! - a rotation (equations (9) and (10)) is `G' = A^T G A` on the node's `d`
//!   rows and columns, whatever the node's conditions, then a refactorisation if
//!   the node has displacement-given coordinates;
//! - a node addition borders `G` with the new node's columns, no correction;
//! - a query costs O((|σ| + m) N) for `m` unknowns, or O((|σ| + m) l) when
//!   only `l` coordinates carry a force (the needle's): then the products
//!   with `f` gather those entries instead of streaming columns of `G`.
//!
//! It is the fastest form while σ (the needle's stuck and slipping
//! coordinates) stays small against `N`; with `|σ|` near `N` the O(|σ|^3)
//! refactorisations lose to the O(N^2) rank-one updates of `S`. Exchanges add
//! no round-off to `G` at all (only rotations touch it).
//!
//! [`UpdatePolicy::Capacitance`]: crate::UpdatePolicy::Capacitance

use crate::dense::{Dense, dot};
use crate::{CondenseError, CondensedSystem, UpdatePolicy};

/// The factor of `G[σ, σ]` and the work vectors of the capacitance form.
#[derive(Debug, Clone, Default)]
pub(crate) struct Capacitance {
    /// Displacement-given coordinates, in the order of the factor's rows.
    sigma: Vec<usize>,
    /// Lower Cholesky factor of `G[σ, σ]`, rows packed: row `r` holds its
    /// `r + 1` entries from offset `r (r + 1) / 2`, so that appending a
    /// coordinate appends a row and the triangular solves read rows.
    factor: Vec<f64>,
    /// Force vector of the last solve: prescribed on τ, solved on σ.
    force: Vec<f64>,
    /// Indices of the non-zero entries of `force` (σ and the loaded part of τ).
    loaded: Vec<usize>,
    /// True when `loaded` is short enough that products with `force` gather
    /// its entries instead of streaming whole columns of `G`.
    sparse: bool,
    /// Work vector of length |σ|.
    work: Vec<f64>,
}

impl Capacitance {
    fn row(&self, r: usize) -> &[f64] {
        let start = r * (r + 1) / 2;
        &self.factor[start..start + r + 1]
    }

    /// `z <- L^{-1} z` for the leading `z.len()` rows.
    fn forward(factor: &[f64], z: &mut [f64]) {
        for r in 0..z.len() {
            let start = r * (r + 1) / 2;
            let row = &factor[start..start + r + 1];
            let partial: f64 = row[..r].iter().zip(&z[..r]).map(|(l, v)| l * v).sum();
            z[r] = (z[r] - partial) / row[r];
        }
    }

    /// `z <- L^{-T} z`.
    fn backward(&self, z: &mut [f64]) {
        for r in (0..z.len()).rev() {
            let row = self.row(r);
            z[r] /= row[r];
            let value = z[r];
            for (v, l) in z[..r].iter_mut().zip(&row[..r]) {
                *v -= l * value;
            }
        }
    }

    /// `z <- G[σ, σ]^{-1} z`.
    fn solve(&self, z: &mut [f64]) {
        Self::forward(&self.factor, z);
        self.backward(z);
    }

    /// Bordered Cholesky step for joining `i`: leaves `l = L^{-1} G[σ, i]` in
    /// `work` and returns the pivot `G_ii - l·l`, which is `S_ii` (the Schur
    /// complement) and positive exactly when `G[σ ∪ {i}, σ ∪ {i}]` is SPD.
    fn border(&mut self, g: &Dense, i: usize) -> f64 {
        let column = g.col(i);
        self.work.clear();
        self.work.extend(self.sigma.iter().map(|&k| column[k]));
        Self::forward(&self.factor, &mut self.work);
        column[i] - self.work.iter().map(|l| l * l).sum::<f64>()
    }

    /// Appends `i` to σ with the border left in `work` by [`Self::border`].
    fn append(&mut self, i: usize, pivot: f64) {
        self.factor.extend_from_slice(&self.work);
        self.factor.push(pivot.sqrt());
        self.sigma.push(i);
    }

    /// Factorises `G[σ, σ]` afresh for the coordinates in `sigma` (in order).
    fn refactor(&mut self, g: &Dense, sigma: &[usize]) -> Result<(), CondenseError> {
        self.sigma.clear();
        self.factor.clear();
        for &i in sigma {
            let pivot = self.border(g, i);
            if !(pivot > 0.0 && pivot.is_finite()) {
                return Err(CondenseError::SingularPivot {
                    coordinate: i,
                    pivot,
                });
            }
            self.append(i, pivot);
        }
        Ok(())
    }

    /// `force <- f` for prescribed values `y` and conditions `given` (true on σ).
    fn forces(&mut self, g: &Dense, given: &[bool], y: &[f64]) {
        let mut force = std::mem::take(&mut self.force);
        force.clear();
        force.extend(
            y.iter()
                .zip(given)
                .map(|(&v, &on_sigma)| if on_sigma { 0.0 } else { v }),
        );
        self.loaded.clear();
        self.loaded
            .extend((0..force.len()).filter(|&j| force[j] != 0.0));
        self.sparse = 4 * (self.loaded.len() + self.sigma.len()) <= force.len();
        let mut rhs = std::mem::take(&mut self.work);
        rhs.clear();
        rhs.extend(
            self.sigma
                .iter()
                .map(|&k| y[k] - self.times_force(g.col(k), &force)),
        );
        self.solve(&mut rhs);
        for (&k, &value) in self.sigma.iter().zip(&rhs) {
            force[k] = value;
        }
        self.loaded.extend_from_slice(&self.sigma);
        self.force = force;
        self.work = rhs;
    }

    /// `column · force`, gathering the loaded entries when they are few (the
    /// usual haptic state: forces only at the needle) and streaming otherwise.
    fn times_force(&self, column: &[f64], force: &[f64]) -> f64 {
        if self.sparse {
            self.loaded.iter().map(|&j| column[j] * force[j]).sum()
        } else {
            dot(column, force)
        }
    }

    /// The unknown of coordinate `i` from the last [`Self::forces`]: its force
    /// on σ, its displacement `G[:, i] · f` (G symmetric) otherwise.
    fn unknown(&self, g: &Dense, given: &[bool], i: usize) -> f64 {
        if given[i] {
            self.force[i]
        } else {
            self.times_force(g.col(i), &self.force)
        }
    }
}

impl CondensedSystem {
    pub(crate) fn is_capacitance(&self) -> bool {
        self.policy == UpdatePolicy::Capacitance
    }

    /// Refactorises `G[σ, σ]` after σ lost a coordinate, was renumbered, or
    /// its block of `G` changed (a rotation, a refresh).
    ///
    /// On failure σ and the factor are put back as they were, so that the
    /// sizes stay consistent (queries never index past the factor); the
    /// caller reports the error, and the system needs `refresh()`.
    pub(crate) fn refactor_capacitance(&mut self) -> Result<(), CondenseError> {
        let sigma = std::mem::take(&mut self.capacitance.sigma);
        let factor = self.capacitance.factor.clone();
        let result = self.capacitance.refactor(&self.base, &sigma);
        if result.is_err() {
            self.capacitance.sigma = sigma;
            self.capacitance.factor = factor;
        }
        result
    }

    /// Exchange in the capacitance form: see [`CondensedSystem::exchange`].
    pub(crate) fn exchange_capacitance(&mut self, i: usize) -> Result<(), CondenseError> {
        self.capacitance
            .forces(&self.base, &self.displacement_given, &self.prescribed);
        let unknown = self
            .capacitance
            .unknown(&self.base, &self.displacement_given, i);
        if self.displacement_given[i] {
            // Leaving σ: the pivot S_ii = (G[σ, σ]^{-1})_ii is positive.
            let before = (
                self.capacitance.sigma.clone(),
                self.capacitance.factor.clone(),
            );
            self.capacitance.sigma.retain(|&k| k != i);
            if let Err(error) = self.refactor_capacitance() {
                // Nothing exchanged: the old factor still holds.
                (self.capacitance.sigma, self.capacitance.factor) = before;
                return Err(error);
            }
            self.displacement_given[i] = false;
        } else {
            let pivot = self.capacitance.border(&self.base, i);
            if !(pivot > 0.0 && pivot.is_finite()) {
                return Err(CondenseError::SingularPivot {
                    coordinate: i,
                    pivot,
                });
            }
            self.capacitance.append(i, pivot);
            self.displacement_given[i] = true;
        }
        self.prescribed[i] = unknown;
        Ok(())
    }

    /// `out[k] = x_{coordinates[k]}` in the capacitance form: O((|σ| + m) N),
    /// or O(N + (|σ| + m) l) with `l` loaded coordinates when they are few.
    pub(crate) fn unknowns_capacitance(&mut self, coordinates: &[usize], out: &mut [f64]) {
        self.capacitance
            .forces(&self.base, &self.displacement_given, &self.prescribed);
        for (o, &i) in out.iter_mut().zip(coordinates) {
            *o = self
                .capacitance
                .unknown(&self.base, &self.displacement_given, i);
        }
    }

    /// Every unknown in the capacitance form: `f` as in the tick query, then
    /// `u = G f` over the non-zero forces only.
    pub(crate) fn unknowns_all_capacitance(&self, out: &mut [f64]) {
        let mut solver = Capacitance {
            sigma: self.capacitance.sigma.clone(),
            factor: self.capacitance.factor.clone(),
            ..Capacitance::default()
        };
        solver.forces(&self.base, &self.displacement_given, &self.prescribed);
        out.fill(0.0);
        for (j, &f) in solver.force.iter().enumerate() {
            if f != 0.0 {
                for (o, g) in out.iter_mut().zip(self.base.col(j)) {
                    *o += g * f;
                }
            }
        }
        for &k in &solver.sigma {
            out[k] = solver.force[k];
        }
    }

    /// Column `j` of `S = PPT_σ(G)`: with `z = G[σ, σ]^{-1} G[σ, j]` for `j` in
    /// τ, `S[τ, j] = G[τ, j] - G[τ, σ] z` and `S[σ, j] = -z`; with
    /// `z = G[σ, σ]^{-1} e_j` for `j` in σ, `S[τ, j] = G[τ, σ] z` and `S[σ, j] = z`.
    /// O(N |σ|), for inspection (`current_matrix`), never on the haptic path.
    pub(crate) fn capacitance_column_into(&self, j: usize, out: &mut [f64]) {
        let cap = &self.capacitance;
        let position = cap.sigma.iter().position(|&k| k == j);
        let mut z: Vec<f64> = match position {
            Some(p) => (0..cap.sigma.len())
                .map(|q| if q == p { 1.0 } else { 0.0 })
                .collect(),
            None => cap.sigma.iter().map(|&k| self.base.get(k, j)).collect(),
        };
        cap.solve(&mut z);
        let sign = if position.is_some() {
            out.fill(0.0);
            1.0
        } else {
            out.copy_from_slice(self.base.col(j));
            -1.0
        };
        for (&k, &weight) in cap.sigma.iter().zip(&z) {
            for (o, g) in out.iter_mut().zip(self.base.col(k)) {
                *o += sign * weight * g;
            }
        }
        for (&k, &weight) in cap.sigma.iter().zip(&z) {
            out[k] = sign * weight;
        }
    }

    /// Renumbers σ after node removal moved coordinate `from` to `to`.
    pub(crate) fn renumber_sigma(&mut self, from: usize, to: usize) {
        for k in self.capacitance.sigma.iter_mut() {
            if *k == from {
                *k = to;
            }
        }
    }

    /// Drops the coordinates `range` from σ (their node leaves the working set).
    pub(crate) fn drop_from_sigma(&mut self, range: std::ops::Range<usize>) {
        self.capacitance.sigma.retain(|k| !range.contains(k));
    }
}
