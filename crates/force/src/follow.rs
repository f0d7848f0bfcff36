//! The tip-following estimator: one density profile behind the tip, fitted
//! to several frames at once.
//!
//! **Assumption.** At a constant insertion velocity in a homogeneous
//! phantom the axial force density is a steady function of the distance
//! behind the tip, $q_k(s) = f(L_k - s)$ at every frame $k$ (inserted length
//! $L_k$, $s$ from the deformed entry). The markers are fixed while the tip
//! moves, so each frame samples $f$ at a different offset between the tip
//! and the marker grid (and the model's mesh): together, frames spread over
//! one marker spacing of depth see a tip feature at every offset and
//! resolve it below the marker spacing, which no single frame can.
//!
//! **Estimate.** $f(d) = \sum_j f_j \psi_j(d)$ with hat functions on nodes
//! $d_j = jh$ behind the tip ([`FollowOptions::spacing`], finer than the
//! single-frame stations). Frame $k$'s load is placed as the single-frame
//! estimator places it (`crate::place`, in the model's field of the frame's
//! own fit), and its whitened response to the nodes is
//! $A_k = W_k H K^{-1} P_k$, $(P_k)_{\cdot j}$ the loads of $\psi_j(L_k - s)$.
//! With the frames' whitened data $b_k$,
//!
//! $$\hat f = \arg\min_f \sum_k |A_k f - b_k|^2 + \lambda|L_{z,\rho} f|^2,$$
//!
//! solved from the pooled normal equations $\sum_k A_k^TA_k$,
//! $\sum_k A_k^T b_k$; $\lambda$ and the tip prior $(z, \rho)$ (the same
//! candidates as [`crate::TipPrior::Evidence`], zones measured from the
//! tip, $d = 0$) are those of largest marginal likelihood of the pooled data
//! (`crate::evidence`). Frames of other insertions at the same velocity
//! (the paper's repeated insertions) pool the same way: each brings its own
//! model.
//!
//! **Check.** A frame the steady profile does not explain is flagged
//! ([`crate::LambdaChoice::PooledNotExplained`]): when the pooled fit
//! misses it by more than Morozov's margin beyond the frame's own fit,
//! $|A_k\hat f - b_k|^2 - |A_k\hat q_k - b_k|^2 > (\tau^2 - 1)\,m_k$
//! ($\hat q_k$ the single-frame estimate, $m_k$ its data), or when the
//! pooled model as a whole is short of the noise ($\hat s^2 > \tau^2$ at the
//! evidence's optimum; the implied variance $\hat s^2$ then plays the
//! noise, since the evidence with a noise far below the model error fits
//! that error).

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::error::ForceError;
use crate::estimate::{ShaftDistribution, ShaftEstimator};
use crate::evidence::Evidence;
use crate::observe::{Frame, Insertion};
use crate::place::Placement;
use crate::regularise::{DISCREPANCY_SAFETY, LambdaChoice, Regularisation};
use crate::shaft::{ShaftBasis, Smoothness};
use crate::tip::{TipPrior, TipZone};

/// Fixed-point rounds of the noise variance when the pooled model is short
/// of the stated noise ([`fit_tip_following`]).
const FLOOR_ROUNDS: usize = 3;

/// Output stations per node spacing of the profile when a frame's density
/// is tabulated along its shaft (the profile's kinks are rounded over a
/// quarter of its spacing).
const OUTPUT_PER_SPACING: f64 = 4.0;

/// Options of the tip-following estimator.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FollowOptions {
    /// Spacing of the profile's nodes behind the tip (m).
    pub spacing: f64,
    /// Which frames [`tip_following_distributions`](crate::tip_following_distributions) pools for a target
    /// frame: `Some(w)`, the frames whose tip depth lies within `w` marker
    /// spacings of the target's (the density need only be steady over that
    /// stretch; one spacing either side sees every offset between the tip
    /// and the marker grid); `None`, every frame of the insertion (steady
    /// over the whole insertion). Either way frames the profile does not
    /// explain are dropped and the profile refitted
    /// ([`fit_explained_pool`](crate::fit_explained_pool)).
    pub window_spacings: Option<f64>,
}

