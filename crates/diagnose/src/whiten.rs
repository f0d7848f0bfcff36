//! Whiten the residuals with their full noise covariance.
//!
//! Marker coordinates carry independent tracking noise $\sigma_m$ (or the
//! row's own `sx`, `sy` where `markers.csv` gives them) and forces
//! independent sensor noise $\sigma_F$. A probe frame's markers are
//! predicted from the *measured* probe force $F$, whose noise (standard
//! deviation $s$ per component, after averaging) moves every marker of the
//! frame together along the unit responses $g_x, g_y$ (the displacements,
//! stacked over the frame's markers, under unit forces along x and y). The
//! covariance of that frame's $2n$ residuals is therefore, with
//! $D = \operatorname{diag}(\sigma_i)$ the markers' own noise,
//!
//! $$ C = D^2 + s^2 (g_x g_x^T + g_y g_y^T)
//!      = D (I + U U^T) D, \qquad U = s D^{-1} [g_x\; g_y]. $$
//!
//! Treating it as diagonal lets effects that rescale whole trials absorb the
//! correlated part and look significant when they are not. The whitening
//! used here is $W = (I + U U^T)^{-1/2} D^{-1}$ (so $W C W^T = I$; with
//! one $\sigma_m$ for all it is the symmetric $C^{-1/2}$): with
//! $U^T U = V \Lambda V^T$ and $q_i = U v_i / \sqrt{\lambda_i}$
//! (orthonormal),
//!
//! $$ W = \Big(I + \sum_i \big((1+\lambda_i)^{-1/2} - 1\big) q_i q_i^T\Big) D^{-1}, $$
//!
//! two dot products and two updates per frame, $O(n)$, never a dense
//! $2n \times 2n$ matrix. The responses are taken at the first fit, and
//! again from each model the ladder adds an effect to (at that effect's
//! refit, before the model is fitted): every model of one step is compared
//! under the same weights, and each step's model is fitted under its own
//! responses. An effect can change them several-fold: on a probing campaign
//! (no needles) with a foundation under the slab, the fit under the
//! baseline's weights stopped 6.5% above the chi-square per dof of the same
//! model fitted alone (1.065 against 0.997, `Unexplained` for
//! `ConsistentWithNoise`). When the noise is estimated from the fit (see
//! `noise`) the weights are taken again after each step's fit, with it.

/// The responses of one probe frame to unit forces, for its covariance.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ProbeResponse {
    /// First residual slot of the frame.
    pub start: usize,
    /// Response to a unit x force, two entries per marker of the frame.
    pub unit_x: Vec<f64>,
    /// Response to a unit y force, same layout.
    pub unit_y: Vec<f64>,
    /// Standard deviation of each component of the frame's probe force (N).
    pub force_sigma: f64,
}

/// One direction of correlated noise in a frame: unit vector `q` over the
/// frame's slots and the coefficient $(1+\lambda)^{-1/2} - 1$.
#[derive(Debug, Clone, PartialEq)]
struct Direction {
    q: Vec<f64>,
    coefficient: f64,
}

#[derive(Debug, Clone, PartialEq)]
struct CorrelatedFrame {
    start: usize,
    directions: Vec<Direction>,
}

/// The whitening operator of one diagnosis: residual vector (model - data,
/// marker coordinates first, then forces) to independent unit-variance
/// residuals.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Whitening {
    marker_sigma: f64,
    /// Per marker slot, the row's own tracking sigma (`sx` or `sy`), NaN
    /// where its row gives none; empty when no row does.
    row_sigmas: Vec<f64>,
    force_sigma: f64,
    marker_count: usize,
    frames: Vec<CorrelatedFrame>,
}

impl Whitening {
    /// Independent noise: $\sigma_m$ on the first `marker_count` residuals
    /// (or the row's own, `row_sigmas`, where finite), $\sigma_F$ on the
    /// rest.
    pub fn independent(
        marker_count: usize,
        marker_sigma: f64,
        row_sigmas: &[f64],
        force_sigma: f64,
    ) -> Self {
        Self {
            marker_sigma,
            row_sigmas: row_sigmas.to_vec(),
            force_sigma,
            marker_count,
            frames: Vec::new(),
        }
    }

    /// Independent noise plus each probe frame's correlated force noise.
    pub fn with_probe_noise(
        marker_count: usize,
        marker_sigma: f64,
        row_sigmas: &[f64],
        force_sigma: f64,
        responses: &[ProbeResponse],
    ) -> Self {
        let mut out = Self::independent(marker_count, marker_sigma, row_sigmas, force_sigma);
        let frames = responses
            .iter()
            .map(|r| CorrelatedFrame {
                start: r.start,
                directions: directions(r, |slot| out.slot_sigma(slot)),
            })
            .collect();
        out.frames = frames;
        out
    }

    /// The marker noise of residual slot `slot`.
    fn slot_sigma(&self, slot: usize) -> f64 {
        match self.row_sigmas.get(slot) {
            Some(&sigma) if sigma.is_finite() => sigma,
            _ => self.marker_sigma,
        }
    }

    /// Whitened residuals of `raw` (model - data).
    pub fn apply(&self, raw: &[f64]) -> Vec<f64> {
        let mut out = raw.to_vec();
        let split = self.marker_count.min(out.len());
        for (slot, r) in out[..split].iter_mut().enumerate() {
            *r /= self.slot_sigma(slot);
        }
        for r in &mut out[split..] {
            *r /= self.force_sigma;
        }
        for frame in &self.frames {
            for d in &frame.directions {
                let block = &mut out[frame.start..frame.start + d.q.len()];
                let projection: f64 = block.iter().zip(&d.q).map(|(r, q)| r * q).sum();
                let scale = d.coefficient * projection;
                for (r, q) in block.iter_mut().zip(&d.q) {
                    *r += scale * q;
                }
            }
        }
        out
    }
}

