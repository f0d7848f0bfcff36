//! Subpixel marker tracking: integer search by zero-mean normalised
//! cross-correlation (ZNCC), then inverse-compositional Gauss-Newton (IC-GN)
//! on the zero-mean normalised sum of squared differences.
//!
//! A template $f$ is sampled on the integer nodes $x_i \in [-h, h]^2$ around
//! its centre pixel; the marker sits at `offset` from that centre. In a new
//! frame $g$ the tracker finds the shift $s$ (the image position of the
//! template's centre node) minimising
//! $C(s) = \sum_i \big(\tilde f_i/\Delta f - \tilde g(x_i + s)/\Delta g\big)^2$,
//! where a tilde means "minus the mean over the nodes" and $\Delta$ is the
//! root sum of squares of the tilde values, so that $C$ is blind to the
//! gain and offset of the illumination and $\mathrm{ZNCC} = 1 - C/2$.
//! Each IC-GN step linearises the template instead of the frame,
//! $\tilde f(x_i + \delta) \approx \tilde f_i + \nabla f_i \cdot \delta$, so the
//! Hessian $H = \sum_i \nabla f_i \nabla f_i^{\mathsf T}$ is computed once:
//! $\delta = H^{-1} \sum_i \nabla f_i \big(\tfrac{\Delta f}{\Delta g}\tilde g(x_i + s) - \tilde f_i\big)$,
//! $s \leftarrow s - \delta$. The frame is interpolated with a cubic B-spline
//! ([`crate::interpolate`]); since every node shares one fractional offset,
//! each step costs one separable 4-tap filter pass, fused with the sums in
//! single precision ([`crate::shift_sampler`]).
//!
//! The marker is reported at $s + $ `offset`, with its ZNCC, the residual
//! and the standard deviation $\hat\sigma \sqrt{(H^{-1})_{kk}}$, where
//! $\hat\sigma^2$ is the residual variance in template grey levels.
//! A marker that leaves the frame, sits in a flat patch, correlates badly or
//! does not converge is reported lost with the reason, never at a guessed
//! position.

use nalgebra::{Matrix2, Vector2, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use wide::f32x4;

use crate::interpolate::SplinePatch;
use crate::shift_sampler::ShiftSampler;
use crate::{GreyFrame, RenderOptions, VisionError, pixel_space_view, render_ideal};

/// Rows and columns of frame around a spline patch that absorb the
/// prefilter's boundary transient: 0.27^4 = 0.5 % of the mismatch between
/// the mirrored and the true continuation at the edge, where a marker's
/// patch holds flat background (noise of a few grey levels), so some 0.01
/// grey levels reach nodes whose gradient is near zero. The precision and
/// bias tests read the same to three digits as with a margin of 6.
const SPLINE_MARGIN: usize = 4;
/// Largest drift (px) of IC-GN from its start that the spline patch covers.
const MAX_DRIFT: usize = 2;

/// When the integer ZNCC search runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum SearchPolicy {
    /// Before every refinement.
    Always,
    /// Only when IC-GN from the prediction fails (does not converge, ends
    /// with a low ZNCC or drifts away); the usual frame-to-frame case needs
    /// none.
    WhenNeeded,
}

/// Tracking options.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrackOptions {
    /// Integer search radius around the prediction (px).
    pub search_radius: usize,
    /// When to search.
    pub search: SearchPolicy,
    /// Smallest ZNCC of a tracked marker.
    pub min_zncc: f64,
    /// Smallest grey-level standard deviation in the marker window.
    pub min_contrast: f64,
    /// IC-GN iteration limit.
    pub max_iterations: usize,
    /// IC-GN stops once the distance left to the answer, estimated from the
    /// last two steps (or the last step alone), is shorter than this (px).
    pub tolerance: f64,
}

impl Default for TrackOptions {
    fn default() -> TrackOptions {
        TrackOptions {
            search_radius: 6,
            search: SearchPolicy::WhenNeeded,
            min_zncc: 0.9,
            min_contrast: 5.0,
            max_iterations: 30,
            tolerance: 1e-4,
        }
    }
}