impl Default for FollowOptions {
    /// Nodes 0.5 mm apart (a third of the single-frame stations), the
    /// frames within one marker spacing of depth either side pooled.
    fn default() -> Self {
        Self {
            spacing: 0.5e-3,
            window_spacings: Some(1.0),
        }
    }
}

/// One frame prepared for pooling: its single-frame estimate, its whitened
/// data and their response to the profile's nodes.
#[derive(Debug, Clone)]
pub struct FollowedFrame {
    /// The frame's own estimate (the single-frame estimator).
    pub single: ShaftDistribution,
    /// Inserted length of the pooled placement (m).
    pub(crate) length: f64,
    /// Node spacing of the profile (m).
    spacing: f64,
    smoothness: Smoothness,
    /// $A_k$: whitened marker rows x profile nodes $0 \dots n_k - 1$.
    design: DMatrix<f64>,
    /// $b_k$: whitened data.
    pub(crate) data: DVector<f64>,
    /// The rows' weights $1/\sigma$ (to report the residual in metres).
    weights: DVector<f64>,
    /// $|A_k\hat q_k - b_k|^2$ of the single-frame fit.
    pub(crate) single_misfit: f64,
}

impl FollowedFrame {
    /// Profile nodes this frame's shaft reaches.
    pub(crate) fn nodes(&self) -> usize {
        self.design.ncols()
    }
}

/// How well the pooled profile explains one frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FrameCheck {
    /// Frame time (s).
    pub t: f64,
    /// Inserted length (m).
    pub length: f64,
    /// Whitened misfit of the pooled profile on this frame.
    pub pooled_misfit: f64,
    /// Whitened misfit of the frame's own fit.
    pub single_misfit: f64,
    /// Marker coordinates of the frame, $m_k$.
    pub data_count: usize,
}

impl FrameCheck {
    /// The pooled misfit's excess over the frame's own, in units of
    /// Morozov's margin $(\tau^2 - 1) m_k$: above 1 the steady profile does
    /// not explain the frame.
    pub fn excess(&self) -> f64 {
        (self.pooled_misfit - self.single_misfit)
            / ((DISCREPANCY_SAFETY * DISCREPANCY_SAFETY - 1.0) * self.data_count as f64)
    }

    /// True when the steady profile explains the frame.
    pub fn is_explained(&self) -> bool {
        self.excess() <= 1.0
    }
}

/// The density profile behind the tip fitted to a pool of frames.
#[derive(Debug, Clone, PartialEq)]
pub struct TipFollowing {
    /// Node spacing (m): node $j$ lies $jh$ behind the tip.
    pub spacing: f64,
    /// Profile values at the nodes (N/m).
    pub density: Vec<f64>,
    /// One standard deviation of them from the marker noise (N/m).
    pub density_sigma: Vec<f64>,
    /// Covariance of the node values (from the marker noise).
    covariance: DMatrix<f64>,
    /// The regularisation weight of the whitened problem.
    pub lambda: f64,
    /// The tip prior the evidence chose (zone measured from the tip).
    pub tip_zone: TipZone,
    /// $\hat s^2$ at the optimum: 1 when the model explains the pooled
    /// whitened data to the noise.
    pub noise_variance: f64,
    /// The check of every pooled frame, in pool order.
    pub frames: Vec<FrameCheck>,
}

