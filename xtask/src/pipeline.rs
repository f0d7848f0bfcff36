//! `cargo xtask pipeline`: the main job on the built-in default experiment.
//!
//! 1. the truth world (`needle-synth`) writes the paper-default campaign as a
//!    measurement bundle, with its ground truth beside it;
//! 2. the bundle is read and validated (`needle-data`), and the measured
//!    deformation of the deepest needle frame is plotted; the camera is
//!    calibrated from the bundle's dot-grid images and the trials with
//!    rendered frames are tracked (`needle-vision`) and compared with their
//!    `markers.csv`;
//! 3. E and nu are identified from the probing trials (`needle-identify`,
//!    the paper's eq. 5) and compared with the truth;
//! 4. the needle shaft force is inverted (`needle-force`): the paper's plane
//!    f = K u (eq. 4, Figs. 9-11) and the regularised 3-D slab estimate
//!    (eq. 6, Figs. 10b, 13, 14);
//! 5. the diagnosis loop (`needle-diagnose`) fits the paper's baseline to
//!    every trial, names the missing effect, adds it and refits until the
//!    residual is consistent with noise or unexplained (the error ladder),
//!    and the fitted model's simulation of each insertion is compared with
//!    the measured markers (the paper's Fig. 16; in-sample, since the
//!    fitted model saw those markers);
//! 6. everything goes into one offline HTML report.
//!
//! Steps 2b to 4 need the bundle and the truth but nothing from step 5, and
//! step 5 needs only the bundle, so once the bundle is read the two branches
//! run side by side on the machine's two cores; the report keeps the order
//! above.

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use needle_data::{BundleError, LoadedBundle, TrialKind, read_bundle};
use needle_diagnose::{DiagnoseOptions, ModelSpec, diagnose, write_outputs};
use needle_fem::Material;
use needle_force::{
    EstimatorOptions, Insertion, IntegratedPoint, IntegratedSeries, MaterialField, Method,
    PlaneKind, Regularisation, ShaftCurve, ShaftWindow, density_vs_velocity, integrated_vs_base,
    observe_insertion, plot_density_vs_velocity, plot_integrated_vs_base, plot_shaft_distributions,
    shaft_force_distributions,
};
use needle_identify::{IdentifyOptions, PlaneModel, identify_material};
use needle_synth::{GroundTruth, Scenario, Stage, generate, load_scenario};
use needle_vision::{calibrate_from_bundle, frame_rate, track_trial};

use crate::diagnose_command::sequential_linear_algebra;
use crate::diagnosis_report::{add_sections, print_ladder};
use crate::output::OutputFolder;
use crate::plot;
use crate::report::Report;

/// Options of `cargo xtask pipeline`.
#[derive(Args)]
pub struct PipelineArgs {
    /// Scenario file (RON) for the truth world; default: the built-in paper default.
    #[arg(long)]
    scenario: Option<PathBuf>,
    /// Output folder (must not exist); default: a new folder under `out/`.
    #[arg(long)]
    out: Option<PathBuf>,
    /// A smaller experiment (the truth world's quick campaign, fewer frames
    /// inverted), as run in CI.
    #[arg(long)]
    quick: bool,
}

/// Frames per insertion given to the shaft force inversion: the slab
/// estimate costs a regularised solve per frame, and the figures need a
/// dozen depths, not every camera frame.
const FRAMES_PER_INSERTION: usize = 12;
/// Camera frames per trial given to the diagnosis (each costs a solve in
/// every evaluation of every fit).
const DIAGNOSIS_FRAMES_PER_TRIAL: usize = 4;
/// Model mesh of the diagnosis: elements half the marker spacing.
const DIAGNOSIS_REFINEMENT: usize = 2;
/// Frames shallower than this are left out of the force error figures, as
/// in the target (the shaft carries too little force there).
const MIN_DEPTH: f64 = 0.010;

