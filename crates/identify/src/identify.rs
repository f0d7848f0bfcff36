//! The identification pipeline: scan Poisson's ratio with the modulus
//! projected out in closed form, polish $(E, \nu)$ and the probe's contact
//! width with Levenberg-Marquardt, then the per-region moduli, the
//! per-trial moduli and their drift.

use needle_data::LoadedBundle;
use needle_fem::material::Materials;
use needle_lsq::{CovarianceScaling, FitReport, LevenbergMarquardt, Parameter, ParameterStatus};

use crate::error::IdentifyError;
use crate::extract::extract_probe_data;
use crate::model::{ModelSpec, ProbeModel};
use crate::observe::{Observations, load_points};
use crate::options::{IdentifyOptions, ProbeLoad};
use crate::probe::ProbeData;
use crate::problem::{LineProblem, ProbeProblem, ScaleProblem};
use crate::result::{
    DriftFit, Estimate, FitFlag, MaterialFit, ModelSummary, NoiseSource, RegionFit, TrialFit,
};

/// chi2/dof above which a fit with stated noise is flagged as poor.
const POOR_FIT_REDUCED_CHI2: f64 = 2.0;
/// A drift is flagged when the slope exceeds this many standard errors...
const DRIFT_Z: f64 = 3.0;
/// ...and changes the modulus by more than this fraction over the days spanned.
const DRIFT_FRACTION: f64 = 0.005;
/// Largest contact width searched, as a fraction of the smaller side of
/// the phantom.
const MAX_WIDTH_FRACTION: f64 = 0.5;

/// Identifies the material from the bundle's `Probe` trials (equation (5)).
/// Trials that cannot contribute are skipped and flagged; see
/// [`identify_from_data`] for the fit itself.
pub fn identify_material(
    bundle: &LoadedBundle,
    options: &IdentifyOptions,
) -> Result<MaterialFit, IdentifyError> {
    options.validate()?;
    let (data, mut flags) = extract_probe_data(bundle, options)?;
    let mut fit = identify_from_data(&data, options)?;
    flags.append(&mut fit.flags);
    fit.flags = flags;
    Ok(fit)
}

/// The best compliance scale and the cost at one Poisson's ratio.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ScanPoint {
    /// Poisson's ratio.
    pub poisson_ratio: f64,
    /// $s = \langle g, d\rangle_W / \langle g, g\rangle_W$: the measured
    /// displacements are $s$ times the prediction at the reference modulus.
    pub scale: f64,
    /// $\tfrac12 |W(d - s g)|^2$ (with $s$ clamped at 0).
    pub cost: f64,
}

