//! The diagnosis loop: fit, rank the missing effects, give a verdict, and
//! on request add the recommended effect and go again (the error ladder).

use std::path::Path;

use needle_data::{Campaign, read_bundle};
use serde::{Deserialize, Serialize};

use crate::discretisation::{CHECK_FACTOR, DiscretisationCheck, check_discretisation};
use crate::error::DiagnoseError;
use crate::fit::{Context, Fit, Fitted, Precision, fit_model};
use crate::forward::{Forward, Start};
use crate::model::{Baseline, Model, POISSON_RATIO};
use crate::noise::{
    ChannelNoise, NoiseBasis, NoiseSource, RepeatedSampleNoise, marker_sigma_from_fit,
    noise_from_repeated_samples,
};
use crate::observe::{Load, Observations};
use crate::rank::{Candidate, Ranked, rank_candidates};
use crate::spec::{DiagnoseOptions, ModelSpec};
use crate::whiten::{ProbeResponse, Whitening};

/// What the residuals say.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub enum Verdict {
    /// This catalog effect explains a significant part of the residual.
    MissingEffect(String),
    /// Every channel's chi-square per dof is consistent with 1 and no
    /// candidate is significant.
    ConsistentWithNoise,
    /// Some channel misfits beyond the noise, yet no catalog effect
    /// explains it significantly.
    Unexplained,
}

/// The machine-readable summary, `diagnosis.ron`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Diagnosis {
    /// Bundle name.
    pub bundle: String,
    /// Effects in the model that was fitted.
    pub model: Vec<String>,
    /// The verdict.
    pub verdict: Verdict,
    /// Misfit of the fitted model.
    pub fit: Fit,
    /// Every catalog effect not in the model, best first.
    pub candidates: Vec<Candidate>,
    /// Where the noise levels came from.
    pub noise: NoiseSource,
    /// The p-value below which a candidate counts (significance / candidates).
    pub threshold_p: f64,
    /// Fitted constants outside the range physical for a soft phantom,
    /// with what that usually means.
    #[serde(default)]
    pub warnings: Vec<String>,
    /// Why the effect this step names may not be physics: its likelihood
    /// ratio is within what the model's own mesh could explain (see
    /// [`DiscretisationCheck::doubt`]).
    #[serde(default)]
    pub doubt: Option<String>,
    /// How far the model's own plane mesh moves the first fit's
    /// predictions (the same at every step; see [`DiscretisationCheck`]).
    #[serde(default)]
    pub discretisation: Option<DiscretisationCheck>,
}

/// One fitted parameter with its 95 % Wald interval (absent when it has no
/// standard error: on a bound or unidentifiable).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FittedParameter {
    /// Name.
    pub name: String,
    /// Fitted value.
    pub value: f64,
    /// Standard error.
    pub standard_error: Option<f64>,
    /// 95 % interval.
    pub interval: Option<(f64, f64)>,
    /// What it means.
    pub meaning: String,
}

/// The fitted model, written as `model.ron`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FittedModel {
    /// Bundle name.
    pub bundle: String,
    /// Effects of the model.
    pub model: Vec<String>,
    /// Its parameters.
    pub parameters: Vec<FittedParameter>,
    /// Its misfit.
    pub fit: Fit,
}

/// One row of the error ladder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LadderRow {
    /// Step number, 0 for the model given.
    pub step: usize,
    /// Effect added at this step (none at step 0).
    pub added: Option<String>,
    /// Effects in the model.
    pub model: Vec<String>,
    /// Number of parameters.
    pub parameters: usize,
    /// Misfit.
    pub fit: Fit,
    /// Verdict at this step.
    pub verdict: Verdict,
}

/// The error ladder: the misfit of the model given, then after each effect added.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Ladder {
    /// One row per step.
    pub rows: Vec<LadderRow>,
}