/// A marker template with its precomputed IC-GN quantities.
///
/// The IC-GN quantities are stored column by column (`[i * side + j]` for
/// the node $(i - h, j - h)$), the order in which the frame sampler
/// (`shift_sampler.rs`) produces the warped frame, and rounded to `f32`;
/// every sum derived from them is taken from the rounded values, so that
/// the normal equations stay consistent.
#[derive(Debug, Clone)]
pub struct MarkerTemplate {
    half: usize,
    offset: Vector2<f64>,
    /// Zero-mean grey levels, row-major, for the integer search.
    zero_mean_rows: Vec<f32>,
    /// Zero-mean grey levels and gradient, column-major, for IC-GN.
    zero_mean_columns: Vec<f32>,
    gradient_x: Vec<f32>,
    gradient_y: Vec<f32>,
    norm: f64,
    /// $\sum_i \nabla f_i$ and $\sum_i \nabla f_i \tilde f_i$, which let one
    /// fused pass over the frame give every IC-GN sum.
    gradient_sum: Vector2<f64>,
    gradient_template_sum: Vector2<f64>,
    hessian_inverse: Matrix2<f64>,
}

/// Why a marker was not tracked.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum LostReason {
    /// The window around the prediction leaves the frame.
    OutOfFrame,
    /// The window's grey levels are too flat (dark, saturated or washed out).
    LowContrast,
    /// The best match correlates less than `min_zncc` (occluded, damaged).
    LowCorrelation,
    /// IC-GN did not converge or drifted out of its patch.
    NotConverged,
}

/// The result of tracking one marker in one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackOutcome {
    /// The marker's image position (px), or why it was lost.
    pub position: Result<Vector2<f64>, LostReason>,
    /// ZNCC at the final position (or the best found before losing it).
    pub zncc: f64,
    /// Root-mean-square residual in template grey levels.
    pub residual_rms: f64,
    /// Estimated standard deviation of the position (px), per coordinate.
    pub standard_deviation: Vector2<f64>,
    /// IC-GN iterations used.
    pub iterations: usize,
    /// Whether the integer search ran.
    pub searched: bool,
}

impl MarkerTemplate {
    /// Template half-width $h$: the template is $(2h+1)^2$ pixels.
    pub fn half_width(&self) -> usize {
        self.half
    }

    /// Cut a template from a frame around a marker at `position` (px).
    pub fn from_frame(
        frame: &GreyFrame,
        position: Vector2<f64>,
        half: usize,
    ) -> Result<MarkerTemplate, VisionError> {
        let centre = position.map(f64::round);
        let reach = (half + SPLINE_MARGIN) as f64;
        if !(centre.x - reach >= 0.0
            && centre.y - reach >= 0.0
            && centre.x + reach <= frame.width as f64 - 1.0
            && centre.y + reach <= frame.height as f64 - 1.0)
        {
            return Err(VisionError::InvalidParameter {
                field: "template position",
                reason: format!(
                    "a {}-px template at {position:?} does not fit in the {} x {} frame",
                    2 * half + 1,
                    frame.width,
                    frame.height
                ),
            });
        }
        let size = 2 * (half + SPLINE_MARGIN) + 1;
        let (c0, r0) = ((centre.x - reach) as usize, (centre.y - reach) as usize);
        let mut samples = Vec::with_capacity(size * size);
        for r in 0..size {
            samples.extend(
                frame.pixels[(r0 + r) * frame.width + c0..][..size]
                    .iter()
                    .map(|&p| p as f64),
            );
        }
        MarkerTemplate::from_samples(samples, size, half, position - centre)
    }

    /// A noise-free rendered dot of `diameter` px, blurred by `blur_sigma`
    /// px, at the template centre.
    pub fn synthetic(
        diameter: f64,
        blur_sigma: f64,
        background: f64,
        contrast: f64,
        half: usize,
    ) -> Result<MarkerTemplate, VisionError> {
        let size = 2 * (half + SPLINE_MARGIN) + 1;
        let (camera, pose) = pixel_space_view();
        let centre = (half + SPLINE_MARGIN) as f64;
        let options = RenderOptions {
            width: size,
            height: size,
            dot_diameter: diameter,
            background,
            contrast,
            blur_sigma,
            illumination_gradient: [0.0; 2],
            read_noise_sigma: 0.0,
            electrons_per_grey: None,
            bit_depth: crate::BitDepth::Sixteen,
        };
        let frame = render_ideal(
            &camera,
            &pose,
            &[Vector3::new(centre, centre, 0.0)],
            &options,
        )?;
        let samples = frame.pixels.iter().map(|&p| p as f64).collect();
        MarkerTemplate::from_samples(samples, size, half, Vector2::zeros())
    }

