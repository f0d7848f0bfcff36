//! The marginal likelihood (evidence) of a smoothness prior, for choosing
//! its weight $\lambda$ and its form from the data when the noise is known.
//!
//! Read the regularised problem $\min_q |Aq - b|^2 + \lambda|Lq|^2$ on
//! whitened data as a Gaussian model: $b = Aq + e$ with $e \sim N(0, I)$,
//! and a prior density $\propto \exp(-\lambda|Lq|^2/2)$ on $q$ (improper
//! along the null space of $L$, the constants for a first difference).
//! With $N = A^TA + \lambda L^TL$, $\hat q = N^{-1}A^Tb$ and $p$ the rows of
//! a full-row-rank $L$, the restricted marginal likelihood of the data is
//!
//! $$-2\log p(b \mid \lambda, L) = |A\hat q - b|^2 + \lambda|L\hat q|^2
//! + \log\det N - p\log\lambda - \log\det(LL^T) + \text{const},$$
//!
//! the constant the same for every $L$ with the same shape. The first two
//! terms reward the fit, the determinants (the Occam factor) penalise a
//! prior loose enough to fit the noise. Unlike the discrepancy principle,
//! whose target $|r|^2 = \tau^2 m$ lies $(\tau^2 - 1)m$ above the expected
//! residual (185 noise variances for 441 markers, $m = 882$, at
//! $\tau = 1.1$: 4.4 standard deviations of $\chi^2_m$), it weighs the
//! residual and the prior on the same statistical footing.
//!
//! The evidence assumes the model reaches the noise. Whether it does is
//! checked with the restricted estimate of the noise variance at the
//! optimum, $\hat s^2 = (|A\hat q - b|^2 + \lambda|L\hat q|^2)/(m - n + p)$
//! (1 for whitened data the model explains): above $\tau^2$ the model error
//! dominates and the caller falls back to the discrepancy principle at the
//! misfit floor, flagged.

use nalgebra::{DMatrix, DVector};

/// Steps of the $\lambda$ grid per decade.
const STEPS_PER_DECADE: usize = 5;

/// Decades of the grid below $\mu = \mathrm{tr}(A^TA)/\mathrm{tr}(L^TL)$,
/// the scale at which the two terms weigh alike.
const DECADES_BELOW: i32 = 12;

/// Decades of the grid above $\mu$.
const DECADES_ABOVE: i32 = 4;

/// The normal-equation pieces of one whitened problem, shared by every
/// prior tried on it.
pub(crate) struct Evidence {
    gram: DMatrix<f64>,
    projected: DVector<f64>,
    data_squared: f64,
    data_count: usize,
}

/// The most probable $\lambda$ of one prior.
#[derive(Debug, Clone, Copy)]
pub(crate) struct MostProbable {
    /// $-2\log p(b \mid \lambda, L)$ up to the common constant.
    pub score: f64,
    /// The weight.
    pub lambda: f64,
    /// $\hat s^2$: the noise variance the fit implies (1 when the model
    /// explains the whitened data to the noise).
    pub noise_variance: f64,
}

impl Evidence {
    /// For the whitened data `b` and design `a`.
    pub(crate) fn new(a: &DMatrix<f64>, b: &DVector<f64>) -> Self {
        Self {
            gram: a.tr_mul(a),
            projected: a.tr_mul(b),
            data_squared: b.norm_squared(),
            data_count: a.nrows(),
        }
    }

    /// From the normal-equation pieces of whitened data: $A^TA$, $A^Tb$,
    /// $|b|^2$ and the number of data $m$ (data pooled from several frames
    /// add up this way without forming the stacked $A$).
    pub(crate) fn from_normal(
        gram: DMatrix<f64>,
        projected: DVector<f64>,
        data_squared: f64,
        data_count: usize,
    ) -> Self {
        Self {
            gram,
            projected,
            data_squared,
            data_count,
        }
    }

    /// The $\lambda$ of largest evidence for the prior $L$: a grid of
    /// [`STEPS_PER_DECADE`] per decade, refined by a parabola in
    /// $\log\lambda$ through the best point and its neighbours. `None` when
    /// $L$ is rank-deficient or every $N$ is singular.
    pub(crate) fn most_probable(&self, l: &DMatrix<f64>) -> Option<MostProbable> {
        let penalty_gram = l.tr_mul(l);
        let log_det_llt = log_det(&(l * l.transpose()))?;
        let mu = self.gram.trace() / penalty_gram.trace();
        let at = |log_lambda: f64| {
            self.score(l, &penalty_gram, log_det_llt, mu * 10f64.powf(log_lambda))
        };
        let steps = (DECADES_BELOW + DECADES_ABOVE) as usize * STEPS_PER_DECADE;
        let step = 1.0 / STEPS_PER_DECADE as f64;
        let grid: Vec<(f64, MostProbable)> = (0..=steps)
            .filter_map(|k| {
                let x = -f64::from(DECADES_BELOW) + k as f64 * step;
                at(x).map(|s| (x, s))
            })
            .collect();
        let best = (0..grid.len()).min_by(|&i, &j| grid[i].1.score.total_cmp(&grid[j].1.score))?;
        let mut found = grid[best].1;
        if best > 0 && best + 1 < grid.len() {
            let (f0, f1, f2) = (grid[best - 1].1.score, found.score, grid[best + 1].1.score);
            let curvature = f0 - 2.0 * f1 + f2;
            if curvature > 0.0 {
                let vertex = grid[best].0 + 0.5 * step * (f0 - f2) / curvature;
                if let Some(refined) = at(vertex).filter(|r| r.score < found.score) {
                    found = refined;
                }
            }
        }
        Some(found)
    }

    /// The evidence terms at one $\lambda$.
    fn score(
        &self,
        l: &DMatrix<f64>,
        penalty_gram: &DMatrix<f64>,
        log_det_llt: f64,
        lambda: f64,
    ) -> Option<MostProbable> {
        let normal = (&self.gram + penalty_gram * lambda).cholesky()?;
        let q = normal.solve(&self.projected);
        let residual =
            (self.data_squared - 2.0 * q.dot(&self.projected) + q.dot(&(&self.gram * &q))).max(0.0);
        let misfit = residual + lambda * (l * &q).norm_squared();
        let log_det_normal = 2.0 * normal.l_dirty().diagonal().map(f64::ln).sum();
        let p = l.nrows() as f64;
        let free = (self.data_count + l.nrows()) as f64 - l.ncols() as f64;
        Some(MostProbable {
            score: misfit + log_det_normal - p * lambda.ln() - log_det_llt,
            lambda,
            noise_variance: misfit / free.max(1.0),
        })
    }
}

/// $\log\det$ of a symmetric positive definite matrix; `None` if it is not.
fn log_det(m: &DMatrix<f64>) -> Option<f64> {
    let factor = m.clone().cholesky()?;
    Some(2.0 * factor.l_dirty().diagonal().map(f64::ln).sum())
}
