//! Add and remove working nodes at run time: a bordered update of `S` from
//! columns of the factorised full model (prefetched into a cache so that a
//! node the needle is about to reach is added in O(N d |σ|)).

use rayon::prelude::*;

use crate::system::IDENTITY_FRAME;
use crate::{CondenseError, CondensedSystem};

impl CondensedSystem {
    /// Solves (in parallel) and caches the full-model columns of the given
    /// nodes, so that a later [`CondensedSystem::add_node`] costs no solve.
    /// Nodes already working or cached are skipped.
    pub fn prefetch(&mut self, nodes: &[usize]) -> Result<(), CondenseError> {
        let mut wanted: Vec<usize> = Vec::new();
        for &node in nodes {
            self.model.check_free_node(node)?;
            if !self.is_working(node) && !self.cache.contains_key(&node) && !wanted.contains(&node)
            {
                wanted.push(node);
            }
        }
        let model = &self.model;
        let solved: Vec<(usize, Vec<f64>)> = wanted
            .par_iter()
            .map(|&node| (node, node_columns(model, node)))
            .collect();
        self.cache.extend(solved);
        Ok(())
    }

    /// Drops every cached column (e.g. once the needle has moved away).
    pub fn clear_prefetched(&mut self) {
        self.cache.clear();
    }

    /// Number of nodes whose columns are cached.
    pub fn prefetched(&self) -> usize {
        self.cache.len()
    }

    /// Brings `node` into the working set, force-free in the global frame, so
    /// nothing physical changes (no force jump). Its columns come from the cache
    /// or from one solve with the factorised model.
    ///
    /// With `c = K^{-1}[W, n]`, `γ = K^{-1}[n, n]`, `g = A^T c` (working frames)
    /// and σ the displacement-given coordinates, the principal pivot transform of
    /// the bordered `G` gives the border without touching the rest of `S`:
    /// $$ S[W, n] = g_τ - S[:, σ] g_σ,\quad S[n, j] = s_j S[j, n],\quad
    ///    S[n, n] = γ - g_σ^T (S[:, σ] g_σ)_σ , $$
    /// O(N d |σ|): the cost is set by the few needle coordinates, not by N^2.
    pub fn add_node(&mut self, node: usize) -> Result<(), CondenseError> {
        self.model.check_free_node(node)?;
        if self.is_working(node) {
            return Err(CondenseError::AlreadyWorking { node });
        }
        let columns = match self.cache.remove(&node) {
            Some(columns) => columns,
            None => node_columns(&self.model, node),
        };
        let d = self.dim;
        let n = self.len();
        let n_free = self.model.n_free();
        let new_free: Vec<usize> = (0..d)
            .map(|a| self.model.free_index(node * d + a).expect("checked free"))
            .collect();

        // g = A^T c, with c the compliance between the working coordinates and the new node.
        let mut g = vec![0.0; n * d];
        for a in 0..d {
            let column = &columns[a * n_free..(a + 1) * n_free];
            for (slot, frame) in self.frames.iter().enumerate() {
                for r in 0..d {
                    g[a * n + slot * d + r] = (0..d)
                        .map(|q| frame[q][r] * column[self.free_of_coord[slot * d + q]])
                        .sum();
                }
            }
        }
        // S[:, σ] g_σ = S_b[:, σ] g_σ + U (W[σ, :]^T g_σ). The capacitance
        // form stores G itself: the border is g and the corner γ, as if σ were empty.
        let pivoted = !self.is_capacitance();
        let mut s_g = vec![0.0; n * d];
        let pending = self.pending;
        let mut projected = vec![0.0; pending * d];
        for j in (0..n).filter(|&j| pivoted && self.displacement_given[j]) {
            let base_col = self.base.col(j);
            for a in 0..d {
                let weight = g[a * n + j];
                for (acc, v) in s_g[a * n..(a + 1) * n].iter_mut().zip(base_col) {
                    *acc += weight * v;
                }
                for l in 0..pending {
                    projected[a * pending + l] += self.pending_w.get(j, l) * weight;
                }
            }
        }
        for a in 0..d {
            for l in 0..pending {
                let weight = projected[a * pending + l];
                for (acc, u) in s_g[a * n..(a + 1) * n]
                    .iter_mut()
                    .zip(self.pending_u.col(l))
                {
                    *acc += weight * u;
                }
            }
        }

        let new_n = n + d;
        self.base.resize(new_n, new_n);
        let rows_u = self.pending_u.cols();
        self.pending_u.resize(new_n, rows_u);
        self.pending_w.resize(new_n, rows_u);
        for a in 0..d {
            for k in 0..n {
                let border = if pivoted && self.displacement_given[k] {
                    -s_g[a * n + k]
                } else {
                    g[a * n + k] - s_g[a * n + k]
                };
                let row_sign = if pivoted { self.sign(k) } else { 1.0 };
                self.base.set(k, n + a, border);
                self.base.set(n + a, k, row_sign * border);
            }
        }
        for a in 0..d {
            for b in 0..d {
                // γ is symmetric; average the two solves so the corner is exactly so.
                let gamma =
                    0.5 * (columns[b * n_free + new_free[a]] + columns[a * n_free + new_free[b]]);
                let correction: f64 = (0..n)
                    .filter(|&j| pivoted && self.displacement_given[j])
                    .map(|j| g[a * n + j] * s_g[b * n + j])
                    .sum();
                self.base.set(n + a, n + b, gamma - correction);
            }
        }
        self.nodes.push(node);
        self.slot_of.insert(node, self.frames.len());
        self.frames.push(IDENTITY_FRAME);
        self.free_of_coord.extend_from_slice(&new_free);
        self.displacement_given
            .extend(std::iter::repeat_n(false, d));
        self.prescribed.extend(std::iter::repeat_n(0.0, d));
        self.size_scratch();
        Ok(())
    }