    fn from_samples(
        samples: Vec<f64>,
        size: usize,
        half: usize,
        offset: Vector2<f64>,
    ) -> Result<MarkerTemplate, VisionError> {
        let spline = SplinePatch::new(samples.clone(), size, size);
        let side = 2 * half + 1;
        let value = |i: usize, j: usize| samples[(j + SPLINE_MARGIN) * size + i + SPLINE_MARGIN];
        let mean = (0..side)
            .flat_map(|j| (0..side).map(move |i| (i, j)))
            .map(|(i, j)| value(i, j))
            .sum::<f64>()
            / (side * side) as f64;
        let zero_mean_rows: Vec<f32> = (0..side)
            .flat_map(|j| (0..side).map(move |i| (i, j)))
            .map(|(i, j)| (value(i, j) - mean) as f32)
            .collect();
        let mut zero_mean_columns = Vec::with_capacity(side * side);
        let mut gradient_x = Vec::with_capacity(side * side);
        let mut gradient_y = Vec::with_capacity(side * side);
        for i in 0..side {
            for j in 0..side {
                let (x, y) = ((i + SPLINE_MARGIN) as f64, (j + SPLINE_MARGIN) as f64);
                let (_, gx, gy) = spline.sample_with_gradient(x, y);
                zero_mean_columns.push((value(i, j) - mean) as f32);
                gradient_x.push(gx as f32);
                gradient_y.push(gy as f32);
            }
        }
        let wide = |v: &[f32]| v.iter().map(|&x| x as f64).collect::<Vec<f64>>();
        let (f, gx, gy) = (
            wide(&zero_mean_columns),
            wide(&gradient_x),
            wide(&gradient_y),
        );
        let norm = f.iter().map(|v| v * v).sum::<f64>().sqrt();
        let mut hessian = Matrix2::zeros();
        for (gx, gy) in gx.iter().zip(&gy) {
            hessian += Matrix2::new(gx * gx, gx * gy, gx * gy, gy * gy);
        }
        let hessian_inverse = hessian
            .try_inverse()
            .filter(|_| norm > 0.0)
            .ok_or_else(|| VisionError::InvalidParameter {
                field: "template",
                reason: "the template is flat: no gradient to track".into(),
            })?;
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(a, b)| a * b).sum::<f64>();
        let gradient_sum = Vector2::new(gx.iter().sum(), gy.iter().sum());
        let gradient_template_sum = Vector2::new(dot(&gx, &f), dot(&gy, &f));
        Ok(MarkerTemplate {
            half,
            offset,
            zero_mean_rows,
            zero_mean_columns,
            gradient_x,
            gradient_y,
            norm,
            gradient_sum,
            gradient_template_sum,
            hessian_inverse,
        })
    }

    /// Fisher information $\sum_i \nabla f_i \nabla f_i^{\mathsf T}$ of the
    /// template per unit noise variance (the Cramer-Rao bound of a shift is
    /// $\sigma^2$ times its inverse).
    pub fn fisher_information(&self) -> Matrix2<f64> {
        self.hessian_inverse
            .try_inverse()
            .unwrap_or_else(Matrix2::zeros)
    }
}