/// The eigen-directions of $U U^T$ for one frame.
fn directions(response: &ProbeResponse, slot_sigma: impl Fn(usize) -> f64) -> Vec<Direction> {
    let scaled = |unit: &[f64]| -> Vec<f64> {
        unit.iter()
            .enumerate()
            .map(|(k, g)| response.force_sigma * g / slot_sigma(response.start + k))
            .collect()
    };
    let u: [Vec<f64>; 2] = [scaled(&response.unit_x), scaled(&response.unit_y)];
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let (a, b, d) = (dot(&u[0], &u[0]), dot(&u[0], &u[1]), dot(&u[1], &u[1]));
    let mean = 0.5 * (a + d);
    let radius = (0.25 * (a - d).powi(2) + b * b).sqrt();
    let mut out = Vec::new();
    for lambda in [mean + radius, mean - radius] {
        // Below this the correction is lost in round-off anyway.
        if lambda <= 1e-12 * (a + d).max(f64::MIN_POSITIVE) {
            continue;
        }
        // Eigenvector of the 2 x 2 matrix [[a, b], [b, d]] for lambda.
        let v = if b.abs() > 1e-14 * (a + d) {
            let (x, y) = (lambda - d, b);
            let norm = x.hypot(y);
            [x / norm, y / norm]
        } else if (lambda - a).abs() <= (lambda - d).abs() {
            [1.0, 0.0]
        } else {
            [0.0, 1.0]
        };
        let scale = 1.0 / lambda.sqrt();
        let q = u[0]
            .iter()
            .zip(&u[1])
            .map(|(x, y)| scale * (v[0] * x + v[1] * y))
            .collect();
        out.push(Direction {
            q,
            coefficient: 1.0 / (1.0 + lambda).sqrt() - 1.0,
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use nalgebra::DMatrix;
    use proptest::prelude::*;

    use super::*;

    /// The whitening as a dense matrix, column by column.
    fn dense(whitening: &Whitening, n: usize) -> DMatrix<f64> {
        DMatrix::from_fn(n, n, |i, j| {
            let mut e = vec![0.0; n];
            e[j] = 1.0;
            whitening.apply(&e)[i]
        })
    }

    proptest! {
        /// $W C W^T = I$ for the covariance the module doc states.
        /// Some marker slots with their rows' own sigma, the rest with the
        /// channel's.
        #[test]
        fn whitened_covariance_is_the_identity(
            gx in prop::collection::vec(-1.0e-3f64..1.0e-3, 6),
            gy in prop::collection::vec(-1.0e-3f64..1.0e-3, 6),
            force_sigma in 1.0e-4f64..1.0e-1,
            rows in prop::collection::vec(prop::option::of(2.0e-6f64..3.0e-5), 8),
            with_rows in any::<bool>(),
        ) {
            let (sm, sf) = (8.0e-6, 5.0e-3);
            let row_sigmas: Vec<f64> = if with_rows {
                rows.iter().map(|r| r.unwrap_or(f64::NAN)).collect()
            } else {
                Vec::new()
            };
            let slot_sigma = |i: usize| match row_sigmas.get(i) {
                Some(s) if s.is_finite() => *s,
                _ => sm,
            };
            // Two independent marker slots, the 6-slot probe frame, two forces.
            let (markers, n) = (8, 10);
            let response = ProbeResponse {
                start: 2,
                unit_x: gx.clone(),
                unit_y: gy.clone(),
                force_sigma,
            };
            let w = dense(
                &Whitening::with_probe_noise(markers, sm, &row_sigmas, sf, &[response]),
                n,
            );
            let mut c = DMatrix::zeros(n, n);
            for i in 0..n {
                c[(i, i)] = if i < markers { slot_sigma(i).powi(2) } else { sf * sf };
            }
            for i in 0..6 {
                for j in 0..6 {
                    c[(2 + i, 2 + j)] += force_sigma.powi(2) * (gx[i] * gx[j] + gy[i] * gy[j]);
                }
            }
            let identity = &w * c * w.transpose();
            for i in 0..n {
                for j in 0..n {
                    let expected = if i == j { 1.0 } else { 0.0 };
                    prop_assert!((identity[(i, j)] - expected).abs() < 1e-9,
                        "({i}, {j}): {}", identity[(i, j)]);
                }
            }
        }
    }

    #[test]
    fn parallel_responses_leave_one_direction() {
        let g = vec![1.0e-3, -2.0e-3, 0.5e-3, 0.0];
        let response = ProbeResponse {
            start: 0,
            unit_x: g.clone(),
            unit_y: g.iter().map(|v| 2.0 * v).collect(),
            force_sigma: 1.0e-2,
        };
        assert_eq!(directions(&response, |_| 1.0e-5).len(), 1);
        let independent = Whitening::independent(4, 2.0, &[], 4.0);
        assert_eq!(
            independent.apply(&[2.0, 4.0, 6.0, 8.0, 4.0]),
            vec![1.0, 2.0, 3.0, 4.0, 1.0]
        );
        // A row's own sigma where given, the channel's elsewhere.
        let rows = Whitening::independent(4, 2.0, &[f64::NAN, 8.0, 3.0, f64::NAN], 4.0);
        assert_eq!(
            rows.apply(&[2.0, 4.0, 6.0, 8.0, 4.0]),
            vec![1.0, 0.5, 2.0, 4.0, 1.0]
        );
    }
}