impl ShaftEstimator {
    /// Prepares `frame` for a tip-following pool with profile nodes
    /// `spacing` apart: the single-frame estimate, then the load re-placed
    /// in the model's field of that estimate on pieces fine enough for the
    /// profile, and the frame's whitened response to the profile's nodes.
    ///
    /// Errors: those of [`ShaftEstimator::estimate`]; an estimator whose
    /// rule is not [`Regularisation::MarginalLikelihood`] (the pooled prior
    /// is chosen by the evidence, which needs the noise).
    pub fn follow(
        &self,
        insertion: &Insertion,
        frame: &Frame,
        spacing: f64,
    ) -> Result<FollowedFrame, ForceError> {
        crate::error::positive("profile spacing", spacing)?;
        if !matches!(
            self.options().regularisation,
            Regularisation::MarginalLikelihood { .. }
        ) {
            return Err(ForceError::Mismatch(
                "the tip-following estimator needs Regularisation::MarginalLikelihood (a known noise)"
                    .into(),
            ));
        }
        let placed = self.estimate_placed(insertion, frame)?;
        let response = self.response();
        let q = DVector::from_column_slice(&placed.solved.density);
        let field = response.band_field(&(&placed.solved.loads * q));
        let extent = [insertion.phantom.width, insertion.phantom.depth];
        let fine = Placement::in_field(&placed.needle, spacing, &|x| field.at(x), extent)?;
        let length = fine.basis.length();
        let nodes = (length / spacing - 1e-9).ceil() as usize + 1;
        let loads = response.point_loads_of(&fine.load_points(), nodes, length, |s| {
            profile_hats(length - s, spacing, nodes)
        })?;
        let g = response.marker_response(&loads);
        let weighted = self.weighted_data(insertion, frame)?;
        let m = weighted.rows.len();
        if m < nodes {
            return Err(ForceError::TooFewMarkers {
                context: "tip-following profile (tracked marker coordinates)",
                found: m,
                required: nodes,
            });
        }
        let design = DMatrix::from_fn(m, nodes, |r, j| {
            weighted.weights[r] * g[(weighted.rows[r], j)]
        });
        let data = DVector::from_fn(m, |r, _| weighted.weights[r] * weighted.values[r]);
        let single_misfit = placed.solved.whitened_misfit;
        Ok(FollowedFrame {
            single: placed
                .solved
                .into_distribution(frame, &placed.placement, placed.change),
            length,
            spacing,
            smoothness: self.options().smoothness,
            design,
            data,
            weights: DVector::from_vec(weighted.weights),
            single_misfit,
        })
    }
}

/// The hat functions of the profile at distance `d` behind the tip: pairs
/// (node, value), nodes `spacing` apart from $d = 0$.
fn profile_hats(d: f64, spacing: f64, nodes: usize) -> Vec<(usize, f64)> {
    let x = (d / spacing).max(0.0);
    let k = (x.floor() as usize).min(nodes.saturating_sub(2));
    let t = (x - k as f64).clamp(0.0, 1.0);
    vec![(k, 1.0 - t), (k + 1, t)]
}

/// $\int_a^b \psi_j(d)\,dd$ for the hat of node `j`, nodes `h` apart.
fn hat_integral(j: usize, h: f64, a: f64, b: f64) -> f64 {
    // Antiderivative of the hat in units of h, from its left foot.
    let primitive = |d: f64| {
        let t = ((d - j as f64 * h) / h).clamp(-1.0, 1.0);
        h * if t < 0.0 {
            0.5 * (t + 1.0).powi(2)
        } else {
            1.0 - 0.5 * (1.0 - t).powi(2)
        }
    };
    primitive(b) - primitive(a)
}

/// The steady profile behind the tip that best explains the pooled
/// `frames` (one insertion or several at the same velocity), with
/// $\lambda$ and the tip prior of largest marginal likelihood, and the
/// check of every frame. When the pooled model is short of the stated
/// noise ($\hat s^2 > \tau^2$), the variance the fit implies plays the
/// noise (a few fixed-point rounds of $\hat s^2$), and every frame is
/// flagged.
///
/// Errors: no frames, frames prepared with different spacings or priors,
/// a singular pooled problem.
pub fn fit_tip_following(frames: &[&FollowedFrame]) -> Result<TipFollowing, ForceError> {
    fit_profile(frames, 0)
}