/// ZNCC of the template with its centre at integer pixel `(cx, cy)` and the
/// window's grey-level standard deviation; `None` if the window leaves the
/// frame.
fn zncc_at(frame: &GreyFrame, template: &MarkerTemplate, cx: i64, cy: i64) -> Option<(f64, f64)> {
    let h = template.half as i64;
    let side = 2 * template.half + 1;
    let count = (side * side) as f64;
    if cx - h < 0 || cy - h < 0 || cx + h >= frame.width as i64 || cy + h >= frame.height as i64 {
        return None;
    }
    let (mut cross, mut sum, mut sum_sq) = (0.0f64, 0.0f64, 0.0f64);
    for j in 0..side {
        let row = &frame.pixels
            [(cy - h) as usize * frame.width + j * frame.width + (cx - h) as usize..][..side];
        let t = &template.zero_mean_rows[j * side..][..side];
        // Explicit vectors: the compiler's own vectorisation of lane arrays
        // shuffles more than it adds.
        let (mut c, mut s, mut q) = (f32x4::ZERO, f32x4::ZERO, f32x4::ZERO);
        let (row_chunks, t_chunks) = (row.chunks_exact(4), t.chunks_exact(4));
        let (row_tail, t_tail) = (row_chunks.remainder(), t_chunks.remainder());
        for (g, f) in row_chunks.zip(t_chunks) {
            let g = f32x4::new(g.try_into().unwrap());
            c += g * f32x4::new(f.try_into().unwrap());
            s += g;
            q += g * g;
        }
        let (mut c, mut s, mut q) = (c.reduce_add(), s.reduce_add(), q.reduce_add());
        for (g, f) in row_tail.iter().zip(t_tail) {
            c += g * f;
            s += g;
            q += g * g;
        }
        cross += c as f64;
        sum += s as f64;
        sum_sq += q as f64;
    }
    let spread = (sum_sq - sum * sum / count).max(0.0).sqrt();
    let zncc = if spread > 0.0 {
        cross / (template.norm * spread)
    } else {
        0.0
    };
    Some((zncc, spread / count.sqrt()))
}

/// Integer ZNCC search for the template centre near `predicted` (a template
/// centre position): every second pixel of the window, then the eight
/// neighbours of the best (the correlation peak of a dot is several pixels
/// wide, so the coarse grid cannot step over it). Returns the best integer
/// centre, its ZNCC and the largest grey-level standard deviation of the
/// windows visited, or `None` if no candidate window lies in the frame.
fn integer_search(
    frame: &GreyFrame,
    template: &MarkerTemplate,
    predicted: Vector2<f64>,
    radius: usize,
) -> Option<(Vector2<f64>, f64, f64)> {
    let (pc, pr) = (predicted.x.round() as i64, predicted.y.round() as i64);
    let r = radius as i64;
    let mut best: Option<((i64, i64), f64)> = None;
    let mut contrast: f64 = 0.0;
    let mut visit = |cx: i64, cy: i64, best: &mut Option<((i64, i64), f64)>| {
        if let Some((zncc, spread)) = zncc_at(frame, template, cx, cy) {
            contrast = contrast.max(spread);
            if best.is_none_or(|(_, b)| zncc > b) {
                *best = Some(((cx, cy), zncc));
            }
        }
    };
    for dy in (-r..=r).step_by(2) {
        for dx in (-r..=r).step_by(2) {
            visit(pc + dx, pr + dy, &mut best);
        }
    }
    if let Some(((bx, by), _)) = best {
        for (dx, dy) in [
            (-1, -1),
            (0, -1),
            (1, -1),
            (-1, 0),
            (1, 0),
            (-1, 1),
            (0, 1),
            (1, 1),
        ] {
            visit(bx + dx, by + dy, &mut best);
        }
    }
    best.map(|((cx, cy), zncc)| (Vector2::new(cx as f64, cy as f64), zncc, contrast))
}

struct Refinement {
    centre: Vector2<f64>,
    zncc: f64,
    residual_rms: f64,
    standard_deviation: Vector2<f64>,
    iterations: usize,
    converged: bool,
    contrast: f64,
}

/// Estimated distance (px) from the position after a step of `length` to
/// the fixed point, given the previous step's `previous_length`.
///
/// IC-GN on a fixed template converges linearly near the answer: each step
/// is about $\rho$ times the one before, so the steps still to come add up
/// to $\rho\,|\delta_k| / (1 - \rho)$ with $\rho = |\delta_k| / |\delta_{k-1}|$.
/// Here $\rho$ is about 0.02, so this ends the iteration one evaluation
/// before a plain $|\delta_k| <$ tolerance rule would. When the steps do
/// not shrink fast (first step, $\rho > 1/2$) the estimate falls back to
/// the step itself.
fn remaining_distance(length: f64, previous_length: f64) -> f64 {
    let ratio = length / previous_length;
    if previous_length.is_finite() && ratio <= 0.5 {
        length * ratio / (1.0 - ratio)
    } else {
        length
    }
}

