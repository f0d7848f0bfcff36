//! The noise of a bundle that states none, estimated from its repeated
//! samples.
//!
//! A camera tracks every marker at every frame and the sensor reads the
//! force at every sample, far more often than the tissue's state changes
//! appreciably, so successive samples repeat the same measurement of a
//! slowly moving signal. (Repeated *trials* do not: two insertions follow
//! different lines, since a needle cannot enter the same line twice
//! without changing the phantom.) Over three successive samples
//! $v_0, v_1, v_2$ at times $t_0 < t_1 < t_2$ of a signal that is linear in
//! time over them, the residual of linear interpolation
//! $$e = v_1 - \frac{h_2 v_0 + h_1 v_2}{h_1 + h_2}, \qquad
//!   h_1 = t_1 - t_0,\ h_2 = t_2 - t_1,$$
//! is pure noise of variance $\sigma^2\,(1 + (h_1^2 + h_2^2)/(h_1 + h_2)^2)$
//! (3/2 of $\sigma^2$ at even spacing), whatever the signal's level and
//! slope. Each residual is divided by that factor's square root and the
//! channel's $\sigma$ is their clipped RMS: the RMS of all of them, then
//! of those within [`CLIP_SIGMAS`] times the last value, until it settles
//! (sigma clipping). The clipping keeps events out (a puncture, a probe
//! stepping to its next hold). A scale from the median would be robust
//! from the start, but on a quantised sensor the residuals take few
//! distinct values: on the quick campaign (12.5 mN steps) the median's
//! scale is 7.57 mN and the clipped RMS 5.97 mN, against the 6.17 mN the
//! generator states, and below the resolution most residuals are exactly
//! zero, and so is their median.
//!
//! A marker missing from a frame (occluded) is skipped: its windows span
//! the gap. Curvature of the signal between samples adds to $e$, so it
//! biases the estimate upwards, never downwards, and frames far apart
//! (a few holds of a probe, a few depths of a needle) are all signal. The
//! same scale is therefore also taken from the differences of third order
//! (four successive samples, $\sum_i c_i v_i / \lVert c \rVert$ with the
//! divided difference's coefficients $c_i = 1 / \prod_{j \ne i} (t_i - t_j)$,
//! which the second order's $e$ is too, up to sign): on noise both give
//! $\sigma$, on signal they differ, and unless they agree within
//! [`AGREEMENT`] the channel's noise is taken from the fit instead (at each
//! step of the ladder, see [`NoiseBasis::Fit`]). Even when they agree,
//! `diagnose` takes the lesser of this estimate and the fit's, which
//! misfit inflates instead.

use std::fmt;

use needle_data::Campaign;
use serde::{Deserialize, Serialize};

use crate::whiten::{ProbeResponse, Whitening};

/// Residuals beyond this many sigmas are events, not noise.
const CLIP_SIGMAS: f64 = 4.0;

/// Fewest differences a channel's estimate is made from.
const MIN_DIFFERENCES: usize = 50;

/// The relative difference within which the estimates from differences of
/// second and third order must agree.
const AGREEMENT: f64 = 0.1;

/// At most this many differences per channel and order: beyond it they
/// are taken at an even stride (a full campaign holds millions of marker
/// rows).
const MAX_DIFFERENCES: usize = 1_000_000;

/// One channel's noise estimated from its repeated samples.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SampleNoise {
    /// The standard deviation per coordinate or component from the
    /// differences of second order (m or N).
    pub sigma: f64,
    /// How many differences of second order it was estimated from.
    pub differences: usize,
    /// The same from the differences of third order, if there are enough.
    pub third_order_sigma: Option<f64>,
}

impl SampleNoise {
    /// True when the two orders agree (within 10 %): the samples
    /// are dense enough for the signal between them to be negligible.
    pub fn consistent(&self) -> bool {
        self.third_order_sigma
            .is_some_and(|third| (third / self.sigma - 1.0).abs() <= AGREEMENT)
    }
}

/// Where the noise levels of the whitening came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum NoiseSource {
    /// Stated in the bundle.
    Stated,
    /// Not stated: estimated per channel.
    Estimated {
        /// Marker noise per coordinate (m).
        marker: ChannelNoise,
        /// Force noise per component (N).
        force: ChannelNoise,
    },
}

