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
//!   folded into the interpolation weights;
//! - the prefilter, the transpose (4 x 4 blocks) and the fused
//!   interpolate-and-sum pass are written with explicit `f32x4` vectors
//!   (the `wide` crate, safe code): the compiler's own vectorisation of
//!   arrays of lanes paired lanes of different sums in one register and
//!   spent more instructions shuffling than computing.
//!
//! All nodes of a translated grid share one fractional offset $(t_x, t_y)$,
//! so the grid values are two 4-tap passes: along $y$ with the weights
//! $\beta^3(t_y + 1 - k)$, then across $x$.

use wide::f32x4;

use crate::GreyFrame;
use crate::interpolate::weights;

/// Pole of the cubic B-spline prefilter, $\sqrt 3 - 2$.
const POLE: f32 = -0.267_949_2;
/// Terms of the causal initialisation sum: $|z|^{13} < 2^{-23}$, the `f32`
/// resolution.
const INITIALISATION_TERMS: usize = 13;
/// The prefilter's gain per axis.
const GAIN: f64 = 6.0;
/// Width of the explicit vectors (`f32x4`, one SSE register: the baseline
/// x86-64 build, which criterion measures, has nothing wider).
const LANES: usize = 4;
/// Blocks of [`LANES`] nodes gathered in `f32` before the partial sums move
/// to `f64`.
const BLOCKS_PER_FLUSH: usize = 32;

/// A square frame patch and its B-spline coefficients, with buffers reused
/// from one marker to the next.
#[derive(Debug, Default)]
pub(crate) struct ShiftSampler {
    side: usize,
    samples: Vec<f32>,
    coefficients: Vec<f32>,
    along_y: Vec<f32>,
}

/// Four consecutive values as a vector.
fn vector(v: &[f32]) -> f32x4 {
    f32x4::new(v[..LANES].try_into().unwrap())
}

/// `target[k] = op(target[k], source[k])` along a row, four columns at a
/// time (a ragged end is padded with zeros and written back in part).
fn update_row(target: &mut [f32], source: &[f32], op: impl Fn(f32x4, f32x4) -> f32x4) {
    let mut targets = target.chunks_exact_mut(LANES);
    let mut sources = source.chunks_exact(LANES);
    for (t, s) in (&mut targets).zip(&mut sources) {
        t.copy_from_slice(&op(vector(t), vector(s)).to_array());
    }
    let (t, s) = (targets.into_remainder(), sources.remainder());
    if !t.is_empty() {
        let pad = |v: &[f32]| {
            let mut lanes = [0.0; LANES];
            lanes[..v.len()].copy_from_slice(v);
            f32x4::new(lanes)
        };
        let out = op(pad(t), pad(s)).to_array();
        t.copy_from_slice(&out[..t.len()]);
    }
}

/// In-place prefilter of a row-major `side` x `side` array along its
/// columns (the recursion steps from row to row, every step updating a
/// whole row), without the gain of 6.
fn prefilter_along_rows(data: &mut [f32], side: usize) {
    let pole = f32x4::splat(POLE);
    // Causal initialisation: row 0 gathers sum_k z^k row_k (mirror boundary)
    // while rows 1.. are still the samples.
    let (first, rest) = data.split_at_mut(side);
    let mut zk = 1.0;
    for row in rest.chunks_exact(side).take(INITIALISATION_TERMS - 1) {
        zk *= POLE;
        let z = f32x4::splat(zk);
        update_row(first, row, |a, b| a + z * b);
    }
    for r in 1..side {
        let (done, rest) = data.split_at_mut(r * side);
        update_row(&mut rest[..side], &done[(r - 1) * side..], |c, p| {
            c + pole * p
        });
    }
    let (before, last) = data.split_at_mut((side - 1) * side);
    let factor = f32x4::splat(POLE / (POLE * POLE - 1.0));
    update_row(last, &before[(side - 2) * side..], |l, b| {
        factor * (l + pole * b)
    });
    for r in (0..side - 1).rev() {
        let (head, next) = data.split_at_mut((r + 1) * side);
        update_row(&mut head[r * side..], &next[..side], |c, n| pole * (n - c));
    }
}