/// A marker residual with everything it can be plotted against.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MarkerResidual {
    /// Trial index in the bundle's order of non-compression trials.
    pub trial: usize,
    /// Frame time (s).
    pub t: f64,
    /// Marker index in `markers_rest.csv` order.
    pub marker: usize,
    /// Rest position (m).
    pub x: f64,
    /// Rest position (m).
    pub y: f64,
    /// Model minus data, x (m).
    pub rx: f64,
    /// Model minus data, y (m).
    pub ry: f64,
    /// Trial velocity (m/s).
    pub velocity: f64,
    /// Trial day.
    pub day: f64,
    /// Inserted length of a needle, 0 otherwise (m).
    pub tip_depth: f64,
    /// Distance from the needle shaft or the probe tip (m).
    pub distance_from_tool: f64,
    /// Distance from the image centre (m).
    pub radius: f64,
}

/// A needle force residual.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ForceResidual {
    /// Trial index.
    pub trial: usize,
    /// Sample time (s).
    pub t: f64,
    /// Inserted length (m).
    pub tip_depth: f64,
    /// Trial velocity (m/s).
    pub velocity: f64,
    /// Trial day.
    pub day: f64,
    /// Model minus data (N).
    pub rx: f64,
    /// Model minus data (N).
    pub ry: f64,
}

/// The misfit of one trial under the final model: which trials the model
/// fails, before looking at where in them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrialMisfit {
    /// Trial id.
    pub trial: String,
    /// Marker coordinates of the trial in the fit.
    pub marker_values: usize,
    /// RMS marker residual (m); `NaN` without markers.
    pub rms_marker: f64,
    /// Mean square of the whitened marker residuals: about 1 when the
    /// trial misfits only by the noise (the fitted parameters are shared
    /// by all trials, so no dof are charged to one); `NaN` without markers.
    pub chi2_marker: f64,
    /// Force components of the trial in the fit.
    pub force_values: usize,
    /// RMS force residual (N); `NaN` without forces.
    pub rms_force: f64,
    /// Mean square of the whitened force residuals; `NaN` without forces.
    pub chi2_force: f64,
    /// Marker positions of probe frames left out as too near the contact
    /// (see [`DiagnoseOptions::probe_near_field`]).
    pub near_field_left_out: usize,
}

/// Everything a diagnosis produced.
#[derive(Debug, Clone)]
pub struct DiagnosisRun {
    /// Summary of the final model (the model given, or the last one of the ladder).
    pub diagnosis: Diagnosis,
    /// Summaries of every step.
    pub steps: Vec<Diagnosis>,
    /// The error ladder.
    pub ladder: Ladder,
    /// The final fitted model.
    pub fitted: FittedModel,
    /// Marker residuals of the final model.
    pub marker_residuals: Vec<MarkerResidual>,
    /// Force residuals of the final model.
    pub force_residuals: Vec<ForceResidual>,
    /// Trial ids, indexed by the residuals' `trial`.
    pub trial_ids: Vec<String>,
    /// The misfit of every trial under the final model, in `trial_ids` order.
    pub trials: Vec<TrialMisfit>,
}

/// Diagnoses `model` on the bundle at `bundle_dir`, as its files give it
/// (a trial with camera frames and no `markers.csv` counts as force-only;
/// `needle_vision::track_untracked_trials` and [`diagnose_campaign`] track
/// it first).
pub fn diagnose(
    bundle_dir: &Path,
    model: &ModelSpec,
    options: &DiagnoseOptions,
) -> Result<DiagnosisRun, DiagnoseError> {
    options.validate()?;
    model.effects()?;
    let bundle = read_bundle(bundle_dir)?;
    diagnose_campaign(&bundle.campaign, model, options)
}