/// One channel's estimated noise.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ChannelNoise {
    /// The standard deviation (m or N).
    pub sigma: f64,
    /// What it was estimated from.
    pub basis: NoiseBasis,
}

/// What a channel's noise was estimated from.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum NoiseBasis {
    /// The channel's repeated samples (see the module doc).
    RepeatedSamples(SampleNoise),
    /// The residuals of the fit of the model at each step of the ladder,
    /// where that channel's chi-square per dof is 1 by construction and
    /// only the candidate tests carry information: the repeated samples
    /// gave too few differences (`None`), orders that disagree (signal
    /// between samples), or a larger value.
    Fit {
        /// The repeated samples' estimate, if any.
        repeated_samples: Option<SampleNoise>,
    },
    /// Every marker row gives its own standard deviations (`sx,sy` in
    /// `markers.csv`); the channel's sigma is a placeholder.
    Rows,
    /// The channel has no residuals; its sigma is a placeholder.
    NoResiduals,
}

impl ChannelNoise {
    /// The lesser of the repeated samples' estimate, when its two orders
    /// agree, and the fit's, `from_fit` (`None` for a channel without
    /// residuals, which gets `placeholder`).
    pub(crate) fn choose(
        from_fit: Option<f64>,
        repeated: Option<SampleNoise>,
        placeholder: f64,
    ) -> Self {
        match (repeated, from_fit) {
            (Some(r), Some(f)) if r.consistent() && r.sigma <= f => Self {
                sigma: r.sigma,
                basis: NoiseBasis::RepeatedSamples(r),
            },
            (repeated_samples, Some(f)) => Self {
                sigma: f,
                basis: NoiseBasis::Fit { repeated_samples },
            },
            (_, None) => Self {
                sigma: placeholder,
                basis: NoiseBasis::NoResiduals,
            },
        }
    }

    /// The value in `unit` (`scale` per SI unit) and where it came from.
    fn describe(&self, unit: &str, scale: f64) -> String {
        let sigma = self.sigma * scale;
        let third = |r: &SampleNoise| match r.third_order_sigma {
            Some(third) => format!("{:.3} {unit}", third * scale),
            None => "too few".to_string(),
        };
        match &self.basis {
            NoiseBasis::RepeatedSamples(r) => format!(
                "{sigma:.3} {unit} from {} differences of successive samples (third order: {})",
                r.differences,
                third(r)
            ),
            NoiseBasis::Fit {
                repeated_samples: None,
            } => format!("{sigma:.3} {unit} from the fit's residuals"),
            NoiseBasis::Fit {
                repeated_samples: Some(r),
            } => format!(
                "{sigma:.3} {unit} from the fit's residuals (successive samples gave {:.3} {unit}, \
                 third order: {}; signal between samples, or the fit leaves less)",
                r.sigma * scale,
                third(r)
            ),
            NoiseBasis::Rows => "per row, as markers.csv gives them (sx, sy)".to_string(),
            NoiseBasis::NoResiduals => "no data".to_string(),
        }
    }
}

/// The marker noise under which the marker residuals (the first
/// `marker_count` of `residuals`) have chi-square `dof`, each probe frame
/// whitened with its force noise too (`responses`, see `whiten`) and the
/// rows that give their own noise with it (`row_sigmas`); `None` without
/// marker residuals.
///
/// Chi-square falls as the marker noise grows, and without rows of their
/// own it is at most $\nu$ at the plain estimate
/// $\hat\sigma^2 = \sum r^2 / \nu$ (the probe terms only add covariance),
/// so bisection below that finds it. Rows of their own can keep it above
/// $\nu$ at any value; the search then ends at the top of its bracket,
/// a thousand times the plain estimate.
pub(crate) fn marker_sigma_from_fit(
    residuals: &[f64],
    marker_count: usize,
    dof: f64,
    row_sigmas: &[f64],
    responses: &[ProbeResponse],
) -> Option<f64> {
    let markers = &residuals[..marker_count.min(residuals.len())];
    let sum2: f64 = markers.iter().map(|r| r * r).sum();
    if sum2 <= 0.0 || dof <= 0.0 {
        return None;
    }
    let plain = (sum2 / dof).sqrt();
    let chi2 = |sigma: f64| -> f64 {
        // The force channel's own sigma does not touch the markers.
        let whitening =
            Whitening::with_probe_noise(marker_count, sigma, row_sigmas, 1.0, responses);
        whitening.apply(residuals)[..markers.len()]
            .iter()
            .map(|w| w * w)
            .sum()
    };
    let top = if row_sigmas.is_empty() { 1.0 } else { 1e3 };
    let (mut low, mut high) = (1e-3 * plain, top * plain);
    for _ in 0..60 {
        let middle = (low * high).sqrt();
        if chi2(middle) > dof {
            low = middle;
        } else {
            high = middle;
        }
    }
    Some(high)
}