/// Runs the pipeline.
pub fn run(args: &PipelineArgs) -> Result<(), String> {
    let started = Instant::now();
    let folder = OutputFolder::create(args.out.as_deref(), "pipeline")?;
    let mut report = Report::default();

    let scenario = match &args.scenario {
        Some(path) => load_scenario(path).map_err(|e| e.to_string())?,
        None if args.quick => Scenario::quick(),
        None => Scenario::paper_default(),
    };
    let bars = MultiProgress::new();
    let mut stages = StageTimes::default();
    let truth = stages.time("truth world", || {
        synthesise(&scenario, &folder, &mut report, &bars)
    })?;
    let bundle = stages.time("bundle: read, validate, plot", || {
        let bundle = read_bundle(folder.file("bundle")).map_err(|e| match e {
            BundleError::Invalid { report } => {
                format!("the generated bundle is invalid:\n{report}")
            }
            other => other.to_string(),
        })?;
        measured_deformation(&bundle, &folder, &mut report)?;
        Ok::<_, String>(bundle)
    })?;
    // The diagnosis reads the bundle alone, so it runs beside the camera,
    // identification and force stages: it keeps both cores busy only part
    // of the time, and they fill the rest. faer runs sequentially in both
    // branches, which already share the two cores.
    sequential_linear_algebra();
    let (upstream, diagnosis) = std::thread::scope(|scope| {
        let diagnosis = scope.spawn(|| {
            let mut section = Report::default();
            let mut times = StageTimes::default();
            let outcome = times.time("diagnosis and simulation", || {
                diagnose_stage(
                    &folder,
                    args.quick,
                    scenario.needles.radius,
                    &mut section,
                    &bars,
                )
            });
            (outcome, section, times)
        });
        let mut sections = Report::default();
        let mut times = StageTimes::default();
        let outcome = (|| {
            times.time("camera: calibrate, track", || {
                track_camera_frames(&bundle, &truth, &mut sections, &bars)
            })?;
            let material = times.time("identification", || {
                identify(&bundle, &truth, &mut sections, &bars)
            })?;
            times.time("force inversion", || {
                invert_forces(&bundle, material, args.quick, &folder, &mut sections, &bars)
            })
        })();
        let diagnosis = diagnosis
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
        ((outcome, sections, times), diagnosis)
    });
    for (outcome, sections, times) in [upstream, diagnosis] {
        outcome?;
        report.append(sections);
        stages.0.extend(times.0);
    }
    stages.print();
    report.table(
        "Run time per stage (the camera, identification and force inversion \
         ran beside the diagnosis)",
        &["stage", "wall time (s)"],
        &stages.rows(),
    );

    folder.write("report.html", &report.to_html("needle pipeline report"))?;
    let finished = folder.finish()?;
    println!(
        "pipeline finished in {:.1} s; report: {}",
        started.elapsed().as_secs_f64(),
        finished.join("report.html").display()
    );
    Ok(())
}

