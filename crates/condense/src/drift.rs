//! Drift control: measure the round-off accumulated by many updates against
//! the factorised full model, and rebuild `S` exactly from it when needed.
//! No copy of `K_W^{-1}` is stored: it would double the memory streamed and
//! make every node addition write twice as many strided rows.

use crate::system::fill_compliance;
use crate::{CondenseError, CondensedSystem, UpdatePolicy};

impl CondensedSystem {
    /// Relative residual of the defining relation for one pseudo-random probe:
    /// with `y` drawn from `seed`, `x = S y`, the local `(u, f)` assembled from
    /// `(x, y)` must satisfy `A u = K_W^{-1} A f` (global frame). Returns
    /// `‖A u − K_W^{-1} A f‖ / max(‖A u‖, ‖K_W^{-1} A f‖)`, with `K_W^{-1} A f`
    /// from one sparse solve of the full model. O(N^2) plus one solve,
    /// independent of the update history: exact arithmetic gives 0.
    pub fn drift(&self, seed: u64) -> f64 {
        let n = self.len();
        if n == 0 {
            return 0.0;
        }
        let mut state = seed;
        let probe: Vec<f64> = (0..n)
            .map(|_| 2.0 * unit_random(&mut state) - 1.0)
            .collect();
        let current = self.current_matrix();
        let mut displacement = vec![0.0; n];
        let mut force = vec![0.0; n];
        for i in 0..n {
            let x: f64 = (0..n).map(|j| current[(i, j)] * probe[j]).sum();
            if self.displacement_given[i] {
                displacement[i] = probe[i];
                force[i] = x;
            } else {
                displacement[i] = x;
                force[i] = probe[i];
            }
        }
        let to_global = |local: &[f64]| -> Vec<f64> {
            let d = self.dim;
            let mut global = vec![0.0; n];
            for (slot, frame) in self.frames.iter().enumerate() {
                for r in 0..d {
                    global[slot * d + r] = (0..d).map(|c| frame[r][c] * local[slot * d + c]).sum();
                }
            }
            global
        };
        let displacement = to_global(&displacement);
        let force = to_global(&force);
        // K_W^{-1} A f: one solve of the full model loaded at the working dofs
        // only (every other node is force-free), so the check needs no stored
        // copy of K_W^{-1} and does not depend on any update of S.
        let mut load = vec![0.0; self.model.n_free()];
        for (&dof, &f) in self.free_of_coord.iter().zip(&force) {
            load[dof] = f;
        }
        self.model
            .solve(&mut load)
            .expect("the load has one entry per free dof");
        let predicted: Vec<f64> = self.free_of_coord.iter().map(|&dof| load[dof]).collect();
        let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
        let residual: Vec<f64> = displacement
            .iter()
            .zip(&predicted)
            .map(|(a, b)| a - b)
            .collect();
        let scale = norm(&displacement).max(norm(&predicted));
        if scale == 0.0 {
            0.0
        } else {
            norm(&residual) / scale
        }
    }

    /// Rebuilds `S` from the factorised full model: `K_W^{-1}` by `N` parallel
    /// sparse solves (as in [`CondensedSystem::new`]), `G = A^T K_W^{-1} A` by
    /// the O(N) per-node rotations, then one exchange per displacement-given
    /// coordinate. O(N solves + |σ| N^2). The prescribed values are kept.
    pub fn refresh(&mut self) -> Result<(), CondenseError> {
        let n = self.len();
        fill_compliance(&self.model, &self.free_of_coord, &mut self.base);
        self.pending = 0;
        let d = self.dim;
        for slot in 0..self.frames.len() {
            let frame = self.frames[slot];
            self.rotate_uniform(slot * d, &frame);
        }
        if self.is_capacitance() {
            // G is all the capacitance form stores; σ and y are unchanged.
            return self.refactor_capacitance();
        }
        let policy = self.policy;
        let prescribed = self.prescribed.clone();
        let swapped: Vec<usize> = (0..n).filter(|&i| self.displacement_given[i]).collect();
        self.displacement_given.fill(false);
        self.policy = UpdatePolicy::Immediate;
        let result = swapped.iter().try_for_each(|&i| self.exchange(i));
        self.policy = policy;
        self.prescribed = prescribed;
        result
    }

    /// Runs [`CondensedSystem::drift`] and, when it exceeds `bound`,
    /// [`CondensedSystem::refresh`]. Returns the drift measured before any refresh.
    pub fn refresh_if_drifted(&mut self, bound: f64, seed: u64) -> Result<f64, CondenseError> {
        let drift = self.drift(seed);
        if drift > bound || drift.is_nan() {
            self.refresh()?;
        }
        Ok(drift)
    }
}

/// splitmix64 mapped to [0, 1): a dependency-free, reproducible probe.
pub(crate) fn unit_random(state: &mut u64) -> f64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64
}