/// Identifies the material from probing data given as arrays.
///
/// 1. Scan $\nu$ over `options.poisson_bounds` (points uniform in
///    $\ln(1/2 - \nu)$, which crowds them where the response changes fast,
///    plus the start), projecting the modulus out in closed form at each,
///    with the contact width at its start.
/// 2. Polish $(E, \nu)$ and the contact width (when fitted) from the best
///    scan point with the `needle-lsq` Levenberg-Marquardt engine
///    (analytic Jacobian in the material, a difference of the load in the
///    width), which also gives the covariance.
/// 3. With regions: fit $(E_0, \dots, E_{R-1}, \nu)$ from the homogeneous
///    optimum.
/// 4. With `per_trial`: each trial's modulus with $\nu$ held, and a line
///    through them against the day (three or more trials on two or more days).
pub fn identify_from_data(
    data: &ProbeData,
    options: &IdentifyOptions,
) -> Result<MaterialFit, IdentifyError> {
    options.validate()?;
    data.validate()?;
    if data.frames.is_empty() {
        return Err(IdentifyError::NoContactFrames {
            reason: "the data hold no frame".into(),
        });
    }
    if data.frames.iter().all(|f| f.force == [0.0, 0.0]) {
        return Err(IdentifyError::NoContactFrames {
            reason: "the probe force is zero in every frame".into(),
        });
    }
    let (points, frame_loads) = load_points(data)?;
    let spec = ModelSpec {
        element: options.element,
        plane: options.plane,
        refinement: options.refinement,
        layers: options.slab_layers,
        regions: options.regions.clone(),
    };
    let model = ProbeModel::new(&data.setup, &points, &spec)?;
    let mut observations = Observations::new(data, &model, &frame_loads, options)?;
    let (start_width, fit_width) = match options.probe {
        ProbeLoad::Point => (0.0, false),
        ProbeLoad::FlatPunch { width, fit_width } => {
            (width.unwrap_or(model.marker_spacing()), fit_width)
        }
    };
    let parameter_count = usize::from(fit_width)
        + if model.region_count() > 1 {
            model.region_count() + 1
        } else {
            2
        };
    if observations.rows.len() <= parameter_count {
        return Err(IdentifyError::TooFewMarkers {
            context: format!(
                "{} residual(s) for {parameter_count} parameters",
                observations.rows.len()
            ),
            needed: parameter_count.div_ceil(2) + 1,
            found: observations.markers,
        });
    }
    let mut flags = Vec::new();

    // 1. The scan with the modulus projected out.
    let reference = options.start_youngs_modulus;
    let scan = scan_poisson(&model, &observations, options, start_width)?;
    let best = scan
        .iter()
        .copied()
        .filter(|p| p.scale > 0.0)
        .min_by(|a, b| a.cost.total_cmp(&b.cost))
        .ok_or_else(|| IdentifyError::NoElasticResponse {
            context: "all probing frames".into(),
            scale: scan
                .iter()
                .map(|p| p.scale)
                .fold(f64::NEG_INFINITY, f64::max),
        })?;
    let scaling = if let NoiseSource::Estimated(_) = observations.noise {
        let dof = observations.rows.len() - parameter_count;
        let sigma = (2.0 * best.cost / dof as f64).sqrt();
        if sigma.is_nan() || sigma <= 0.0 {
            return Err(IdentifyError::InvalidValue {
                field: "estimated marker noise",
                value: sigma,
                reason: "the model fits exactly; state the noise (options.marker_sigma) to get uncertainties",
            });
        }
        observations.rescale(sigma);
        flags.push(FitFlag::NoiseEstimated { sigma });
        CovarianceScaling::ReducedChiSquare
    } else {
        CovarianceScaling::KnownNoise
    };
    let engine = LevenbergMarquardt::new(needle_lsq::Options {
        covariance_scaling: scaling,
        ..options.lsq.clone()
    });
    let (e_lo, e_hi) = options.modulus_bounds;
    let (nu_lo, nu_hi) = options.poisson_bounds;
    let modulus = |name: String, value: f64| {
        Parameter::new(name, value.clamp(e_lo, e_hi))
            .with_bounds(e_lo, e_hi)
            .with_scale(value.clamp(e_lo, e_hi))
    };
    let poisson = |value: f64| {
        Parameter::new("nu", value)
            .with_bounds(nu_lo, nu_hi)
            .with_scale(0.01)
    };
    let max_width = MAX_WIDTH_FRACTION * data.setup.width.min(data.setup.depth);
    let contact_width = |value: f64| {
        let parameter = Parameter::new("probe width", value.clamp(0.0, max_width))
            .with_bounds(0.0, max_width)
            .with_scale(model.marker_spacing());
        if fit_width {
            parameter
        } else {
            parameter.fix()
        }
    };

    // 2. The polish of (E, nu) and the contact width.
    let problem = ProbeProblem::new(&model, &observations, true, fit_width);
    let report = engine.minimize(
        &problem,
        &[
            modulus("E".into(), reference / best.scale),
            poisson(best.poisson_ratio),
            contact_width(start_width),
        ],
    )?;
    flag_report(&report, "homogeneous fit", &mut flags);
    let youngs_modulus = Estimate::from_report(&report, 0);
    let poisson_ratio = Estimate::from_report(&report, 1);
    let width = Estimate::from_report(&report, 2);
    let reduced_chi2 = report.reduced_chi2().unwrap_or(f64::NAN);
    if scaling == CovarianceScaling::KnownNoise && reduced_chi2 > POOR_FIT_REDUCED_CHI2 {
        flags.push(FitFlag::PoorFit { reduced_chi2 });
    }

    // 3. Per-region moduli.
    let regions = if model.region_count() > 1 {
        let problem = ProbeProblem::new(&model, &observations, false, fit_width);
        let mut parameters: Vec<Parameter> = (0..model.region_count())
            .map(|r| modulus(format!("E[{r}]"), youngs_modulus.value))
            .collect();
        parameters.push(poisson(poisson_ratio.value));
        parameters.push(contact_width(width.value));
        let regional = engine.minimize(&problem, &parameters)?;
        flag_report(&regional, "region fit", &mut flags);
        Some(RegionFit {
            youngs_moduli: (0..model.region_count())
                .map(|r| Estimate::from_report(&regional, r))
                .collect(),
            poisson_ratio: Estimate::from_report(&regional, model.region_count()),
            reduced_chi2: regional.reduced_chi2().unwrap_or(f64::NAN),
            evaluations: regional.evaluations.residuals,
        })
    } else {
        None
    };

    // 4. Per-trial moduli and their drift.
    let (trials, drift) = if options.per_trial {
        let materials =
            Materials::from_parameters(&vec![
                (youngs_modulus.value, poisson_ratio.value);
                model.region_count()
            ])?;
        let pattern = model.respond(&materials, width.value)?;
        let trials = fit_trials(
            data,
            &observations,
            &pattern.markers,
            youngs_modulus.value,
            &engine,
            options,
            &mut flags,
        )?;
        let drift = fit_drift(&trials, &mut flags)?;
        (trials, drift)
    } else {
        (Vec::new(), None)
    };

    let (nodes, elements) = model.mesh_size();
    Ok(MaterialFit {
        youngs_modulus,
        poisson_ratio,
        probe_width: matches!(options.probe, ProbeLoad::FlatPunch { .. }).then_some(width),
        regions,
        chi2: report.chi2,
        dof: report.dof,
        reduced_chi2,
        noise: observations.noise,
        trials,
        drift,
        model: ModelSummary {
            element: model.element(),
            plane: options.plane,
            nodes,
            elements,
            load_points: model.load_points().len(),
            frames: observations.frames.len(),
            markers: observations.markers,
            residuals: observations.rows.len(),
        },
        evaluations: scan.len() + report.evaluations.residuals,
        jacobians: report.evaluations.jacobians,
        flags,
    })
}