/// IC-GN from the template centre `start`; `None` if the patch it needs
/// leaves the frame.
fn refine(
    frame: &GreyFrame,
    template: &MarkerTemplate,
    start: Vector2<f64>,
    options: &TrackOptions,
    sampler: &mut ShiftSampler,
) -> Option<Refinement> {
    let h = template.half;
    let side = 2 * h + 1;
    let count = (side * side) as f64;
    let reach = (h + MAX_DRIFT + SPLINE_MARGIN + 1) as f64;
    let origin = (start.map(f64::floor) - Vector2::repeat(reach)).map(|v| v as i64);
    let size = 2 * reach as usize + 2;
    if origin.x < 0
        || origin.y < 0
        || origin.x as usize + size > frame.width
        || origin.y as usize + size > frame.height
    {
        return None;
    }
    let (c0, r0) = (origin.x as usize, origin.y as usize);
    sampler.load(frame, c0, r0, size);
    let origin_f = Vector2::new(c0 as f64, r0 as f64);
    let low = (SPLINE_MARGIN + 1) as f64 + h as f64;
    let high = (size - SPLINE_MARGIN - 3) as f64 - h as f64;
    let mut centre = start;
    let mut result = Refinement {
        centre,
        zncc: f64::NEG_INFINITY,
        residual_rms: f64::INFINITY,
        standard_deviation: Vector2::repeat(f64::INFINITY),
        iterations: 0,
        converged: false,
        contrast: 0.0,
    };
    let mut previous_length = f64::INFINITY;
    for iteration in 0..=options.max_iterations {
        let local = centre - origin_f;
        if !(local.x >= low && local.y >= low && local.x < high && local.y < high) {
            return Some(result);
        }
        // sum g, sum g^2, sum grad_x g, sum grad_y g, sum f g over the nodes.
        let sums = sampler.grid_sums(
            (local.x - h as f64, local.y - h as f64),
            side,
            [
                &template.gradient_x,
                &template.gradient_y,
                &template.zero_mean_columns,
            ],
        );
        let [
            frame_sum,
            frame_squared,
            gradient_x_frame,
            gradient_y_frame,
            template_frame,
        ] = sums;
        let mean = frame_sum / count;
        let norm = (frame_squared - frame_sum * mean).max(0.0).sqrt();
        result.contrast = norm / count.sqrt();
        if norm == 0.0 {
            return Some(result);
        }
        // With d_i = scale (g_i - mean) - f_i: sum grad_i d_i and sum d_i^2
        // from the fused sums.
        let scale = template.norm / norm;
        let b = scale
            * (Vector2::new(gradient_x_frame, gradient_y_frame) - mean * template.gradient_sum)
            - template.gradient_template_sum;
        // sum d_i^2 = 2 (|f|^2 - scale sum f_i g_i), as sum f_i = 0.
        let ssd = (2.0 * (template.norm * template.norm - scale * template_frame)).max(0.0);
        result.centre = centre;
        result.iterations = iteration;
        result.zncc = 1.0 - 0.5 * ssd / (template.norm * template.norm);
        result.residual_rms = (ssd / count).sqrt();
        // Residual variance per node in template grey levels, four fitted
        // parameters (shift, gain, offset).
        let variance = ssd / (count - 4.0);
        result.standard_deviation = Vector2::new(
            (variance * template.hessian_inverse[(0, 0)]).sqrt(),
            (variance * template.hessian_inverse[(1, 1)]).sqrt(),
        );
        if iteration == options.max_iterations {
            return Some(result);
        }
        let step = template.hessian_inverse * b;
        centre -= step;
        let length = step.norm();
        if remaining_distance(length, previous_length) < options.tolerance {
            // The quality just computed, a step shorter than the tolerance
            // away, stands for the final position's.
            result.centre = centre;
            result.converged = true;
            return Some(result);
        }
        previous_length = length;
    }
    Some(result)
}

/// Track one marker: `predicted` is its expected image position (px).
pub fn track_marker(
    frame: &GreyFrame,
    template: &MarkerTemplate,
    predicted: Vector2<f64>,
    options: &TrackOptions,
) -> TrackOutcome {
    track_marker_with(
        frame,
        template,
        predicted,
        options,
        &mut ShiftSampler::default(),
    )
}