/// [`fit_tip_following`] with at least `nodes` profile nodes (the nodes no
/// pooled frame reaches follow the prior).
pub(crate) fn fit_profile(
    frames: &[&FollowedFrame],
    nodes: usize,
) -> Result<TipFollowing, ForceError> {
    let first = frames
        .first()
        .ok_or_else(|| ForceError::Mismatch("no frames to pool".into()))?;
    let (h, smoothness) = (first.spacing, first.smoothness);
    if frames
        .iter()
        .any(|f| f.spacing != h || f.smoothness != smoothness)
    {
        return Err(ForceError::Mismatch(
            "pooled frames were prepared with different profile spacings or priors".into(),
        ));
    }
    let n = frames.iter().map(|f| f.nodes()).fold(nodes, usize::max);
    let mut gram = DMatrix::zeros(n, n);
    let mut projected = DVector::zeros(n);
    let (mut data_squared, mut count) = (0.0, 0);
    for f in frames {
        let k = f.nodes();
        let mut block = gram.view_mut((0, 0), (k, k));
        block += f.design.tr_mul(&f.design);
        let mut head = projected.rows_mut(0, k);
        head += f.design.tr_mul(&f.data);
        data_squared += f.data.norm_squared();
        count += f.data.len();
    }
    // The prior's operator on the nodes in the order of a shaft whose tip
    // is its far end (node j at s = (n - 1 - j) h), so that the tip zones
    // are measured from d = 0.
    let along = ShaftBasis {
        stations: (0..n).map(|j| j as f64 * h).collect(),
    };
    let zones = TipPrior::Evidence.candidates()?;
    let operators: Vec<DMatrix<f64>> = zones
        .iter()
        .map(|z| {
            let l = z.operator(&along, smoothness);
            DMatrix::from_fn(l.nrows(), n, |r, j| l[(r, n - 1 - j)])
        })
        .collect();
    // The most probable prior for the data whitened by `variance` times
    // the stated noise variance: (index, lambda of the stated-noise
    // problem, the variance the fit implies in units of the stated one).
    let most_probable = |variance: f64| {
        let evidence = Evidence::from_normal(
            &gram / variance,
            &projected / variance,
            data_squared / variance,
            count,
        );
        operators
            .iter()
            .enumerate()
            .filter_map(|(k, l)| evidence.most_probable(l).map(|found| (k, found)))
            .min_by(|x, y| x.1.score.total_cmp(&y.1.score))
            .map(|(k, found)| (k, found.lambda * variance, found.noise_variance * variance))
            .ok_or_else(|| ForceError::Mismatch("the pooled profile is singular".into()))
    };
    let (mut k, mut lambda, noise_variance) = most_probable(1.0)?;
    // Short of the stated noise, the evidence's noise model fails (it fits
    // the model error, see `crate::evidence`): the variance the fit implies
    // plays the noise instead, a few fixed-point rounds; the profile stays
    // flagged through `noise_variance`.
    let mut variance = 1.0;
    if noise_variance > DISCREPANCY_SAFETY * DISCREPANCY_SAFETY {
        variance = noise_variance;
        for _ in 0..FLOOR_ROUNDS {
            let found = most_probable(variance)?;
            (k, lambda, variance) = found;
        }
    }
    let l = &operators[k];
    let inverse = (&gram + l.tr_mul(l) * lambda)
        .cholesky()
        .ok_or_else(|| ForceError::Mismatch("the pooled profile is singular".into()))?
        .inverse();
    let density = &inverse * &projected;
    let covariance = &inverse * &gram * &inverse * variance;
    let checks = frames
        .iter()
        .map(|f| check(f, &density))
        .collect::<Vec<_>>();
    Ok(TipFollowing {
        spacing: h,
        density_sigma: (0..n).map(|j| covariance[(j, j)].max(0.0).sqrt()).collect(),
        density: density.iter().copied().collect(),
        covariance,
        lambda,
        tip_zone: zones[k],
        noise_variance,
        frames: checks,
    })
}

