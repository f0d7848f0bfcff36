//! Interpolation between solved states: the sensors sample a trial at
//! their own rates, between the states the truth solves (needle states
//! every `depth_step` of tip depth, probe states every
//! `indentation_step`).
//!
//! A quantity $f$ known at the states $g_0 < g_1 < \dots$ is read at $x$
//! in $[g_i, g_{i+1}]$ from the cubic through the four states
//! $g_{i-1}, \dots, g_{i+2}$ (shifted to $g_0, \dots, g_3$ in the first
//! interval and to the last four in the last), with Lagrange weights
//! $$w_j = \prod_{m \ne j} \frac{x - g_m}{g_j - g_m}.$$
//! Its error is $f^{(4)} h^4 / 128$ between two states $h$ apart where
//! $f$ is smooth, against $f'' h^2 / 8$ for the straight line; on the
//! needle states it is measured in `tests/convergence.rs` (and in
//! `docs/truth-world.md`). Quantities linear in the state coordinate, as
//! every linear probe is, are reproduced exactly. Grids of fewer than four
//! states use all of them.

/// Where and with which weights a state table is read at one point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stencil {
    /// The first state used.
    pub first: usize,
    /// Weights of states `first`, `first + 1`, ... (`len` of them).
    pub weights: [f64; 4],
    /// Number of states used (1 to 4).
    pub len: usize,
}

impl Stencil {
    /// The states used and their weights.
    pub fn terms(&self) -> impl Iterator<Item = (usize, f64)> + '_ {
        self.weights[..self.len]
            .iter()
            .enumerate()
            .map(|(k, &w)| (self.first + k, w))
    }

    /// The interpolated value of `table` (one value per state).
    pub fn apply(&self, table: &[f64]) -> f64 {
        self.terms().map(|(j, w)| w * table[j]).sum()
    }
}

/// The stencil reading states on the increasing `grid` at `x` (clamped to
/// the grid's range).
pub fn stencil(grid: &[f64], x: f64) -> Stencil {
    let n = grid.len();
    let len = n.min(4);
    if n < 2 {
        return Stencil {
            first: 0,
            weights: [1.0, 0.0, 0.0, 0.0],
            len,
        };
    }
    let x = x.clamp(grid[0], grid[n - 1]);
    // The interval [g_i, g_{i+1}] holding x.
    let i = grid.partition_point(|&g| g <= x).clamp(1, n - 1) - 1;
    let first = i.saturating_sub(1).min(n - len);
    let nodes = &grid[first..first + len];
    let mut weights = [0.0; 4];
    for (j, w) in weights.iter_mut().enumerate().take(len) {
        *w = nodes
            .iter()
            .enumerate()
            .filter(|&(m, _)| m != j)
            .map(|(_, &g)| (x - g) / (nodes[j] - g))
            .product();
    }
    Stencil {
        first,
        weights,
        len,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cubics_are_reproduced_on_uneven_grids_and_at_the_ends() {
        let grid = [0.0, 0.4, 1.0, 1.5, 2.5, 2.75];
        let f = |x: f64| 2.0 - x + 3.0 * x * x - 0.7 * x * x * x;
        let table: Vec<f64> = grid.iter().map(|&g| f(g)).collect();
        for x in [0.0, 0.1, 0.4, 0.7, 1.2, 2.0, 2.6, 2.75] {
            let s = stencil(&grid, x);
            assert!((s.apply(&table) - f(x)).abs() < 1e-12, "at {x}");
            assert!((s.terms().map(|(_, w)| w).sum::<f64>() - 1.0).abs() < 1e-12);
        }
        // Outside the grid: the end values.
        assert!((stencil(&grid, -1.0).apply(&table) - f(0.0)).abs() < 1e-12);
        assert!((stencil(&grid, 9.0).apply(&table) - f(2.75)).abs() < 1e-12);
    }

    #[test]
    fn states_are_read_exactly_and_short_grids_use_every_state() {
        let grid = [0.0, 1.0, 2.0, 3.0, 4.0];
        let table = [5.0, -1.0, 4.0, 0.5, 2.0];
        for (k, &g) in grid.iter().enumerate() {
            assert!((stencil(&grid, g).apply(&table) - table[k]).abs() < 1e-12);
        }
        // The midpoint of an inner interval: -1/16, 9/16, 9/16, -1/16.
        let s = stencil(&grid, 1.5);
        assert_eq!(s.first, 0);
        assert_eq!(s.weights, [-0.0625, 0.5625, 0.5625, -0.0625]);
        let line = stencil(&[0.0, 2.0], 0.5);
        assert_eq!((line.len, line.apply(&[1.0, 3.0])), (2, 1.5));
        assert_eq!(stencil(&[0.3], 7.0).apply(&[4.0]), 4.0);
    }
}
