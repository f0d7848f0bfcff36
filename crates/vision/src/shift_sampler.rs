//! Single-precision cubic B-spline sampling of a frame patch on a shifted
//! integer grid: the inner loop of translation-only IC-GN.
//!
//! The interpolant is the one of [`crate::interpolate`],
//! $g(x, y) = \sum_{k,l} c_{kl}\,\beta^3(x - k)\,\beta^3(y - l)$, with the
//! coefficients from Unser's recursive prefilter (pole $z = \sqrt 3 - 2$,
//! mirror boundaries) applied along $y$ and then along $x$. Three things make
//! it cheap enough to run for every marker of every frame:
//!
//! - the patch is reloaded into buffers that live across markers, so no
//!   memory is allocated per marker;
//! - everything is `f32` (grey levels below $2^{16}$ keep a relative error of
//!   $10^{-7}$, some $10^{-5}$ grey levels, far below any camera noise), so
//!   a vector register holds twice as many values as with `f64`;
//! - the coefficients are stored column by column (`[x * side + y]`): the
//!   $y$ prefilter runs on the row-major samples, one transpose follows,
//!   then the $x$ prefilter; both recursions run along the outer index and
//!   vectorise across the inner one. The prefilter's gain of 6 per axis is
//!   folded into the interpolation weights.
//!
//! All nodes of a translated grid share one fractional offset $(t_x, t_y)$,
//! so the grid values are two 4-tap passes: along $y$ with the weights
//! $\beta^3(t_y + 1 - k)$, then across $x$.

use crate::GreyFrame;
use crate::interpolate::weights;

/// Pole of the cubic B-spline prefilter, $\sqrt 3 - 2$.
const POLE: f32 = -0.267_949_2;
/// Terms of the causal initialisation sum: $|z|^{13} < 2^{-23}$, the `f32`
/// resolution.
const INITIALISATION_TERMS: usize = 13;
/// The prefilter's gain per axis.
const GAIN: f64 = 6.0;

/// A square frame patch and its B-spline coefficients, with buffers reused
/// from one marker to the next.
#[derive(Debug, Default)]
pub(crate) struct ShiftSampler {
    side: usize,
    samples: Vec<f32>,
    coefficients: Vec<f32>,
    along_y: Vec<f32>,
    sums: Vec<f32>,
}

/// In-place prefilter of a row-major `side` x `side` array along its
/// columns (the recursion steps from row to row, every step updating a
/// whole row), without the gain of 6.
fn prefilter_along_rows(data: &mut [f32], side: usize) {
    // Causal initialisation: row 0 gathers sum_k z^k row_k (mirror boundary)
    // while rows 1.. are still the samples.
    let (first, rest) = data.split_at_mut(side);
    let mut zk = 1.0;
    for row in rest.chunks_exact(side).take(INITIALISATION_TERMS - 1) {
        zk *= POLE;
        for (a, b) in first.iter_mut().zip(row) {
            *a += zk * b;
        }
    }
    for r in 1..side {
        let (done, rest) = data.split_at_mut(r * side);
        for (c, p) in rest[..side].iter_mut().zip(&done[(r - 1) * side..]) {
            *c += POLE * p;
        }
    }
    let (before, last) = data.split_at_mut((side - 1) * side);
    let factor = POLE / (POLE * POLE - 1.0);
    for (l, b) in last.iter_mut().zip(&before[(side - 2) * side..]) {
        *l = factor * (*l + POLE * b);
    }
    for r in (0..side - 1).rev() {
        let (head, next) = data.split_at_mut((r + 1) * side);
        for (c, n) in head[r * side..].iter_mut().zip(&next[..side]) {
            *c = POLE * (n - *c);
        }
    }
}

impl ShiftSampler {
    /// Load the `side` x `side` patch whose top-left pixel is column `c0`,
    /// row `r0` (the caller keeps it inside the frame) and compute its
    /// coefficients.
    pub fn load(&mut self, frame: &GreyFrame, c0: usize, r0: usize, side: usize) {
        self.side = side;
        self.samples.clear();
        for r in r0..r0 + side {
            self.samples
                .extend_from_slice(&frame.pixels[r * frame.width + c0..][..side]);
        }
        prefilter_along_rows(&mut self.samples, side);
        self.coefficients.resize(side * side, 0.0);
        for (r, row) in self.samples.chunks_exact(side).enumerate() {
            for (c, &v) in row.iter().enumerate() {
                self.coefficients[c * side + r] = v;
            }
        }
        prefilter_along_rows(&mut self.coefficients, side);
    }

