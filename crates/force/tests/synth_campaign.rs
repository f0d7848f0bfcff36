//! The 3-D correction on needle-synth's default campaign: the integrated
//! shaft force against the base force at every frame past 10 mm, and the
//! density against the truth's known density. Slow (minutes), so ignored;
//! run with
//!
//! ```text
//! cargo test -p needle-force --test synth_campaign -- --ignored --nocapture
//! ```

use needle_data::{LoadedBundle, read_bundle};
use needle_force::{
    EstimatorOptions, FollowOptions, Insertion, MaterialField, Regularisation, ShaftDistribution,
    distribution_error, observe_insertion, shaft_force_distributions, tip_following_distributions,
};
use needle_identify::{IdentifyOptions, PlaneModel, identify_material};
use needle_synth::{Scenario, generate};

/// The default campaign's physics (out-of-plane, velocity-dependent
/// friction, the tip peak, stiffening over days), its four probes on day 1
/// and one insertion at 3 mm/s on day 2; no camera images (the markers are
/// read from the truth with the tracker's noise).
fn scenario() -> Scenario {
    let mut scenario = Scenario::paper_default();
    scenario.name = "force-check".into();
    scenario.compression = None;
    scenario.frames = None;
    scenario.needles.velocities = vec![0.003];
    scenario.needles.days = vec![2.0];
    scenario
}

fn generated(scenario: &Scenario, dir: &tempfile::TempDir) -> LoadedBundle {
    let (path, truth) = (dir.path().join("bundle"), dir.path().join("truth.ron"));
    generate(scenario, &path, &truth, |_| {}).unwrap();
    read_bundle(&path).unwrap()
}

/// The truth's density (N/m of needle) at distance `d` behind the tip, for
/// the one insertion of `scenario` (needle-synth's shaft model).
fn truth_density(scenario: &Scenario) -> impl Fn(f64) -> f64 {
    let plan = scenario.needles.plan()[0];
    let effects = &scenario.effects;
    let velocity = effects.velocity_dependent_friction.map_or(1.0, |f| {
        f.factor(plan.velocity, scenario.shaft.reference_velocity)
    });
    let density = scenario.shaft.density * velocity;
    let tip = effects.tip_cutting_force;
    move |d: f64| density * tip.map_or(1.0, |t| t.factor(d))
}

/// The axial base force at time `t` from a straight line fitted to the
/// tool samples within +-`half` s: the sensor's noise and steps averaged
/// over about 2 * half * 100 samples (the force grows linearly at a
/// constant velocity, so the fit is unbiased).
fn fitted_base_force(bundle: &LoadedBundle, trial: &str, t: f64, half: f64) -> f64 {
    let samples: Vec<(f64, f64)> = bundle
        .campaign
        .trial(trial)
        .unwrap()
        .tool
        .iter()
        .filter(|s| (s.t - t).abs() <= half)
        .map(|s| (s.t - t, -s.fx * s.theta.sin() + s.fy * s.theta.cos()))
        .collect();
    let n = samples.len() as f64;
    let (st, sf) = samples
        .iter()
        .fold((0.0, 0.0), |(a, b), (t, f)| (a + t, b + f));
    let (mt, mf) = (st / n, sf / n);
    let (mut stt, mut stf) = (0.0, 0.0);
    for (t, f) in &samples {
        stt += (t - mt) * (t - mt);
        stf += (t - mt) * (f - mf);
    }
    mf - stf / stt * mt
}