/// The pooled profile's misfit on one frame against the frame's own.
pub(crate) fn check(frame: &FollowedFrame, profile: &DVector<f64>) -> FrameCheck {
    let k = frame.nodes().min(profile.len());
    let residual = frame.design.columns(0, k) * profile.rows(0, k) - &frame.data;
    FrameCheck {
        t: frame.single.t,
        length: frame.length,
        pooled_misfit: residual.norm_squared(),
        single_misfit: frame.single_misfit,
        data_count: frame.data.len(),
    }
}

impl TipFollowing {
    /// The profile at distance `d` behind the tip (N/m; zero beyond the
    /// last node).
    pub fn density_behind_tip(&self, d: f64) -> f64 {
        let n = self.density.len();
        if !(0.0..=(n - 1) as f64 * self.spacing).contains(&d) {
            return 0.0;
        }
        profile_hats(d, self.spacing, n)
            .iter()
            .map(|&(j, w)| w * self.density[j])
            .sum()
    }

    /// True when the model explains the pooled data to the noise.
    pub fn reaches_noise(&self) -> bool {
        self.noise_variance <= DISCREPANCY_SAFETY * DISCREPANCY_SAFETY
    }

    /// The profile as `frame`'s density along its shaft, $q(s) = f(L - s)$,
    /// in the single-frame estimate's form: stations a quarter of the
    /// profile's spacing apart, the integral and its noise from the
    /// profile's covariance, flagged ([`LambdaChoice::PooledNotExplained`])
    /// when the profile does not explain the frame or the pooled model is
    /// short of the noise. `frame` need not be in the pool.
    ///
    /// Errors: a frame prepared with another spacing or reaching beyond the
    /// profile.
    pub fn distribution(&self, frame: &FollowedFrame) -> Result<ShaftDistribution, ForceError> {
        let n = self.density.len();
        if frame.spacing != self.spacing || frame.nodes() > n {
            return Err(ForceError::Mismatch(format!(
                "a frame of {} m (profile spacing {} m) against a profile of {} nodes {} m apart",
                frame.length, frame.spacing, n, self.spacing
            )));
        }
        let profile = DVector::from_column_slice(&self.density);
        let checked = check(frame, &profile);
        let length = frame.length;
        let basis = ShaftBasis::new(length, self.spacing / OUTPUT_PER_SPACING)?;
        let mut density = Vec::with_capacity(basis.len());
        let mut density_sigma = Vec::with_capacity(basis.len());
        for &s in &basis.stations {
            let hats = profile_hats(length - s, self.spacing, n);
            density.push(hats.iter().map(|&(j, w)| w * self.density[j]).sum());
            let variance: f64 = hats
                .iter()
                .flat_map(|&(i, wi)| {
                    hats.iter()
                        .map(move |&(j, wj)| wi * wj * self.covariance[(i, j)])
                })
                .sum();
            density_sigma.push(variance.max(0.0).sqrt());
        }
        let w = DVector::from_fn(n, |j, _| hat_integral(j, self.spacing, 0.0, length));
        let residual =
            frame.design.columns(0, frame.nodes()) * profile.rows(0, frame.nodes()) - &frame.data;
        let metres: f64 = residual
            .iter()
            .zip(frame.weights.iter())
            .map(|(r, w)| (r / w).powi(2))
            .sum();
        let single = &frame.single;
        Ok(ShaftDistribution {
            length,
            stations: basis.stations,
            density,
            density_sigma,
            integrated: w.dot(&profile),
            integrated_sigma: (w.transpose() * &self.covariance * &w)[(0, 0)]
                .max(0.0)
                .sqrt(),
            lambda: self.lambda,
            choice: if checked.is_explained() && self.reaches_noise() {
                LambdaChoice::MarginalLikelihood
            } else {
                LambdaChoice::PooledNotExplained
            },
            tip_zone: self.tip_zone,
            residual_rms: (metres / frame.data.len() as f64).sqrt(),
            ..single.clone()
        })
    }
}