/// `target` = the transpose of the row-major `side` x `side` array
/// `source`, in 4 x 4 blocks of vectors.
fn transpose(source: &[f32], target: &mut [f32], side: usize) {
    let whole = side - side % LANES;
    for r in (0..whole).step_by(LANES) {
        let rows = &source[r * side..(r + LANES) * side];
        let (row0, rest) = rows.split_at(side);
        let (row1, rest) = rest.split_at(side);
        let (row2, row3) = rest.split_at(side);
        for c in (0..whole).step_by(LANES) {
            let block = [row0, row1, row2, row3].map(|row| vector(&row[c..]));
            for (k, column) in f32x4::transpose(block).iter().enumerate() {
                target[(c + k) * side + r..][..LANES].copy_from_slice(&column.to_array());
            }
        }
        for c in whole..side {
            for k in r..r + LANES {
                target[c * side + k] = source[k * side + c];
            }
        }
    }
    for r in whole..side {
        for c in 0..side {
            target[c * side + r] = source[r * side + c];
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
        transpose(&self.samples, &mut self.coefficients, side);
        prefilter_along_rows(&mut self.coefficients, side);
    }

    /// The five sums one IC-GN step needs over the interpolated values
    /// $g_{ij}$ on the grid $(x_0 + i, y_0 + j)$, $i, j < n$, in patch pixel
    /// coordinates: $\sum g$, $\sum g^2$, $\sum a g$, $\sum b g$,
    /// $\sum c g$, where `a`, `b`, `c` hold one value per node, column-major
    /// (`[i * n + j]`). The caller keeps $1 \le x_0$ and
    /// $x_0 + n < $ `side` $- 2$, likewise for $y_0$.
    ///
    /// The $y$ pass leaves one column of $n$ values per patch column, stored
    /// one after the other, so node $k = i n + j$ of the $x$ pass reads
    /// entries $k$, $k + n$, $k + 2n$, $k + 3n$: the $x$ pass and the sums
    /// are one flat loop over the $n^2$ nodes in blocks of [`LANES`],
    /// summed lane by lane in `f32` and moved to `f64` every
    /// [`BLOCKS_PER_FLUSH`] blocks (32 terms per lane, as many as the
    /// 33-term rows of the earlier per-row version: a relative rounding
    /// near $10^{-7}$).
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
        let nodes = n * n;
        let along_y = &self.along_y;
        let taps = [
            &along_y[..nodes],
            &along_y[n..n + nodes],
            &along_y[2 * n..2 * n + nodes],
            &along_y[3 * n..3 * n + nodes],
        ];
        let mut totals = [0.0f64; 5];
        let whole = nodes - nodes % LANES;
        let span = LANES * BLOCKS_PER_FLUSH;
        for first in (0..whole).step_by(span) {
            let range = first..(first + span).min(whole);
            let partial = block_sums(
                wx,
                taps.map(|v| &v[range.clone()]),
                [a, b, c].map(|v| &v[range.clone()]),
            );
            for (t, lanes) in totals.iter_mut().zip(partial) {
                *t += lanes.to_array().iter().map(|&v| v as f64).sum::<f64>();
            }
        }
        for k in whole..nodes {
            let g =
                wx[0] * taps[0][k] + wx[1] * taps[1][k] + wx[2] * taps[2][k] + wx[3] * taps[3][k];
            for (t, term) in totals.iter_mut().zip([1.0, g, a[k], b[k], c[k]]) {
                *t += (term * g) as f64;
            }
        }
        totals
    }
}

/// Lane-wise sums $\sum g$, $\sum g^2$, $\sum a g$, $\sum b g$, $\sum c g$
/// over a whole number of blocks of [`LANES`] nodes, with
/// $g = \sum_k w_k\,\mathrm{tap}_k$ the $x$ pass of the B-spline.
///
/// Written with explicit vectors: left to itself, the compiler's vectoriser
/// groups the lanes of different sums into one register and spends more
/// instructions shuffling than adding.
fn block_sums(wx: [f32; 4], [p, q, r, s]: [&[f32]; 4], [a, b, c]: [&[f32]; 3]) -> [f32x4; 5] {
    let w = wx.map(f32x4::splat);
    let mut sums = [f32x4::ZERO; 5];
    for ((((((p, q), r), s), a), b), c) in p
        .chunks_exact(LANES)
        .zip(q.chunks_exact(LANES))
        .zip(r.chunks_exact(LANES))
        .zip(s.chunks_exact(LANES))
        .zip(a.chunks_exact(LANES))
        .zip(b.chunks_exact(LANES))
        .zip(c.chunks_exact(LANES))
    {
        let g = w[0] * vector(p) + w[1] * vector(q) + w[2] * vector(r) + w[3] * vector(s);
        sums[0] += g;
        sums[1] += g * g;
        sums[2] += vector(a) * g;
        sums[3] += vector(b) * g;
        sums[4] += vector(c) * g;
    }
    sums
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