/// The two estimators compared: the discrepancy principle with the
/// uniform first-difference prior (before session 6), and the marginal
/// likelihood choosing the weight and the tip prior together.
fn estimators(sigma: f64) -> [(&'static str, EstimatorOptions); 2] {
    [
        (
            "discrepancy, uniform prior",
            EstimatorOptions::slab(Regularisation::Discrepancy { sigma }),
        ),
        (
            "marginal likelihood, tip prior",
            EstimatorOptions::slab(Regularisation::MarginalLikelihood { sigma }),
        ),
    ]
}

/// The truth's material on the day of the campaign's first insertion.
fn true_material(scenario: &Scenario) -> needle_fem::material::Material {
    let day = scenario.needles.days[0];
    let stiffening = scenario
        .effects
        .material_stiffening
        .map_or(1.0, |s| s.factor(day));
    needle_fem::material::Material::new(
        scenario.phantom.youngs_modulus * stiffening,
        scenario.phantom.poisson_ratio,
    )
    .unwrap()
}

/// Estimates every 30th frame past 5 mm (about 1 mm of depth apart at
/// 3 mm/s) with each of [`estimators`] and prints the tables of
/// `docs/force-inversion.md`: per estimator the largest |error| past
/// 10 mm against the raw and the fitted base force, and the largest and
/// mean density error past 10 mm.
fn measure(scenario: &Scenario, bundle: &LoadedBundle, field: &MaterialField, sigma: f64) {
    let needle = bundle
        .campaign
        .trials
        .iter()
        .find(|t| t.trial.kind == needle_data::TrialKind::Needle)
        .unwrap()
        .trial
        .id
        .clone();
    let insertion = observe_insertion(bundle, &needle).unwrap();
    let thinned = every_nth_frame_past_5_mm(&insertion, 30);
    let truth = truth_density(scenario);
    for (name, options) in estimators(sigma) {
        println!("{name}:");
        let distributions = shaft_force_distributions(&thinned, field, options).unwrap();
        summarise(bundle, &needle, &distributions, &truth);
    }
    tip_following(bundle, &needle, &insertion, field, sigma, &truth);
}

/// Every `n`th camera frame of `insertion` with the tip past 5 mm.
fn every_nth_frame_past_5_mm(insertion: &Insertion, n: usize) -> Insertion {
    let mut thinned = insertion.clone();
    thinned.frames = insertion
        .frames
        .iter()
        .filter(|f| f.tip[1] > 5e-3)
        .step_by(n)
        .cloned()
        .collect();
    thinned
}

/// The tip-following estimator at the same frames: every 5th camera frame
/// past 5 mm (about 0.5 mm of depth apart) is a candidate, and the frames
/// of the table (every 6th of these) are shown from the profile pooled
/// over the candidates within one marker spacing of depth (the default),
/// over every candidate, or over every candidate past 10 mm of tip depth;
/// unexplained frames dropped by the rule.
fn tip_following(
    bundle: &LoadedBundle,
    needle: &str,
    insertion: &Insertion,
    field: &MaterialField,
    sigma: f64,
    truth: &impl Fn(f64) -> f64,
) {
    let dense = every_nth_frame_past_5_mm(insertion, 5);
    let options = EstimatorOptions::slab(Regularisation::MarginalLikelihood { sigma });
    let shown: Vec<f64> = dense.frames.iter().step_by(6).map(|f| f.t).collect();
    // The same candidates from 10 mm of tip depth on.
    let mut deep = dense.clone();
    deep.frames.retain(|f| f.tip[1] > 10e-3);
    for (name, candidates, window_spacings) in [
        (
            "tip-following, pooled within one marker spacing (default)",
            &dense,
            Some(1.0),
        ),
        ("tip-following, every frame pooled", &dense, None),
        (
            "tip-following, every frame past 10 mm of tip depth pooled",
            &deep,
            None,
        ),
    ] {
        println!("{name} ({} candidate frames):", candidates.frames.len());
        let follow = FollowOptions {
            window_spacings,
            ..FollowOptions::default()
        };
        let targets: Vec<usize> = (0..candidates.frames.len())
            .filter(|&k| shown.contains(&candidates.frames[k].t))
            .collect();
        let started = std::time::Instant::now();
        let distributions =
            tip_following_distributions(candidates, field, options, follow, &targets).unwrap();
        println!("  {:.1} s", started.elapsed().as_secs_f64());
        summarise(bundle, needle, &distributions, truth);
    }
}

fn summarise(
    bundle: &LoadedBundle,
    needle: &str,
    distributions: &[ShaftDistribution],
    truth: &impl Fn(f64) -> f64,
) {
    let (mut raw, mut fitted, mut density): (f64, f64, f64) = (0.0, 0.0, 0.0);
    let mut densities = Vec::new();
    for d in distributions {
        let base = fitted_base_force(bundle, needle, d.t, 0.25);
        let length = d.length;
        let e = distribution_error(d, |s| truth(length - s));
        let (raw_error, fitted_error) =
            (d.integrated / d.base_force - 1.0, d.integrated / base - 1.0);
        if d.length > 10e-3 {
            raw = raw.max(raw_error.abs());
            fitted = fitted.max(fitted_error.abs());
            density = density.max(e.density);
            densities.push(e.density);
        }
        print_row(d, base, raw_error, fitted_error, e.density);
    }
    let mean = densities.iter().sum::<f64>() / densities.len().max(1) as f64;
    println!(
        "largest past 10 mm: |error| vs raw base {raw:.4}, vs fitted base {fitted:.4}; density L2 error {density:.3} (mean {mean:.3})"
    );
}

fn print_row(d: &ShaftDistribution, base: f64, raw: f64, fitted: f64, density: f64) {
    println!(
        "inserted {:5.1} mm  entry offset {:.2} mm  tip X ({:.2}, {:.2}) mm  moved {:.0e} m  F {:.4} N  base raw {:.4} fitted {:.4}  error raw {:+.4} fitted {:+.4}  density L2 {:.3}  {:?}, tip zone {:.1} mm x {:e}",
        d.length * 1e3,
        d.entry_offset * 1e3,
        d.material_tip[0] * 1e3,
        d.material_tip[1] * 1e3,
        d.placement_change,
        d.integrated,
        d.base_force,
        base,
        raw,
        fitted,
        density,
        d.choice,
        d.tip_zone.zone * 1e3,
        d.tip_zone.relaxation
    );
}

#[test]
#[ignore = "generates a 3-D campaign; minutes"]
fn slab_correction_with_identified_material() {
    let scenario = scenario();
    let dir = tempfile::tempdir().unwrap();
    let bundle = generated(&scenario, &dir);
    // As the pipeline identifies (xtask/src/pipeline.rs), with this
    // crate's default probe model (the fitted flat punch).
    let fit = identify_material(
        &bundle,
        &IdentifyOptions {
            plane: PlaneModel::Slab,
            refinement: 1,
            force_window: Some(0.5),
            ..IdentifyOptions::default()
        },
    )
    .unwrap();
    println!("{fit}");
    let day = scenario.needles.days[0];
    let rate = scenario
        .effects
        .material_stiffening
        .map_or(0.0, |s| s.rate_per_day);
    println!(
        "truth E on the needle day {:.1} Pa (probes on day 1: {:.1} Pa)",
        scenario.phantom.youngs_modulus * (1.0 + rate * day),
        scenario.phantom.youngs_modulus * (1.0 + rate)
    );
    let material =
        needle_fem::material::Material::new(fit.youngs_modulus.value, fit.poisson_ratio.value)
            .unwrap();
    let sigma = bundle.campaign.noise.unwrap().marker_sigma;
    measure(
        &scenario,
        &bundle,
        &MaterialField::Homogeneous(material),
        sigma,
    );
}

/// The estimator alone: exact sensors (marker noise `MARKER_SIGMA`, no
/// force noise or steps) and the truth's modulus on the needle day, so
/// that what remains is the estimator's own error.
#[test]
#[ignore = "generates a 3-D campaign; minutes"]
fn slab_correction_with_the_true_material_and_exact_sensors() {
    for marker_sigma in [1e-8, 4e-6] {
        let mut scenario = scenario();
        scenario.sensors.marker_sigma = marker_sigma;
        scenario.sensors.force_sigma = 0.0;
        scenario.sensors.force_resolution = 0.0;
        let dir = tempfile::tempdir().unwrap();
        let bundle = generated(&scenario, &dir);
        let material = true_material(&scenario);
        println!("marker noise {marker_sigma:e} m, exact base force, true E and nu:");
        measure(
            &scenario,
            &bundle,
            &MaterialField::Homogeneous(material),
            marker_sigma,
        );
    }
}

/// The 4 um case of [`slab_correction_with_the_true_material_and_exact_sensors`]
/// with two other seeds of the campaign's noise: whether the figures of
/// one noise draw hold for others.
#[test]
#[ignore = "generates two 3-D campaigns; minutes"]
fn the_4_um_figures_over_other_noise_draws() {
    for offset in [1, 2] {
        let mut scenario = scenario();
        scenario.seed += offset;
        scenario.sensors.marker_sigma = 4e-6;
        scenario.sensors.force_sigma = 0.0;
        scenario.sensors.force_resolution = 0.0;
        let dir = tempfile::tempdir().unwrap();
        let bundle = generated(&scenario, &dir);
        let material = true_material(&scenario);
        println!(
            "seed {}: marker noise 4 um, exact base force, true E and nu:",
            scenario.seed
        );
        measure(
            &scenario,
            &bundle,
            &MaterialField::Homogeneous(material),
            4e-6,
        );
    }
}