    /// Takes `node` out of the working set: its displacement-given coordinates
    /// are first exchanged back (equation (8)), then its rows and columns are
    /// dropped, which is exact because deleting a force-given index commutes with
    /// the principal pivot transform. The node becomes force-free: whatever force
    /// it carried is released. The last slot moves into the freed one.
    pub fn remove_node(&mut self, node: usize) -> Result<(), CondenseError> {
        let slot = self.slot(node)?;
        let d = self.dim;
        let b0 = slot * d;
        if self.is_capacitance() {
            // Dropping the node's rows and columns of G makes it force-free.
            self.drop_from_sigma(b0..b0 + d);
            self.displacement_given[b0..b0 + d].fill(false);
        }
        for a in 0..d {
            if self.displacement_given[b0 + a] {
                self.exchange(b0 + a)?;
            }
        }
        let last_slot = self.nodes.len() - 1;
        let last0 = last_slot * d;
        if slot != last_slot {
            for a in 0..d {
                let (from, to) = (last0 + a, b0 + a);
                self.base.copy_col(from, to);
                self.base.copy_row(from, to);
                self.pending_u.copy_row(from, to);
                self.pending_w.copy_row(from, to);
                self.renumber_sigma(from, to);
                self.free_of_coord[to] = self.free_of_coord[from];
                self.displacement_given[to] = self.displacement_given[from];
                self.prescribed[to] = self.prescribed[from];
            }
            let moved = self.nodes[last_slot];
            self.nodes[slot] = moved;
            self.frames[slot] = self.frames[last_slot];
            self.slot_of.insert(moved, slot);
        }
        self.slot_of.remove(&node);
        self.nodes.pop();
        self.frames.pop();
        let new_n = last0;
        self.free_of_coord.truncate(new_n);
        self.displacement_given.truncate(new_n);
        self.prescribed.truncate(new_n);
        self.base.resize(new_n, new_n);
        let cols_u = self.pending_u.cols();
        self.pending_u.resize(new_n, cols_u);
        self.pending_w.resize(new_n, cols_u);
        self.size_scratch();
        if self.is_capacitance() {
            self.refactor_capacitance()?;
        }
        Ok(())
    }
}

/// The `d` columns of `K^{-1}` (over the free dofs) belonging to `node`.
fn node_columns(model: &crate::FullModel, node: usize) -> Vec<f64> {
    let d = model.dofs_per_node();
    let dofs: Vec<usize> = (0..d)
        .map(|a| model.free_index(node * d + a).expect("checked free"))
        .collect();
    let solved = model.solve_unit_columns(&dofs);
    let n_free = model.n_free();
    let mut out = vec![0.0; d * n_free];
    for a in 0..d {
        for i in 0..n_free {
            out[a * n_free + i] = solved[(i, a)];
        }
    }
    out
}