impl NoiseSource {
    /// True when every channel with residuals has its noise per sample
    /// (stated, or from repeated samples) rather than from a fit.
    pub(crate) fn per_sample(&self) -> bool {
        match self {
            Self::Stated => true,
            Self::Estimated { marker, force } => [marker, force]
                .iter()
                .all(|c| !matches!(c.basis, NoiseBasis::Fit { .. })),
        }
    }
}

impl fmt::Display for NoiseSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Stated => write!(f, "stated in the bundle"),
            Self::Estimated { marker, force } => write!(
                f,
                "not stated, estimated: marker {}; force {}",
                marker.describe("um", 1e6),
                force.describe("mN", 1e3)
            ),
        }
    }
}

/// The marker and force noise estimated from repeated samples; `None` for
/// a channel with fewer than [`MIN_DIFFERENCES`] differences.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct RepeatedSampleNoise {
    pub marker: Option<SampleNoise>,
    pub force: Option<SampleNoise>,
}

/// The noise of every channel of `campaign` from its repeated samples.
pub(crate) fn noise_from_repeated_samples(campaign: &Campaign) -> RepeatedSampleNoise {
    RepeatedSampleNoise {
        marker: marker_differences(campaign).noise(),
        force: force_differences(campaign).noise(),
    }
}

/// The divided difference of `v` at the times `t` (order `t.len() - 1`),
/// scaled to the noise's standard deviation: $\sum_i c_i v_i / \lVert c
/// \rVert$; `None` unless the times increase strictly.
fn scaled_difference(t: &[f64], v: &[f64]) -> Option<f64> {
    if !t.windows(2).all(|w| w[1] > w[0]) {
        return None;
    }
    let (mut sum, mut norm2) = (0.0, 0.0);
    for (i, (ti, vi)) in t.iter().zip(v).enumerate() {
        let product: f64 = t
            .iter()
            .enumerate()
            .filter(|&(j, _)| j != i)
            .map(|(_, tj)| ti - tj)
            .product();
        let c = 1.0 / product;
        sum += c * vi;
        norm2 += c * c;
    }
    Some(sum / norm2.sqrt())
}

/// Keeps every `stride`-th of the values pushed.
struct Thinned {
    stride: usize,
    seen: usize,
    values: Vec<f64>,
}

impl Thinned {
    fn new(expected: usize) -> Self {
        Self {
            stride: expected.div_ceil(MAX_DIFFERENCES).max(1),
            seen: 0,
            values: Vec::with_capacity(expected.min(MAX_DIFFERENCES)),
        }
    }

    fn push(&mut self, value: f64) {
        if self.seen.is_multiple_of(self.stride) {
            self.values.push(value);
        }
        self.seen += 1;
    }
}

/// One channel's scaled differences of second and third order.
struct Differences {
    second: Thinned,
    third: Thinned,
}

impl Differences {
    /// For about `samples` samples.
    fn new(samples: usize) -> Self {
        Self {
            second: Thinned::new(samples),
            third: Thinned::new(samples),
        }
    }

    /// The differences ending at the last of up to four successive samples.
    fn push(&mut self, t: &[f64], v: &[f64]) {
        let n = t.len();
        if n >= 3
            && let Some(e) = scaled_difference(&t[n - 3..], &v[n - 3..])
        {
            self.second.push(e);
        }
        if n >= 4
            && let Some(e) = scaled_difference(&t[n - 4..], &v[n - 4..])
        {
            self.third.push(e);
        }
    }