/// Diagnoses `model` on a campaign already in memory.
pub fn diagnose_campaign(
    campaign: &Campaign,
    model: &ModelSpec,
    options: &DiagnoseOptions,
) -> Result<DiagnosisRun, DiagnoseError> {
    options.validate()?;
    model.effects()?;
    // Unless stated, the noise from the repeated samples weighs the first
    // fit; a channel without enough of them is weighed relatively.
    let repeated = campaign
        .noise
        .is_none()
        .then(|| noise_from_repeated_samples(campaign));
    let (marker_sigma, force_sigma) = match campaign.noise {
        Some(n) => (n.marker_sigma, n.force_sigma),
        None => (
            repeated.and_then(|r| r.marker).map_or(1.0e-5, |s| s.sigma),
            repeated.and_then(|r| r.force).map_or(1.0e-2, |s| s.sigma),
        ),
    };
    let obs = Observations::from_campaign(
        campaign,
        options.probe_force_samples,
        force_sigma,
        options.frames_per_trial,
        options.probe_near_field,
    )?;
    let needles: Vec<([f64; 2], [f64; 2])> = if options.slab_needle_grading {
        obs.frames
            .iter()
            .filter_map(|f| match f.load {
                Load::Needle(shaft) => Some((shaft.entry, shaft.direction)),
                _ => None,
            })
            .collect()
    } else {
        Vec::new()
    };
    let rest = obs.rest.clone();
    let forward_at = |refinement: usize| {
        Forward::new(
            &campaign.phantom,
            &rest,
            refinement,
            options.slab_refinement,
            &needles,
            options.needle_radius,
        )
    };
    let forward = forward_at(options.refinement)?;
    let measured = obs.measured();
    let marker_count = obs.marker_count();
    let row_sigmas = obs.row_sigmas();
    let mut context = Context {
        whitening: Whitening::independent(marker_count, marker_sigma, &row_sigmas, force_sigma),
        forward,
        obs,
        measured,
    };
    let start = Baseline {
        youngs_modulus: options.initial_youngs_modulus,
        poisson_ratio: options.initial_poisson_ratio,
        shaft_density: initial_shaft_density(&context.obs),
        probe_width: options.initial_probe_width,
    };
    let mut current = Model::new(model, &context.forward.geometry, start)?;
    // A first fit sets the weights: the probe force noise carried to the
    // markers at these parameters, and the noise itself when not stated.
    let first = fit_model(&context, &current, &[], &[], Precision::Model)?;
    let initial = [marker_sigma, force_sigma];
    let mut noise = weigh(&mut context, &current, &first, repeated, initial)?;
    // The mesh check (see `discretisation`) runs beside the fit under the
    // weights: it needs only the first fit's predictions.
    let refinements = [options.refinement, CHECK_FACTOR * options.refinement];
    let predicted: Vec<f64> = (first.residuals.iter())
        .zip(&context.measured)
        .map(|(r, d)| r + d)
        .collect();
    let (fitted, discretisation) = rayon::join(
        || fit_model(&context, &current, &first.params, &[], Precision::Model),
        || {
            check_discretisation(
                &context.obs,
                &context.whitening,
                &predicted,
                &forward_at(refinements[1])?,
                &current,
                &first.params,
                refinements,
            )
        },
    );
    let (mut fitted, discretisation) = (fitted?, discretisation?);
    let mut ladder = Ladder::default();
    let mut steps = Vec::new();
    let mut added: Option<String> = None;
    loop {
        let naming_ratio = options.min_explained
            * unexplained_misfit(&fitted.fit, fitted.dof, options.chi2_spread);
        let ranked = rank_candidates(&context, &current, &fitted, naming_ratio)?;
        let (verdict, threshold_p) = verdict(&ranked, &fitted, options);
        let mut warnings = physical_range_warnings(
            &current,
            &fitted.params,
            fitted.report.uncertainty.standard_errors[POISSON_RATIO],
        );
        warnings.extend(unchecked_slab_warning(&current, options.slab_refinement));
        // The check refines the plane body only, which a model with the
        // slab hardly uses.
        let doubt = if let Verdict::MissingEffect(id) = &verdict
            && !current.spec.effects.iter().any(|e| e == "out_of_plane")
            && let Some(ratio) = ranked
                .iter()
                .find(|r| &r.candidate.effect == id)
                .and_then(|r| r.candidate.likelihood_ratio)
        {
            discretisation.doubt(id, ratio)
        } else {
            None
        };
        let diagnosis = Diagnosis {
            bundle: campaign.name.clone(),
            model: current.spec.effects.clone(),
            verdict: verdict.clone(),
            fit: fitted.fit,
            candidates: ranked.iter().map(|r| r.candidate.clone()).collect(),
            noise: noise.clone(),
            threshold_p,
            warnings,
            doubt,
            discretisation: Some(discretisation),
        };
        ladder.rows.push(LadderRow {
            step: steps.len(),
            added: added.take(),
            model: current.spec.effects.clone(),
            parameters: current.len(),
            fit: fitted.fit,
            verdict: verdict.clone(),
        });
        steps.push(diagnosis);
        let next = match &verdict {
            Verdict::MissingEffect(id)
                if options.add_recommended && steps.len() <= options.max_added =>
            {
                ranked.into_iter().find(|r| &r.candidate.effect == id)
            }
            _ => None,
        };
        // The recommended effect was refitted: only refitted candidates
        // are named.
        let Some(Ranked {
            spec,
            fitted: Some(refit),
            ..
        }) = next
        else {
            break;
        };
        added = spec.effects.last().cloned();
        current = Model::new(
            &spec,
            &context.forward.geometry,
            current.baseline(&refit.params),
        )?;
        // The probe frames' weights carry the probe force noise to the
        // markers through the model's own responses, which the effect may
        // change a great deal (a foundation under a probed slab): they are
        // taken from the model with it, at its refit, before it is fitted.
        // Noise taken from a fit is weighed again below, after the fit.
        if noise.per_sample() {
            reweigh(&mut context, &current, &refit, &noise, initial)?;
        }
        // Candidates are refitted with the probe width held; the chosen
        // model is refitted with it free, since the width the previous
        // model fitted may have absorbed part of what the effect explains.
        // The next ranking's foundation on the slab is made meanwhile.
        let (fit, prepared) = rayon::join(
            || fit_model(&context, &current, &refit.params, &[], Precision::Model),
            || context.forward.prepare_foundation(&current, &refit.params),
        );
        fitted = fit?;
        prepared?;
        // Noise taken from a fit's residuals is taken again from the better
        // model's: the last model's misfit inflated it, and would hide
        // from the channel what the next effect must still explain.
        if !noise.per_sample() {
            noise = weigh(&mut context, &current, &fitted, repeated, initial)?;
            fitted = fit_model(&context, &current, &fitted.params, &[], Precision::Model)?;
        }
    }
    let diagnosis = steps.last().cloned().expect("at least one step");
    Ok(DiagnosisRun {
        fitted: fitted_model(&campaign.name, &current, &fitted),
        marker_residuals: marker_residuals(&context, &fitted),
        force_residuals: force_residuals(&context, &fitted),
        trial_ids: context.obs.trial_ids.clone(),
        trials: trial_misfits(&context, &fitted),
        diagnosis,
        steps,
        ladder,
    })
}