/// The profile of equation (5) over $\nu$: for fixed $\nu$,
/// $K(E,\nu)^{-1} = (E_\text{ref}/E)\,K(E_\text{ref},\nu)^{-1}$, so the
/// prediction is $s\,g(\nu)$ with $s = E_\text{ref}/E$ and the best $s$ is
/// the weighted projection $\langle g, d\rangle_W/\langle g, g\rangle_W$.
pub(crate) fn scan_poisson(
    model: &ProbeModel,
    observations: &Observations,
    options: &IdentifyOptions,
    width: f64,
) -> Result<Vec<ScanPoint>, IdentifyError> {
    let (lo, hi) = options.poisson_bounds;
    let n = options.scan_points;
    let (a, b) = ((0.5 - lo).ln(), (0.5 - hi).ln());
    let mut ratios: Vec<f64> = (0..n)
        .map(|k| 0.5 - (a + (b - a) * k as f64 / (n - 1) as f64).exp())
        .collect();
    ratios.push(options.start_poisson_ratio);
    ratios.sort_by(f64::total_cmp);
    ratios.dedup();
    let reference = options.start_youngs_modulus;
    ratios
        .into_iter()
        .map(|nu| {
            let materials =
                Materials::from_parameters(&vec![(reference, nu); model.region_count()])?;
            let response = model.respond(&materials, width)?;
            let (mut gd, mut gg, mut dd) = (0.0, 0.0, 0.0);
            for row in &observations.rows {
                let w2 = row.weight * row.weight;
                let g = observations.predict(row, &response.markers);
                gd += w2 * g * row.value;
                gg += w2 * g * g;
                dd += w2 * row.value * row.value;
            }
            let scale = if gg > 0.0 { gd / gg } else { 0.0 };
            let cost = 0.5 * if scale > 0.0 { dd - gd * scale } else { dd };
            Ok(ScanPoint {
                poisson_ratio: nu,
                scale,
                cost: cost.max(0.0),
            })
        })
        .collect()
}