    /// The five sums one IC-GN step needs over the interpolated values
    /// $g_{ij}$ on the grid $(x_0 + i, y_0 + j)$, $i, j < n$, in patch pixel
    /// coordinates: $\sum g$, $\sum g^2$, $\sum a g$, $\sum b g$,
    /// $\sum c g$, where `a`, `b`, `c` hold one value per node, column-major
    /// (`[i * n + j]`). The caller keeps $1 \le x_0$ and
    /// $x_0 + n < $ `side` $- 2$, likewise for $y_0$.
    ///
    /// Each sum is gathered per grid row $j$ over the columns in `f32` (33
    /// terms: a relative rounding near $10^{-7}$; the loop is element-wise,
    /// so it vectorises), then over the rows in `f64`.
    pub fn grid_sums(
        &mut self,
        (x0, y0): (f64, f64),
        n: usize,
        [a, b, c]: [&[f32]; 3],
    ) -> [f64; 5] {
        let (fx, fy) = (x0.floor(), y0.floor());
        let single = |w: [f64; 4]| w.map(|v| (GAIN * v) as f32);
        let (wx, wy) = (single(weights(x0 - fx)), single(weights(y0 - fy)));
        let (c0, r0) = (fx as usize - 1, fy as usize - 1);
        let side = self.side;
        self.along_y.resize((n + 3) * n, 0.0);
        for (m, out) in self.along_y.chunks_exact_mut(n).enumerate() {
            let line = &self.coefficients[(c0 + m) * side + r0..][..n + 3];
            for ((((o, p), q), r), s) in out
                .iter_mut()
                .zip(line)
                .zip(&line[1..])
                .zip(&line[2..])
                .zip(&line[3..])
            {
                *o = wy[0] * p + wy[1] * q + wy[2] * r + wy[3] * s;
            }
        }
        self.sums.clear();
        self.sums.resize(5 * n, 0.0);
        let (s0, rest) = self.sums.split_at_mut(n);
        let (s1, rest) = rest.split_at_mut(n);
        let (s2, rest) = rest.split_at_mut(n);
        let (s3, s4) = rest.split_at_mut(n);
        for i in 0..n {
            let four = &self.along_y[i * n..(i + 4) * n];
            let (p, q, r, s) = (
                &four[..n],
                &four[n..2 * n],
                &four[2 * n..3 * n],
                &four[3 * n..],
            );
            let column = i * n..(i + 1) * n;
            let (a, b, c) = (&a[column.clone()], &b[column.clone()], &c[column]);
            for j in 0..n {
                let g = wx[0] * p[j] + wx[1] * q[j] + wx[2] * r[j] + wx[3] * s[j];
                s0[j] += g;
                s1[j] += g * g;
                s2[j] += a[j] * g;
                s3[j] += b[j] * g;
                s4[j] += c[j] * g;
            }
        }
        let total = |v: &[f32]| v.iter().map(|&x| x as f64).sum::<f64>();
        [total(s0), total(s1), total(s2), total(s3), total(s4)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::BitDepth;
    use crate::interpolate::SplinePatch;

    #[test]
    fn grid_sums_agree_with_the_double_precision_spline() {
        let side = 30;
        let mut frame = GreyFrame::filled(40, 36, BitDepth::Eight, 0.0);
        for (i, p) in frame.pixels.iter_mut().enumerate() {
            let (x, y) = ((i % 40) as f32, (i / 40) as f32);
            *p = 120.0 + 80.0 * (0.37 * x).sin() * (0.23 * y + 0.4).cos();
        }
        let (c0, r0) = (5, 3);
        let samples: Vec<f64> = (0..side * side)
            .map(|k| frame.at(c0 + k % side, r0 + k / side) as f64)
            .collect();
        let reference = SplinePatch::new(samples, side, side);
        let (x0, y0, n) = (2.37, 4.81, 19);
        let a: Vec<f32> = (0..n * n).map(|k| (k as f32 * 0.3).sin()).collect();
        let b: Vec<f32> = (0..n * n).map(|k| (k as f32 * 0.7).cos()).collect();
        let c: Vec<f32> = (0..n * n).map(|k| (k % 7) as f32 - 3.0).collect();
        let mut expected = [0.0; 5];
        for i in 0..n {
            for j in 0..n {
                let (g, _, _) = reference.sample_with_gradient(x0 + i as f64, y0 + j as f64);
                let k = i * n + j;
                let terms = [g, g * g, a[k] as f64 * g, b[k] as f64 * g, c[k] as f64 * g];
                for (e, t) in expected.iter_mut().zip(terms) {
                    *e += t;
                }
            }
        }
        let mut sampler = ShiftSampler::default();
        // Reloading must leave no trace of the previous patch or sums.
        sampler.load(&frame, 0, 0, 36);
        sampler.grid_sums((x0, y0), n, [&a, &b, &c]);
        sampler.load(&frame, c0, r0, side);
        let sums = sampler.grid_sums((x0, y0), n, [&a, &b, &c]);
        for (s, e) in sums.iter().zip(expected) {
            // f32 resolution of the largest term, times a few.
            assert!((s - e).abs() < 3e-6 * e.abs().max(1e4), "{s} vs {e}");
        }
    }
}