/// Below this Poisson's ratio a fitted soft phantom is suspect: PVC,
/// gelatin, agar and silicone phantoms are nearly incompressible.
const LEAST_PLAUSIBLE_POISSON_RATIO: f64 = 0.45;
/// How far below [`LEAST_PLAUSIBLE_POISSON_RATIO`] a fitted ratio may be
/// before it is flagged: far less than the plane-stress mimicry's shortfall
/// (0.33 at most for 0.45 to 0.5).
const POISSON_RATIO_TOLERANCE: f64 = 0.01;

/// Warnings about fitted constants outside their physical range. A
/// plane-strain model of a thin free slab (plane stress in the limit)
/// fits it exactly with $\nu' = \nu/(1+\nu)$ and
/// $E' = E(1+2\nu)/(1+\nu)^2$: for $\nu = 0.48$, $\nu' = 0.32$; the data
/// then cannot single out `out_of_plane`, but the constants can. Poisson's
/// ratio is flagged only when it is below the plausible range by more than
/// [`POISSON_RATIO_TOLERANCE`] and by more than twice its standard error
/// (`standard_error`, where the fit estimated one): a phantom of
/// $\nu = 0.45$ itself fits a little either side of it, by the noise and
/// by the model's mesh.
fn physical_range_warnings(
    model: &Model,
    params: &[f64],
    standard_error: Option<f64>,
) -> Vec<String> {
    let nu = model.baseline(params).poisson_ratio;
    let margin = (2.0 * standard_error.unwrap_or(0.0)).max(POISSON_RATIO_TOLERANCE);
    let mut warnings = Vec::new();
    if nu + margin < LEAST_PLAUSIBLE_POISSON_RATIO {
        let plane_stress_nu = (nu / (1.0 - nu)).min(0.5);
        let fitted = match standard_error {
            Some(se) => format!("{nu:.4} +- {se:.4}"),
            None => format!("{nu:.4}"),
        };
        let mut text = format!(
            "poisson_ratio fitted at {fitted}, below the {LEAST_PLAUSIBLE_POISSON_RATIO} of \
             nearly incompressible phantom materials (PVC, gelatin, silicone)"
        );
        if !model.spec.effects.iter().any(|e| e == "out_of_plane") {
            text += &format!(
                ": a plane-strain model reproduces a thin slab's plane-stress response with \
                 nu' = nu / (1 + nu), which here means nu of about {plane_stress_nu:.2} in the \
                 slab; \
                 the slab may be acting out of plane (try the `out_of_plane` effect)"
            );
        }
        warnings.push(text);
    }
    warnings
}