    fn noise(self) -> Option<SampleNoise> {
        let (sigma, differences) = clipped_rms(self.second.values)?;
        Some(SampleNoise {
            sigma,
            differences,
            third_order_sigma: clipped_rms(self.third.values).map(|(s, _)| s),
        })
    }
}

/// The differences of both coordinates of every marker along its track.
fn marker_differences(campaign: &Campaign) -> Differences {
    let rows: usize = campaign
        .trials
        .iter()
        .filter_map(|t| t.markers.as_ref())
        .map(|m| m.row_count())
        .sum();
    let mut out = Differences::new(2 * rows);
    for track in campaign.trials.iter().filter_map(|t| t.markers.as_ref()) {
        // The last four samples of each marker, by its index: times, x, y.
        let mut last: Vec<[Vec<f64>; 3]> = vec![Default::default(); campaign.markers_rest.len()];
        for frame in track.frames() {
            for (id, [x, y]) in frame.iter() {
                let Some(index) = campaign.markers_rest.index_of(id) else {
                    continue;
                };
                let history = &mut last[index];
                for (series, value) in history.iter_mut().zip([frame.t, x, y]) {
                    if series.len() == 4 {
                        series.remove(0);
                    }
                    series.push(value);
                }
                let [t, x, y] = &*history;
                out.push(t, x);
                out.push(t, y);
            }
        }
    }
    out
}

/// The differences of both force components along every trial's samples.
fn force_differences(campaign: &Campaign) -> Differences {
    let rows: usize = campaign.trials.iter().map(|t| t.tool.len()).sum();
    let mut out = Differences::new(2 * rows);
    for trial in &campaign.trials {
        for k in 0..trial.tool.len() {
            let window = &trial.tool[k.saturating_sub(3)..=k];
            let t: Vec<f64> = window.iter().map(|s| s.t).collect();
            let fx: Vec<f64> = window.iter().map(|s| s.fx).collect();
            let fy: Vec<f64> = window.iter().map(|s| s.fy).collect();
            out.push(&t, &fx);
            out.push(&t, &fy);
        }
    }
    out
}