/// Wall time of each stage, so that a user sees where the run went.
#[derive(Default)]
struct StageTimes(Vec<(&'static str, f64)>);

impl StageTimes {
    fn time<T>(&mut self, stage: &'static str, run: impl FnOnce() -> T) -> T {
        let started = Instant::now();
        let out = run();
        self.0.push((stage, started.elapsed().as_secs_f64()));
        out
    }

    fn rows(&self) -> Vec<Vec<String>> {
        self.0
            .iter()
            .map(|(stage, seconds)| vec![stage.to_string(), format!("{seconds:.1}")])
            .collect()
    }

    fn print(&self) {
        for (stage, seconds) in &self.0 {
            println!("{stage:<30} {seconds:>7.1} s");
        }
    }
}

fn spinner(bars: &MultiProgress, message: &str) -> ProgressBar {
    let bar = bars.add(ProgressBar::new_spinner());
    bar.set_style(
        ProgressStyle::with_template("{spinner} [{elapsed}] {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_spinner()),
    );
    bar.set_message(message.to_string());
    bar.enable_steady_tick(std::time::Duration::from_millis(200));
    bar
}

/// Stage 1: the truth world writes the campaign.
fn synthesise(
    scenario: &Scenario,
    folder: &OutputFolder,
    report: &mut Report,
    bars: &MultiProgress,
) -> Result<GroundTruth, String> {
    let bar = spinner(
        bars,
        &format!("truth world: generating {:?}", scenario.name),
    );
    let progress = |stage: Stage| bar.set_message(format!("truth world: {stage:?}"));
    let truth_path = folder.file("truth.ron");
    let summary = generate(scenario, &folder.file("bundle"), &truth_path, progress)
        .map_err(|e| format!("truth world: {e}"))?;
    bar.finish_with_message(format!(
        "truth world: {} trials in {:.1} s",
        summary.trials, summary.seconds
    ));
    let truth_text = std::fs::read_to_string(&truth_path)
        .map_err(|e| format!("cannot read {}: {e}", truth_path.display()))?;
    let truth: GroundTruth = ron::from_str(&truth_text)
        .map_err(|e| format!("cannot parse {}: {e}", truth_path.display()))?;
    report.section(
        "1. Truth world",
        &format!(
            "Scenario <b>{}</b>, effects present: {:?}. The campaign was written as a \
             measurement bundle to <code>bundle/</code> and its ground truth to \
             <code>truth.ron</code> (outside the bundle): {} trials, {} marker rows, {} tool \
             rows, a {}-D truth model with {} dofs, generated in {:.1} s.",
            scenario.name,
            truth.effects,
            summary.trials,
            summary.marker_rows,
            summary.tool_rows,
            truth.discretisation.dimension,
            summary.dofs,
            summary.seconds
        ),
        &[],
    );
    Ok(truth)
}

/// Stage 2b: calibrate the camera from the bundle's calibration images,
/// track every trial that has camera frames, and compare the tracks with
/// the bundle's own `markers.csv` (and the calibration with the truth's
/// camera). The later stages use `markers.csv`, which covers every frame;
/// the rendered frames are a subset.
fn track_camera_frames(
    bundle: &LoadedBundle,
    truth: &GroundTruth,
    report: &mut Report,
    bars: &MultiProgress,
) -> Result<(), String> {
    let with_frames: Vec<&str> = bundle
        .campaign
        .trials
        .iter()
        .filter(|t| !t.frames.is_empty())
        .map(|t| t.trial.id.as_str())
        .collect();
    if with_frames.is_empty() {
        return Ok(());
    }
    let bar = spinner(bars, "camera: calibrating from calibration/");
    let Some(calibration) = calibrate_from_bundle(&bundle.root).map_err(|e| e.to_string())? else {
        bar.finish_with_message("camera: frames but no calibration/ folder; not tracked");
        return Ok(());
    };
    // Rectification error over the marker grid: a marker's true pixel
    // (the truth's calibration) mapped back through ours.
    let rest = bundle.campaign.markers_rest.as_slice();
    let rectification = truth.camera.as_ref().map(|camera| {
        let errors: Vec<f64> = rest
            .iter()
            .filter_map(|m| {
                let point = nalgebra::Vector2::new(m.x, m.y);
                let pixel = camera.calibration.face_to_pixel(point).ok()?;
                let back = calibration.pixel_to_face(pixel).ok()?;
                Some((back - point).norm())
            })
            .collect();
        rms(&errors)
    });
    let metres_per_pixel = rest
        .first()
        .and_then(|m| {
            calibration
                .face_per_pixel(nalgebra::Vector2::new(m.x, m.y))
                .ok()
        })
        .map_or(f64::NAN, |j| j.column(0).norm());
    let mut rows = Vec::new();
    for id in &with_frames {
        bar.set_message(format!("camera: tracking {id}"));
        let tracked = track_trial(bundle, id, &calibration, &frame_rate(bundle, id))
            .map_err(|e| e.to_string())?;
        let given = bundle.trial(id).and_then(|t| t.markers.as_ref());
        let mut differences = Vec::new();
        if let Some(given) = given {
            let frames: std::collections::HashMap<u64, _> =
                given.frames().map(|f| (f.frame, f)).collect();
            for row in &tracked.observations {
                if let Some(p) = frames.get(&row.frame).and_then(|f| f.position(row.id)) {
                    differences.push(row.x - p[0]);
                    differences.push(row.y - p[1]);
                }
            }
        }
        let frame_count = bundle.trial(id).map_or(0, |t| t.frames.len());
        rows.push(vec![
            id.to_string(),
            frame_count.to_string(),
            tracked.observations.len().to_string(),
            tracked.lost.len().to_string(),
            format!("{:.2}", rms(&differences) * 1e6),
            format!("{:.4}", rms(&differences) / metres_per_pixel),
        ]);
    }
    bar.finish_with_message(format!(
        "camera: calibrated (reprojection {:.4} px), {} trials tracked",
        calibration.reprojection_rms,
        with_frames.len()
    ));
    let noise = bundle.campaign.noise.map_or(f64::NAN, |n| n.marker_sigma);
    report.section(
        "2b. Camera frames: calibration and tracking",
        &format!(
            "The camera was calibrated from the bundle's dot-grid images \
             (<code>needle_vision::calibrate_dot_grid</code>, perspective bias of the dot \
             centres corrected): reprojection RMS {:.4} px, fx {:.2} px, k1 {:.4}; a pixel is \
             {:.1} um on the top face. {} Each trial with frames was tracked \
             (ZNCC search, inverse-compositional Gauss-Newton refinement on a B-spline) and \
             compared with the bundle's <code>markers.csv</code> rows of the same frames, \
             which carry the stated marker noise of {:.1} um per coordinate: the RMS \
             difference per coordinate is that noise plus the tracking error. The later \
             stages use <code>markers.csv</code>, which has every frame.",
            calibration.reprojection_rms,
            calibration.camera.intrinsics.fx,
            calibration.camera.distortion.k1,
            metres_per_pixel * 1e6,
            rectification.map_or(String::new(), |e| format!(
                "Against the truth's camera, the rectified marker grid is off by {:.3} um RMS \
                 ({:.4} px).",
                e * 1e6,
                e / metres_per_pixel
            )),
            noise * 1e6
        ),
        &[],
    );
    report.table(
        "2c. Tracked trials",
        &[
            "trial",
            "frames",
            "marker rows tracked",
            "marker-frames lost",
            "RMS tracked - markers.csv (um)",
            "same (px)",
        ],
        &rows,
    );
    Ok(())
}

fn rms(values: &[f64]) -> f64 {
    (values.iter().map(|v| v * v).sum::<f64>() / values.len().max(1) as f64).sqrt()
}

/// Stage 2: the measured deformation at the deepest frame of the first
/// needle insertion.
fn measured_deformation(
    bundle: &LoadedBundle,
    folder: &OutputFolder,
    report: &mut Report,
) -> Result<(), String> {
    let campaign = &bundle.campaign;
    let Some(trial) = campaign
        .trials
        .iter()
        .find(|t| t.trial.kind == TrialKind::Needle && t.markers.is_some())
    else {
        return Ok(());
    };
    let Some(track) = &trial.markers else {
        return Ok(());
    };
    let Some(last) = track.frames().last() else {
        return Ok(());
    };
    let Some(entry) = trial.tool.first() else {
        return Ok(());
    };
    let tip = trial
        .tool
        .iter()
        .rev()
        .find(|s| s.t <= last.t)
        .unwrap_or(entry);
    let mut rest = Vec::new();
    let mut displacement = Vec::new();
    for (id, position) in last.iter() {
        if let Some(marker) = campaign.markers_rest.get(id) {
            rest.push([marker.x, marker.y]);
            displacement.push([position[0] - marker.x, position[1] - marker.y]);
        }
    }
    let phantom = &campaign.phantom;
    let svg = plot::marker_displacements(
        &rest,
        &displacement,
        (phantom.width, phantom.depth),
        ([entry.tip_x, 0.0], [tip.tip_x, tip.tip_y]),
        &format!(
            "Measured marker displacements, {} at t = {:.1} s",
            trial.trial.id, last.t
        ),
    )?;
    folder.write("measured-deformation.svg", &svg)?;
    report.section(
        "2. The measurements",
        &format!(
            "{} trials, {} markers. The bundle was validated before anything else ran \
             ({} warnings).",
            campaign.trials.len(),
            campaign.markers_rest.len(),
            bundle.warnings.warnings().count()
        ),
        &[svg],
    );
    Ok(())
}

/// Stage 3: E and nu from the probing trials (eq. 5).
fn identify(
    bundle: &LoadedBundle,
    truth: &GroundTruth,
    report: &mut Report,
    bars: &MultiProgress,
) -> Result<Material, String> {
    let bar = spinner(
        bars,
        "identification: E and nu from the probing trials (3-D slab model)",
    );
    // The truth is a 3-D slab: the plane model would misread nu (see
    // docs/identification.md); the force record is smoothed over +-0.5 s.
    let options = IdentifyOptions {
        plane: PlaneModel::Slab,
        refinement: 1,
        force_window: Some(0.5),
        ..IdentifyOptions::default()
    };
    let fit = identify_material(bundle, &options).map_err(|e| format!("identification: {e}"))?;
    bar.finish_with_message(format!(
        "identification: E = {:.1} Pa, nu = {:.4}",
        fit.youngs_modulus.value, fit.poisson_ratio.value
    ));
    let interval = |e: &needle_identify::Estimate, scale: f64, digits: usize| match e.interval {
        Some((lo, hi)) => format!("{:.digits$} .. {:.digits$}", lo * scale, hi * scale),
        None => "not determined".into(),
    };
    // The truth's modulus on the probing days (it drifts when the phantom
    // stiffens over days).
    let probe_moduli: Vec<f64> = truth
        .trials
        .iter()
        .filter(|t| {
            bundle
                .trial(&t.id)
                .is_some_and(|data| data.trial.kind == TrialKind::Probe)
        })
        .filter_map(|t| t.youngs_moduli.first().copied())
        .collect();
    let true_modulus = if probe_moduli.is_empty() {
        truth.scenario.phantom.youngs_modulus
    } else {
        probe_moduli.iter().sum::<f64>() / probe_moduli.len() as f64
    };
    let true_material = &truth.scenario.phantom;
    report.table(
        "3. Material identification from probing (eq. 5)",
        &["parameter", "identified", "95% interval", "truth"],
        &[
            vec![
                "E (kPa)".into(),
                format!("{:.3}", fit.youngs_modulus.value * 1e-3),
                interval(&fit.youngs_modulus, 1e-3, 3),
                format!("{:.3}", true_modulus * 1e-3),
            ],
            vec![
                "nu".into(),
                format!("{:.4}", fit.poisson_ratio.value),
                interval(&fit.poisson_ratio, 1.0, 4),
                format!("{:.4}", true_material.poisson_ratio),
            ],
            vec![
                "chi2 / dof".into(),
                format!("{:.2}", fit.reduced_chi2),
                String::new(),
                "1 if the model matched the truth".into(),
            ],
        ],
    );
    if fit.poisson_ratio.value < 0.45 {
        report.section(
            "Warning: the plane model fits only outside the physical range",
            &format!(
                "The identified Poisson ratio {:.3} is far below the 0.45 to 0.5 of PVC \
                 phantoms, with chi2/dof {:.1}: the 2-D plane model is missing physics that \
                 the data contain (for a thin slab, typically out-of-plane deformation). \
                 The force inversion below uses these constants as the paper's method would.",
                fit.poisson_ratio.value, fit.reduced_chi2
            ),
            &[],
        );
    }
    Material::new(fit.youngs_modulus.value, fit.poisson_ratio.value)
        .map_err(|e| format!("identified material: {e}"))
}

/// Keeps about `count` frames of an insertion, evenly spread, always the last.
fn thin_frames(insertion: &Insertion, count: usize) -> Insertion {
    let mut thinned = insertion.clone();
    let total = insertion.frames.len();
    if total > count {
        let step = total.div_ceil(count);
        thinned.frames = insertion
            .frames
            .iter()
            .enumerate()
            .filter(|(i, _)| (total - 1 - i).is_multiple_of(step))
            .map(|(_, f)| f.clone())
            .collect();
    }
    thinned
}

/// Stage 4: shaft force inversion, plane (paper) and 3-D slab (corrected).
fn invert_forces(
    bundle: &LoadedBundle,
    material: Material,
    quick: bool,
    folder: &OutputFolder,
    report: &mut Report,
    bars: &MultiProgress,
) -> Result<(), String> {
    let campaign = &bundle.campaign;
    let mut needle_trials: Vec<_> = campaign
        .trials
        .iter()
        .filter(|t| t.trial.kind == TrialKind::Needle && t.markers.is_some())
        .map(|t| (t.trial.id.clone(), t.trial.velocity))
        .collect();
    // One insertion per velocity (the first repeat) keeps the run short.
    needle_trials.sort_by(|a, b| a.1.total_cmp(&b.1));
    needle_trials.dedup_by(|a, b| a.1 == b.1);
    if quick {
        needle_trials.truncate(2);
    }
    if needle_trials.is_empty() {
        return Ok(());
    }
    let field = MaterialField::Homogeneous(material);
    let regularisation = match campaign.noise {
        Some(noise) => Regularisation::MarginalLikelihood {
            sigma: noise.marker_sigma,
        },
        None => Regularisation::Gcv,
    };
    let bar = bars.add(ProgressBar::new(needle_trials.len() as u64));
    bar.set_style(
        ProgressStyle::with_template("force inversion [{bar:30}] {pos}/{len} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut rows = Vec::new();
    let mut plane_series = Vec::new();
    let mut slab_series = Vec::new();
    let mut per_velocity = Vec::new();
    let mut first_distributions = Vec::new();
    for (id, velocity) in &needle_trials {
        bar.set_message(id.clone());
        let force_error = |e: needle_force::ForceError| format!("force inversion of {id}: {e}");
        let insertion = thin_frames(
            &observe_insertion(bundle, id).map_err(force_error)?,
            FRAMES_PER_INSERTION,
        );
        let plane = integrated_vs_base(&insertion, &field, Method::PaperNodal(PlaneKind::Strain))
            .map_err(force_error)?;
        let distributions =
            shaft_force_distributions(&insertion, &field, EstimatorOptions::slab(regularisation))
                .map_err(force_error)?;
        let slab = IntegratedSeries {
            trial: id.clone(),
            method: "3-D slab, regularised (eq. 6)".into(),
            points: distributions
                .iter()
                .map(|d| IntegratedPoint {
                    t: d.t,
                    depth: d.length,
                    integrated: d.integrated,
                    integrated_sigma: d.integrated_sigma,
                    base_force: d.base_force,
                    flagged: d.is_flagged(),
                })
                .collect(),
        };
        let percent =
            |value: Option<f64>| value.map_or("-".into(), |v| format!("{:+.1}", v * 100.0));
        rows.push(vec![
            id.clone(),
            format!("{:.0}", velocity * 1e3),
            percent(plane.mean_relative_error(MIN_DEPTH)),
            percent(slab.mean_relative_error(MIN_DEPTH)),
            percent(slab.max_relative_error(MIN_DEPTH)),
            slab.points.iter().filter(|p| p.flagged).count().to_string(),
        ]);
        if first_distributions.is_empty() {
            first_distributions = distributions.clone();
        }
        per_velocity.push((*velocity, distributions));
        plane_series.push(plane);
        slab_series.push(slab);
        bar.inc(1);
    }
    bar.finish_with_message("done");

    let plot_error = |e: needle_force::ForceError| format!("force figures: {e}");
    let mut figures = Vec::new();
    figures.push(
        plot_integrated_vs_base(
            "Integrated shaft force against base force, plane model (Fig. 11)",
            &plane_series[..1],
        )
        .map_err(plot_error)?,
    );
    figures.push(
        plot_integrated_vs_base(
            "Integrated shaft force against base force, 3-D slab (Fig. 13)",
            &slab_series[..1],
        )
        .map_err(plot_error)?,
    );
    let curves: Vec<ShaftCurve> = first_distributions
        .iter()
        .rev()
        .step_by(3)
        .map(|d| ShaftCurve {
            label: format!("depth {:.0} mm", d.length * 1e3),
            s: d.stations.clone(),
            values: d.density.clone(),
        })
        .collect();
    figures.push(
        plot_shaft_distributions(
            "Shaft force density along the needle, 3-D slab (Fig. 10b)",
            "N/m",
            &curves,
        )
        .map_err(plot_error)?,
    );
    // Short (quick) insertions may have no frame deep enough for the
    // density window; the figure is then left out and the report says why.
    let velocity_note = if per_velocity.len() > 1 {
        match density_vs_velocity(&per_velocity, ShaftWindow::default()) {
            Ok(points) => {
                figures.push(plot_density_vs_velocity(&points).map_err(plot_error)?);
                String::new()
            }
            Err(reason) => format!(" No shaft density against velocity figure: {reason}."),
        }
    } else {
        String::new()
    };
    for (index, svg) in figures.iter().enumerate() {
        folder.write(&format!("force-{}.svg", index + 1), svg)?;
    }
    report.section(
        "4. Needle shaft force inversion (eqs. 4 and 6)",
        &format!(
            "Material from stage 3. The paper's plane method sums f = K u over the shaft \
             nodes; the 3-D slab estimate solves eq. (6) as a regularised linear least-squares \
             problem ({}). Errors are the relative difference between the integrated shaft \
             force and the measured base force, over frames deeper than {:.0} mm. Flagged \
             frames are those whose fit did not reach the stated noise.{velocity_note}",
            match regularisation {
                Regularisation::Discrepancy { .. } => "weight by the discrepancy principle",
                Regularisation::MarginalLikelihood { .. } => {
                    "weight and tip prior by the marginal likelihood, the discrepancy \
                     principle where the model does not reach the noise"
                }
                _ => "weight by generalised cross-validation",
            },
            MIN_DEPTH * 1e3
        ),
        &figures,
    );
    report.table(
        "Integrated shaft force against the measured base force",
        &[
            "trial",
            "velocity (mm/s)",
            "plane, mean error (%)",
            "3-D slab, mean error (%)",
            "3-D slab, worst error (%)",
            "flagged frames",
        ],
        &rows,
    );
    Ok(())
}

/// Stage 5: the diagnosis loop from the paper's baseline, and the fitted
/// model's simulation of every insertion against the measured markers.
/// The model's needle has the radius of the instrument the campaign used.
fn diagnose_stage(
    folder: &OutputFolder,
    quick: bool,
    needle_radius: f64,
    report: &mut Report,
    bars: &MultiProgress,
) -> Result<(), String> {
    let bar = spinner(bars, "diagnosis: fit, rank the missing effects, add, refit");
    let options = DiagnoseOptions {
        add_recommended: true,
        frames_per_trial: if quick { 2 } else { DIAGNOSIS_FRAMES_PER_TRIAL },
        // Refinement 1 misfits by its own mesh at about the level the
        // model reaches once `out_of_plane` is in, and named
        // `layered_stiffness`, which is not hidden, on the quick campaign.
        refinement: DIAGNOSIS_REFINEMENT,
        needle_radius,
        slab_needle_grading: !quick,
        ..DiagnoseOptions::default()
    };
    let run = diagnose(&folder.file("bundle"), &ModelSpec::baseline(), &options)
        .map_err(|e| format!("diagnosis: {e}"))?;
    bar.finish_with_message(format!(
        "diagnosis: model {:?}, verdict {:?}",
        run.diagnosis.model, run.diagnosis.verdict
    ));
    bars.suspend(|| print_ladder(&run));
    write_outputs(&run, &folder.file("diagnosis")).map_err(|e| format!("diagnosis: {e}"))?;
    add_sections(report, &run, "5.")?;
    // Fig. 16: node error of the fitted model's simulation of each insertion.
    let mut rows = Vec::new();
    for (index, id) in run.trial_ids.iter().enumerate() {
        let errors: Vec<f64> = run
            .marker_residuals
            .iter()
            .filter(|r| r.trial == index && r.tip_depth > 0.0)
            .map(|r| r.rx.hypot(r.ry))
            .collect();
        if errors.is_empty() {
            continue;
        }
        let mean = errors.iter().sum::<f64>() / errors.len() as f64;
        let max = errors.iter().copied().fold(0.0, f64::max);
        rows.push(vec![
            id.clone(),
            errors.len().to_string(),
            format!("{:.4}", mean * 1e3),
            format!("{:.4}", max * 1e3),
        ]);
    }
    report.table(
        "6. Simulated insertions against the measurements (the paper's Fig. 16; \
         in-sample: the fitted model's residuals)",
        &[
            "insertion",
            "marker positions compared",
            "mean node error (mm; paper 0.6)",
            "max node error (mm; paper 1.4)",
        ],
        &rows,
    );
    Ok(())
}