/// The warning for a model with the `out_of_plane` slab at
/// `slab_refinement`, which the mesh check does not refine (eight times
/// the unknowns). Its elements are far coarser than the plane's, and a
/// stiff mesh is taken up by the material constants and the slab's
/// weight rather than left in the misfit: on the paper default the final
/// model's E and nu sat some 40 standard errors below the truth, and half
/// as far on a slab of half the element size (`docs/benchmarks.md`,
/// session 35). The fit cannot tell that bias from the data, so the run
/// says where to look.
fn unchecked_slab_warning(model: &Model, slab_refinement: usize) -> Option<String> {
    if !model.spec.effects.iter().any(|e| e == "out_of_plane") {
        return None;
    }
    Some(format!(
        "the `out_of_plane` slab (refinement {slab_refinement}) is not refined by the mesh \
         check: the fitted youngs_modulus, poisson_ratio and slab_weight may carry its mesh's \
         bias beyond their intervals; rerun with --slab-refinement {} to see how far they move",
        2 * slab_refinement
    ))
}

/// The noise (`None` for `repeated`: stated, as `initial`) and the
/// whitening it gives at the fit `fitted` of `current`, each probe frame
/// with its force noise; an unstated channel's noise is the lesser of its
/// repeated samples' estimate and the fit's (see `noise`), `initial` where
/// it has no residuals.
fn weigh(
    context: &mut Context,
    current: &Model,
    fitted: &Fitted,
    repeated: Option<RepeatedSampleNoise>,
    initial: [f64; 2],
) -> Result<NoiseSource, DiagnoseError> {
    let marker_count = context.obs.marker_count();
    let force_count = context.obs.force_count();
    let row_sigmas = context.obs.row_sigmas();
    let mut responses = context
        .forward
        .predict(current, &fitted.params, &context.obs)?
        .probe_responses;
    let noise = match repeated {
        None => NoiseSource::Stated,
        Some(repeated) => {
            let (rms, dof) = (fitted.fit.rms_force, fitted.dof[1]);
            let from_fit =
                (force_count > 0 && rms > 0.0).then(|| rms * (force_count as f64 / dof).sqrt());
            let force = ChannelNoise::choose(from_fit, repeated.force, initial[1]);
            // The probe frames' force noise was set from `initial`.
            for response in &mut responses {
                response.force_sigma *= force.sigma / initial[1];
            }
            let marker = if !row_sigmas.is_empty() && row_sigmas.iter().all(|s| s.is_finite()) {
                ChannelNoise {
                    sigma: initial[0],
                    basis: NoiseBasis::Rows,
                }
            } else {
                let from_fit = marker_sigma_from_fit(
                    &fitted.residuals,
                    marker_count,
                    fitted.dof[0],
                    &row_sigmas,
                    &responses,
                );
                ChannelNoise::choose(from_fit, repeated.marker, initial[0])
            };
            NoiseSource::Estimated { marker, force }
        }
    };
    context.whitening = whitening(&context.obs, &noise, initial, &responses);
    Ok(noise)
}

/// The whitening of `noise` (`initial` where stated), with the probe
/// frames' force noise carried to the markers by `responses`.
fn whitening(
    obs: &Observations,
    noise: &NoiseSource,
    initial: [f64; 2],
    responses: &[ProbeResponse],
) -> Whitening {
    let [marker_sigma, force_sigma] = match noise {
        NoiseSource::Stated => initial,
        NoiseSource::Estimated { marker, force } => [marker.sigma, force.sigma],
    };
    Whitening::with_probe_noise(
        obs.marker_count(),
        marker_sigma,
        &obs.row_sigmas(),
        force_sigma,
        responses,
    )
}