/// The clipped RMS of `residuals` (see the module doc) and their count;
/// `None` for fewer than [`MIN_DIFFERENCES`] or a zero scale.
fn clipped_rms(mut residuals: Vec<f64>) -> Option<(f64, usize)> {
    residuals.retain(|e| e.is_finite());
    if residuals.len() < MIN_DIFFERENCES {
        return None;
    }
    let mut sigma = (residuals.iter().map(|e| e * e).sum::<f64>() / residuals.len() as f64).sqrt();
    for _ in 0..50 {
        let bound = CLIP_SIGMAS * sigma;
        let (sum2, count) = residuals
            .iter()
            .filter(|e| e.abs() <= bound)
            .fold((0.0, 0usize), |(s, n), e| (s + e * e, n + 1));
        // Guards a degenerate channel (nearly all residuals exactly zero).
        if count == 0 {
            break;
        }
        let next = (sum2 / count as f64).sqrt();
        let settled = (next - sigma).abs() <= 1e-9 * sigma;
        sigma = next;
        if settled {
            break;
        }
    }
    (sigma > 0.0).then_some((sigma, residuals.len()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use needle_data::{MarkerRest, Phantom, ToolSample, Trial, TrialData, TrialKind};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    /// A needle trial whose markers drift smoothly (faster near the needle)
    /// with noise `marker_sigma`, sampled unevenly at about 30 Hz with a
    /// marker occluded in some frames, and whose force ramps up with noise
    /// `force_sigma`, quantised to `resolution`, with a puncture: a 0.3 N
    /// drop.
    fn campaign(marker_sigma: f64, force_sigma: f64, resolution: f64) -> Campaign {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let marker_noise = Normal::new(0.0, marker_sigma).unwrap();
        let force_noise = Normal::new(0.0, force_sigma).unwrap();
        let phantom = Phantom {
            width: 0.075,
            depth: 0.075,
            thickness: 0.0075,
            fixed: vec![needle_data::Face::Back],
        };
        let mut campaign = Campaign::new("noise", phantom);
        let rest: Vec<MarkerRest> = (0..25)
            .map(|i| MarkerRest {
                id: 100 + 3 * i,
                x: 0.015 * (i % 5) as f64,
                y: 0.015 * (i / 5) as f64,
            })
            .collect();
        campaign.markers_rest = needle_data::MarkerSet::new(rest.clone());
        let mut trial = TrialData::new(Trial {
            id: "needle".into(),
            kind: TrialKind::Needle,
            velocity: 0.005,
            day: 0.0,
        });
        let quantise = |f: f64| (f / resolution).round() * resolution;
        for k in 0..1000 {
            let t = 0.01 * k as f64;
            let drop = if t > 6.0 { 0.3 } else { 0.0 };
            trial.tool.push(ToolSample {
                t,
                tip_x: 0.03,
                tip_y: 0.005 * t,
                theta: 0.0,
                fx: quantise(force_noise.sample(&mut rng)),
                fy: quantise(0.08 * t - drop + force_noise.sample(&mut rng)),
                mz: 0.0,
            });
        }
        let track = trial.markers_mut();
        for frame in 0..300u64 {
            let t = frame as f64 / 30.0 + 0.004 * ((frame * 7) % 5) as f64;
            let markers: Vec<(u32, [f64; 2])> = rest
                .iter()
                .filter(|m| !(m.id == 106 && frame % 4 == 1))
                .map(|m| {
                    let pull = 2.0e-3 / (1.0 + 100.0 * (m.x - 0.03).abs());
                    let drift = pull * (1.0 - (-t / 4.0).exp());
                    (
                        m.id,
                        [
                            m.x + marker_noise.sample(&mut rng),
                            m.y + drift + marker_noise.sample(&mut rng),
                        ],
                    )
                })
                .collect();
            track.push_frame(frame, t, markers).unwrap();
        }
        campaign.trials.push(trial);
        campaign
    }

    #[test]
    fn recovers_the_noise_of_smooth_signals_through_gaps_events_and_quantisation() {
        let resolution = 0.0125;
        let force_sigma = 0.005;
        let estimate = noise_from_repeated_samples(&campaign(8.0e-6, force_sigma, resolution));
        let marker = estimate.marker.unwrap();
        // 25 markers x 300 frames, 2 per frame missing for one marker.
        assert_eq!(marker.differences, 2 * (25 * 298 - 75));
        assert!((marker.sigma / 8.0e-6 - 1.0).abs() < 0.03, "{marker:?}");
        assert!(marker.consistent(), "{marker:?}");
        // The quantised sensor's noise: Gaussian plus the rounding's
        // uniform error.
        let effective = (force_sigma.powi(2) + resolution.powi(2) / 12.0).sqrt();
        let force = estimate.force.unwrap();
        assert_eq!(force.differences, 2 * 998);
        assert!((force.sigma / effective - 1.0).abs() < 0.06, "{force:?}");
        assert!(force.consistent(), "{force:?}");
    }

    #[test]
    fn a_sparse_channel_has_no_estimate() {
        let mut campaign = campaign(8.0e-6, 0.005, 0.0125);
        campaign.trials[0].tool.truncate(26);
        campaign.trials[0].markers = None;
        let estimate = noise_from_repeated_samples(&campaign);
        assert_eq!(estimate.marker, None);
        // 24 triples of two components: fewer than the least.
        assert_eq!(estimate.force, None);
        campaign.trials[0].tool = campaign.trials[0].tool.repeat(2);
        // Time going back between the copies spoils two triples.
        assert_eq!(
            noise_from_repeated_samples(&campaign)
                .force
                .unwrap()
                .differences,
            2 * 48
        );
    }

    #[test]
    fn differences_are_scaled_to_the_noise_and_blind_to_low_order_signal() {
        // Even spacing: the second difference over sqrt(6), the third over
        // sqrt(20), up to sign.
        let e = scaled_difference(&[0.0, 1.0, 2.0], &[0.0, 1.0, 0.0]).unwrap();
        assert!((e.abs() - 2.0 / 6f64.sqrt()).abs() < 1e-15);
        let e = scaled_difference(&[0.0, 1.0, 2.0, 3.0], &[0.0, 0.0, 0.0, 1.0]).unwrap();
        assert!((e.abs() - 1.0 / 20f64.sqrt()).abs() < 1e-15);
        assert_eq!(scaled_difference(&[0.0, 1.0, 1.0], &[0.0, 1.0, 0.0]), None);
        // Uneven times: the second order leaves nothing of a line, the
        // third nothing of a parabola.
        let t = [0.0, 0.3, 1.1, 1.25];
        let line: Vec<f64> = t.iter().map(|t| 3.0 - 2.0 * t).collect();
        assert!(scaled_difference(&t[..3], &line[..3]).unwrap().abs() < 1e-14);
        let parabola: Vec<f64> = t.iter().map(|t| 3.0 - 2.0 * t + 5.0 * t * t).collect();
        assert!(scaled_difference(&t, &parabola).unwrap().abs() < 1e-12);
        assert!(scaled_difference(&t[..3], &parabola[..3]).unwrap().abs() > 0.1);
    }

    #[test]
    fn each_channel_takes_the_lesser_estimate_when_the_orders_agree() {
        let sample = |sigma| SampleNoise {
            sigma,
            differences: 1000,
            third_order_sigma: Some(1.05 * sigma),
        };
        let marker = ChannelNoise::choose(Some(1.0), Some(sample(0.8)), 7.0);
        assert_eq!(marker.basis, NoiseBasis::RepeatedSamples(sample(0.8)));
        assert_eq!(marker.sigma, 0.8);
        let force = ChannelNoise::choose(Some(0.01), Some(sample(0.02)), 7.0);
        assert_eq!(
            force.basis,
            NoiseBasis::Fit {
                repeated_samples: Some(sample(0.02))
            }
        );
        assert_eq!(force.sigma, 0.01);
        let source = NoiseSource::Estimated { marker, force };
        assert!(!source.per_sample());

        let none = ChannelNoise::choose(None, None, 7.0);
        assert_eq!(none.basis, NoiseBasis::NoResiduals);
        assert_eq!(none.sigma, 7.0);
        let source = NoiseSource::Estimated {
            marker,
            force: none,
        };
        assert!(source.per_sample());

        // Orders that disagree: signal between samples.
        let spoilt = SampleNoise {
            third_order_sigma: Some(0.6),
            ..sample(0.8)
        };
        let marker = ChannelNoise::choose(Some(1.0), Some(spoilt), 7.0);
        assert_eq!(
            marker.basis,
            NoiseBasis::Fit {
                repeated_samples: Some(spoilt)
            }
        );
        assert_eq!(marker.sigma, 1.0);
    }

    #[test]
    fn marker_noise_from_a_fit_gives_unit_chi_square_with_the_probe_noise() {
        // 40 marker coordinates and 3 forces; one probe frame over the
        // first 20 coordinates.
        let residuals: Vec<f64> = (0..43)
            .map(|k| 1e-5 * ((k as f64 * 0.7).sin() + 0.3))
            .collect();
        let dof = 36.0;
        let plain = (residuals[..40].iter().map(|r| r * r).sum::<f64>() / dof).sqrt();
        let without = marker_sigma_from_fit(&residuals, 40, dof, &[], &[]).unwrap();
        assert!((without / plain - 1.0).abs() < 1e-12);

        let response = ProbeResponse {
            start: 0,
            unit_x: (0..20).map(|k| 1e-4 * (k % 2) as f64).collect(),
            unit_y: (0..20).map(|k| 1e-4 * ((k + 1) % 2) as f64).collect(),
            force_sigma: 0.05,
        };
        let responses = [response];
        let sigma = marker_sigma_from_fit(&residuals, 40, dof, &[], &responses).unwrap();
        assert!(sigma < 0.99 * plain, "{sigma} {plain}");
        let whitened =
            Whitening::with_probe_noise(40, sigma, &[], 0.005, &responses).apply(&residuals);
        let chi2: f64 = whitened[..40].iter().map(|w| w * w).sum();
        assert!((chi2 / dof - 1.0).abs() < 1e-9, "{chi2}");
        assert_eq!(marker_sigma_from_fit(&[0.0; 43], 40, dof, &[], &[]), None);
    }
}