/// Each trial's modulus with the displacement pattern of the global fit.
fn fit_trials(
    data: &ProbeData,
    observations: &Observations,
    pattern: &[Vec<f64>],
    reference: f64,
    engine: &LevenbergMarquardt,
    options: &IdentifyOptions,
    flags: &mut Vec<FitFlag>,
) -> Result<Vec<TrialFit>, IdentifyError> {
    let (e_lo, e_hi) = options.modulus_bounds;
    let mut fits = Vec::new();
    for (t, trial) in data.trials.iter().enumerate() {
        let rows: Vec<(f64, f64, f64)> = observations
            .rows
            .iter()
            .filter(|row| observations.frames[row.frame].trial == t)
            .map(|row| (row.weight, row.value, observations.predict(row, pattern)))
            .collect();
        let frames = observations.frames.iter().filter(|f| f.trial == t).count();
        if rows.len() < 2 {
            continue;
        }
        let (gd, gg) = rows.iter().fold((0.0, 0.0), |(gd, gg), &(w, d, g)| {
            (gd + w * w * g * d, gg + w * w * g * g)
        });
        let scale = if gg > 0.0 { gd / gg } else { 0.0 };
        if scale.is_nan() || scale <= 0.0 {
            flags.push(FitFlag::TrialSkipped {
                trial: trial.id.clone(),
                reason: format!("its markers do not respond to the probe force like an elastic body (scale {scale:e})"),
            });
            continue;
        }
        let start = (reference / scale).clamp(e_lo, e_hi);
        let problem = ScaleProblem { rows, reference };
        let name = format!("E[{}]", trial.id);
        let report = engine.minimize(
            &problem,
            &[Parameter::new(name, start).with_bounds(e_lo, e_hi)],
        )?;
        flag_report(&report, &format!("trial `{}`", trial.id), flags);
        fits.push(TrialFit {
            id: trial.id.clone(),
            day: trial.day,
            frames,
            youngs_modulus: Estimate::from_report(&report, 0),
            reduced_chi2: report.reduced_chi2().unwrap_or(f64::NAN),
        });
    }
    Ok(fits)
}

/// The drift line through the per-trial moduli, when three or more trials
/// with standard errors span two or more days. Its covariance is scaled by
/// the line's chi2/dof, so the scatter of the trials (model error differs
/// from probe site to probe site) widens the slope's error.
fn fit_drift(
    trials: &[TrialFit],
    flags: &mut Vec<FitFlag>,
) -> Result<Option<DriftFit>, IdentifyError> {
    let usable: Vec<(f64, f64, f64)> = trials
        .iter()
        .filter_map(|t| {
            t.youngs_modulus
                .standard_error
                .filter(|s| *s > 0.0)
                .map(|s| (t.day, t.youngs_modulus.value, s))
        })
        .collect();
    let (first, last) = usable
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(p.0), b.max(p.0))
        });
    if usable.len() < 3 || last <= first {
        return Ok(None);
    }
    let reference_day = usable.iter().map(|p| p.0).sum::<f64>() / usable.len() as f64;
    let mean_modulus = usable.iter().map(|p| p.1).sum::<f64>() / usable.len() as f64;
    let problem = LineProblem {
        points: usable
            .iter()
            .map(|&(day, e, s)| (day - reference_day, e, s))
            .collect(),
    };
    let engine = LevenbergMarquardt::new(needle_lsq::Options {
        covariance_scaling: CovarianceScaling::ReducedChiSquare,
        ..needle_lsq::Options::default()
    });
    let scale = mean_modulus.abs().max(f64::MIN_POSITIVE);
    let report = engine.minimize(
        &problem,
        &[
            Parameter::new("E(reference day)", mean_modulus).with_scale(scale),
            Parameter::new("slope", 0.0).with_scale(scale / (last - first)),
        ],
    )?;
    let slope = Estimate::from_report(&report, 1);
    if let Some(se) = slope.standard_error {
        let z = slope.value / se;
        if z.abs() > DRIFT_Z && (slope.value * (last - first)).abs() > DRIFT_FRACTION * mean_modulus
        {
            flags.push(FitFlag::Drift {
                slope: slope.value,
                z,
            });
        }
    }
    Ok(Some(DriftFit {
        modulus_at_reference: Estimate::from_report(&report, 0),
        slope,
        reference_day,
        reduced_chi2: report.reduced_chi2().unwrap_or(f64::NAN),
    }))
}

/// Flags non-convergence, parameters on a bound and unidentifiable ones.
fn flag_report(report: &FitReport, fit: &str, flags: &mut Vec<FitFlag>) {
    if !report.termination.is_converged() {
        flags.push(FitFlag::NotConverged {
            fit: fit.into(),
            termination: report.termination,
        });
    }
    for j in report.uncertainty.indices_with(ParameterStatus::AtBound) {
        flags.push(FitFlag::AtBound {
            parameter: format!("{fit}: {}", report.names[j]),
            value: report.params[j],
        });
    }
    let unidentifiable = report.uncertainty.unidentifiable();
    if !unidentifiable.is_empty() {
        flags.push(FitFlag::Unidentifiable {
            fit: fit.into(),
            parameters: unidentifiable
                .iter()
                .map(|&j| report.names[j].clone())
                .collect(),
        });
    }
}