/// The whitening of the same `noise`, with the probe frames' force noise
/// carried to the markers by `current` at its fit `fitted`. The probe
/// responses do not depend on where the needle loads act, so the needle
/// frames keep the fit's placements (no placement rounds).
fn reweigh(
    context: &mut Context,
    current: &Model,
    fitted: &Fitted,
    noise: &NoiseSource,
    initial: [f64; 2],
) -> Result<(), DiagnoseError> {
    let start = Start::Near {
        placements: &fitted.placements,
        rounds: 0,
    };
    let (prediction, _) =
        context
            .forward
            .predict_from(current, &fitted.params, &context.obs, start)?;
    let mut responses = prediction.probe_responses;
    // The probe frames' force noise was set from `initial`.
    if let NoiseSource::Estimated { force, .. } = noise {
        for response in &mut responses {
            response.force_sigma *= force.sigma / initial[1];
        }
    }
    context.whitening = whitening(&context.obs, noise, initial, &responses);
    Ok(())
}

/// The least-squares shaft density from the needle force samples,
/// $q = \sum |F| L / \sum L^2$ (1 N/m without needle data).
fn initial_shaft_density(obs: &Observations) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for sample in &obs.forces {
        if let Some(shaft) = sample.shaft {
            num += (sample.measured[0] * shaft.direction[0]
                + sample.measured[1] * shaft.direction[1])
                * shaft.length;
            den += shaft.length * shaft.length;
        }
    }
    if den > 0.0 { num / den } else { 1.0 }
}

/// The misfit a named effect must explain a fraction of: per channel the
/// excess $\chi^2_c - \nu_c$, but at least the spread $z\sqrt{2\nu_c}$
/// that the noise alone gives $\chi^2_c$ ($z$ = `chi2_spread`), summed
/// over the channels.
///
/// A channel that fits better than its stated noise (a generous stated
/// sigma) says nothing about what another channel misses, so its deficit
/// does not offset their excess. And a residual whose excess is within
/// the noise's spread can hide the model's own small inexactness (its
/// mesh, its idealised probe contact): an effect explaining only a sliver
/// of that spread may be mimicking it, however small its p-value under
/// an exact model.
fn unexplained_misfit(fit: &Fit, dof: [f64; 2], chi2_spread: f64) -> f64 {
    [fit.chi2_marker, fit.chi2_force]
        .iter()
        .zip(dof)
        .filter(|(per_dof, _)| per_dof.is_finite())
        .map(|(per_dof, dof)| ((per_dof - 1.0) * dof).max(chi2_spread * (2.0 * dof).sqrt()))
        .sum()
}

/// The verdict rules (see the crate documentation).
fn verdict(ranked: &[Ranked], fitted: &Fitted, options: &DiagnoseOptions) -> (Verdict, f64) {
    let threshold_p = options.significance / ranked.len().max(1) as f64;
    let unexplained = unexplained_misfit(&fitted.fit, fitted.dof, options.chi2_spread);
    let leader = ranked
        .iter()
        .filter_map(|r| {
            let c = &r.candidate;
            Some((c, c.likelihood_ratio?, c.likelihood_ratio_p?))
        })
        .filter(|(_, _, p)| *p < threshold_p)
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .filter(|(_, ratio, _)| *ratio >= options.min_explained * unexplained)
        .map(|(c, _, _)| c);
    if let Some(leader) = leader {
        return (Verdict::MissingEffect(leader.effect.clone()), threshold_p);
    }
    let consistent = |chi2: f64, dof: f64| {
        !chi2.is_finite() || chi2 <= 1.0 + options.chi2_spread * (2.0 / dof).sqrt()
    };
    if consistent(fitted.fit.chi2_marker, fitted.dof[0])
        && consistent(fitted.fit.chi2_force, fitted.dof[1])
    {
        (Verdict::ConsistentWithNoise, threshold_p)
    } else {
        (Verdict::Unexplained, threshold_p)
    }
}