/// [`track_marker`] with the caller's sampler buffers.
fn track_marker_with(
    frame: &GreyFrame,
    template: &MarkerTemplate,
    predicted: Vector2<f64>,
    options: &TrackOptions,
    sampler: &mut ShiftSampler,
) -> TrackOutcome {
    let lost = |reason, zncc, searched| TrackOutcome {
        position: Err(reason),
        zncc,
        residual_rms: f64::NAN,
        standard_deviation: Vector2::repeat(f64::NAN),
        iterations: 0,
        searched,
    };
    let predicted_centre = predicted - template.offset;
    let accept = |r: &Refinement, searched: bool| -> Option<TrackOutcome> {
        let drift = (r.centre - predicted_centre).abs().max();
        (r.converged
            && r.zncc >= options.min_zncc
            && r.contrast >= options.min_contrast
            && drift <= options.search_radius as f64 + 0.5)
            .then(|| TrackOutcome {
                position: Ok(r.centre + template.offset),
                zncc: r.zncc,
                residual_rms: r.residual_rms,
                standard_deviation: r.standard_deviation,
                iterations: r.iterations,
                searched,
            })
    };
    if options.search == SearchPolicy::WhenNeeded
        && let Some(refined) = refine(frame, template, predicted_centre, options, sampler)
        && let Some(outcome) = accept(&refined, false)
    {
        return outcome;
    }
    let Some((integer_centre, zncc, contrast)) =
        integer_search(frame, template, predicted_centre, options.search_radius)
    else {
        return lost(LostReason::OutOfFrame, f64::NAN, true);
    };
    if contrast < options.min_contrast {
        return lost(LostReason::LowContrast, zncc, true);
    }
    // The integer peak of a true match is within half a pixel of it, where
    // the ZNCC of a blurred dot drops by about 0.02: a peak below the
    // threshold is no match, whatever refinement would do.
    if zncc < options.min_zncc {
        return lost(LostReason::LowCorrelation, zncc, true);
    }
    let Some(refined) = refine(frame, template, integer_centre, options, sampler) else {
        return lost(LostReason::OutOfFrame, zncc, true);
    };
    if let Some(outcome) = accept(&refined, true) {
        return outcome;
    }
    let reason = if refined.contrast < options.min_contrast {
        LostReason::LowContrast
    } else if refined.converged && refined.zncc < options.min_zncc {
        LostReason::LowCorrelation
    } else {
        LostReason::NotConverged
    };
    lost(reason, refined.zncc.max(zncc), true)
}

/// Track every marker in one frame, in parallel; `templates[i]` is tracked
/// near `predictions[i]`.
pub fn track_markers(
    frame: &GreyFrame,
    templates: &[MarkerTemplate],
    predictions: &[Vector2<f64>],
    options: &TrackOptions,
) -> Result<Vec<TrackOutcome>, VisionError> {
    if templates.len() != predictions.len() {
        return Err(VisionError::InvalidParameter {
            field: "predictions",
            reason: format!(
                "{} predictions for {} templates",
                predictions.len(),
                templates.len()
            ),
        });
    }
    Ok(templates
        .par_iter()
        .zip(predictions.par_iter())
        // One set of sampler buffers per rayon job, reused across its markers.
        .map_init(ShiftSampler::default, |sampler, (template, predicted)| {
            track_marker_with(frame, template, *predicted, options, sampler)
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_remaining_distance_of_geometric_steps_is_the_rest_of_the_series() {
        let (first, ratio) = (0.3, 0.02);
        let step = |k: i32| first * f64::powi(ratio, k);
        for k in 1..5 {
            let rest: f64 = (k + 1..60).map(step).sum();
            let estimate = remaining_distance(step(k), step(k - 1));
            assert!(
                (estimate - rest).abs() < 1e-12 * rest,
                "{estimate} vs {rest}"
            );
        }
        // No history, or steps that do not shrink fast: the step itself.
        assert_eq!(remaining_distance(0.01, f64::INFINITY), 0.01);
        assert_eq!(remaining_distance(0.01, 0.015), 0.01);
    }
}