fn fitted_model(bundle: &str, model: &Model, fitted: &Fitted) -> FittedModel {
    FittedModel {
        bundle: bundle.to_string(),
        model: model.spec.effects.clone(),
        parameters: model
            .parameters
            .iter()
            .enumerate()
            .map(|(k, spec)| FittedParameter {
                name: spec.name.clone(),
                value: fitted.params[k],
                standard_error: fitted.report.standard_error(k),
                interval: fitted.report.confidence_interval(k, 0.95).ok(),
                meaning: spec.meaning.to_string(),
            })
            .collect(),
        fit: fitted.fit,
    }
}

fn marker_residuals(context: &Context, fitted: &Fitted) -> Vec<MarkerResidual> {
    let obs = &context.obs;
    let geometry = &context.forward.geometry;
    let mut out = Vec::new();
    let mut slot = 0;
    for frame in &obs.frames {
        let trial = &obs.trials[frame.trial];
        for &(m, _) in &frame.markers {
            let [x, y] = obs.rest[m];
            let (tip_depth, distance_from_tool) = match frame.load {
                Load::Free => (0.0, f64::NAN),
                Load::Probe { contact, .. } => (
                    0.0,
                    ((x - contact[0]).powi(2) + (y - contact[1]).powi(2)).sqrt(),
                ),
                Load::Needle(shaft) => {
                    let (dx, dy) = (x - shaft.entry[0], y - shaft.entry[1]);
                    let along = (dx * shaft.direction[0] + dy * shaft.direction[1])
                        .clamp(0.0, shaft.length);
                    let px = shaft.entry[0] + along * shaft.direction[0];
                    let py = shaft.entry[1] + along * shaft.direction[1];
                    (shaft.length, ((x - px).powi(2) + (y - py).powi(2)).sqrt())
                }
            };
            out.push(MarkerResidual {
                trial: frame.trial,
                t: frame.t,
                marker: m,
                x,
                y,
                rx: fitted.residuals[slot],
                ry: fitted.residuals[slot + 1],
                velocity: trial.velocity,
                day: trial.day,
                tip_depth,
                distance_from_tool,
                radius: ((x - geometry.image_centre[0]).powi(2)
                    + (y - geometry.image_centre[1]).powi(2))
                .sqrt(),
            });
            slot += 2;
        }
    }
    out
}

/// Sums of squared raw and whitened residuals per trial and channel. The
/// whitening couples residuals only within a probe frame, so the whitened
/// squares add up per trial.
fn trial_misfits(context: &Context, fitted: &Fitted) -> Vec<TrialMisfit> {
    let obs = &context.obs;
    let whitened = context.whitening.apply(&fitted.residuals);
    // Per trial and channel: values, sum of squares, whitened sum of squares.
    let mut sums = vec![[(0usize, 0.0, 0.0); 2]; obs.trial_ids.len()];
    let mut add = |trial: usize, channel: usize, slot: usize| {
        let entry = &mut sums[trial][channel];
        entry.0 += 1;
        entry.1 += fitted.residuals[slot].powi(2);
        entry.2 += whitened[slot].powi(2);
    };
    let mut slot = 0;
    for frame in &obs.frames {
        for _ in 0..2 * frame.markers.len() {
            add(frame.trial, 0, slot);
            slot += 1;
        }
    }
    for sample in &obs.forces {
        for _ in 0..2 {
            add(sample.trial, 1, slot);
            slot += 1;
        }
    }
    let mean = |sum: f64, n: usize| if n > 0 { sum / n as f64 } else { f64::NAN };
    obs.trial_ids
        .iter()
        .zip(sums)
        .zip(&obs.near_field_left_out)
        .map(
            |((id, [(m, m2, mw), (f, f2, fw)]), &left_out)| TrialMisfit {
                trial: id.clone(),
                marker_values: m,
                rms_marker: mean(m2, m).sqrt(),
                chi2_marker: mean(mw, m),
                force_values: f,
                rms_force: mean(f2, f).sqrt(),
                chi2_force: mean(fw, f),
                near_field_left_out: left_out,
            },
        )
        .collect()
}

fn force_residuals(context: &Context, fitted: &Fitted) -> Vec<ForceResidual> {
    let obs = &context.obs;
    let offset = obs.marker_count();
    obs.forces
        .iter()
        .enumerate()
        .map(|(k, sample)| {
            let trial = &obs.trials[sample.trial];
            ForceResidual {
                trial: sample.trial,
                t: sample.t,
                tip_depth: sample.shaft.map_or(0.0, |s| s.length),
                velocity: trial.velocity,
                day: trial.day,
                rx: fitted.residuals[offset + 2 * k],
                ry: fitted.residuals[offset + 2 * k + 1],
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::test_model as model;

    #[test]
    fn a_channel_below_its_noise_does_not_offset_another_s_excess() {
        let fit = |marker: f64, force: f64| Fit {
            rms_marker: 1e-5,
            rms_force: 1e-2,
            chi2_marker: marker,
            chi2_force: force,
        };
        let dof = [20_000.0, 5_000.0];
        // Spread 3 sqrt(2 dof): 600 and 300.
        let floor = 600.0 + 300.0;
        // Markers 2000 beyond their dof, force 500 below: 2000 + 300, not 1500.
        let misfit = unexplained_misfit(&fit(1.1, 0.9), dof, 3.0);
        assert!((misfit - 2300.0).abs() < 1e-6, "{misfit}");
        // Both channels at the noise: the noise's own spread.
        assert!((unexplained_misfit(&fit(1.0, 1.0), dof, 3.0) - floor).abs() < 1e-6);
        // A channel without data counts for nothing.
        let markers_only = unexplained_misfit(&fit(1.5, f64::NAN), dof, 3.0);
        assert!((markers_only - 10_000.0).abs() < 1e-6, "{markers_only}");
    }

    #[test]
    fn a_plane_strain_fit_of_a_thin_slab_is_flagged() {
        let baseline = model(&[]);
        // The plane-stress mimic of nu = 0.48: nu' = 0.48 / 1.48.
        let mimic = [22.6e3, 0.48 / 1.48, 10.0, 0.002];
        let warnings = physical_range_warnings(&baseline, &mimic, Some(0.002));
        assert_eq!(warnings.len(), 1);
        assert!(warnings[0].contains("out_of_plane"), "{}", warnings[0]);
        assert!(warnings[0].contains("about 0.48"), "{}", warnings[0]);
        assert!(warnings[0].contains("0.3243 +- 0.0020"), "{}", warnings[0]);
        let plausible = [25.3e3, 0.48, 10.0, 0.002];
        assert!(physical_range_warnings(&baseline, &plausible, None).is_empty());
        // A phantom of nu = 0.45 fitted a little below it is not flagged,
        // however precise the fit; one clearly below is, unless the fit
        // is too uncertain to say.
        let edge = [15.0e3, 0.4497, 10.0, 0.002];
        assert!(physical_range_warnings(&baseline, &edge, Some(1e-5)).is_empty());
        let below = [15.0e3, 0.43, 10.0, 0.002];
        assert_eq!(
            physical_range_warnings(&baseline, &below, Some(1e-5)).len(),
            1
        );
        assert!(physical_range_warnings(&baseline, &below, Some(0.02)).is_empty());
        let slab = model(&["out_of_plane"]);
        let mut p = vec![25.3e3, 0.3, 10.0, 0.002];
        p.resize(slab.len(), 1.0);
        let warnings = physical_range_warnings(&slab, &p, None);
        assert_eq!(warnings.len(), 1);
        assert!(!warnings[0].contains("try the"), "{}", warnings[0]);
    }

    #[test]
    fn a_model_with_the_slab_is_told_its_slab_is_not_checked() {
        assert_eq!(unchecked_slab_warning(&model(&[]), 1), None);
        assert_eq!(
            unchecked_slab_warning(&model(&["tip_cutting_force"]), 1),
            None
        );
        let warning = unchecked_slab_warning(&model(&["tip_cutting_force", "out_of_plane"]), 3)
            .expect("the slab is in the model");
        assert!(warning.contains("(refinement 3)"), "{warning}");
        assert!(warning.contains("--slab-refinement 6"), "{warning}");
    }
}
