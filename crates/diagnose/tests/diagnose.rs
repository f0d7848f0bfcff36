//! End-to-end diagnosis on bundles from a truth world with hidden effects
//! (see `support`): null data, each catalog effect hidden alone, two hidden
//! effects, and an effect outside the catalog.

mod support;

use needle_diagnose::{
    DiagnoseOptions, DiagnosisRun, ModelSpec, NoiseBasis, NoiseSource, Verdict, diagnose,
    write_outputs,
};
use support::{
    FORCE_SIGMA, Hidden, INCLUSION_CENTRE, MARKER_SIGMA, ODD_MARKER_NOISE, PROBE_WIDTH, Written,
    make_bundle, make_bundle_with,
};

fn options(add_recommended: bool, max_added: usize) -> DiagnoseOptions {
    DiagnoseOptions {
        add_recommended,
        max_added,
        refinement: 2,
        ..DiagnoseOptions::default()
    }
}

fn print(run: &DiagnosisRun) {
    for step in &run.steps {
        eprintln!("{:?} {:?} {:?}", step.model, step.verdict, step.fit);
        for c in &step.candidates {
            eprintln!(
                "  {} score {:.2} (p {:.3e}) LR {:?} p {:?}",
                c.effect, c.score, c.score_p, c.likelihood_ratio, c.likelihood_ratio_p
            );
        }
    }
}

#[test]
fn null_data_is_consistent_with_noise_for_five_seeds() {
    let dir = tempfile::tempdir().unwrap();
    for seed in 1..=5 {
        let bundle = make_bundle(dir.path(), &format!("null-{seed}"), Hidden::default(), seed);
        let run = diagnose(&bundle, &ModelSpec::baseline(), &options(false, 0)).unwrap();
        print(&run);
        let d = &run.diagnosis;
        assert_eq!(d.verdict, Verdict::ConsistentWithNoise, "seed {seed}");
        assert!(d.fit.chi2_marker < 1.3 && d.fit.chi2_force < 1.3);
        // The probe's contact patch is fitted, not assumed a point.
        let width = run
            .fitted
            .parameters
            .iter()
            .find(|p| p.name == "probe_width")
            .unwrap();
        let error = (width.value - PROBE_WIDTH).abs();
        let standard_error = width.standard_error.unwrap();
        println!(
            "seed {seed}: probe width {:.3} mm, standard error {:.3} mm",
            width.value * 1e3,
            standard_error * 1e3
        );
        assert!(error < 3.0 * standard_error, "seed {seed}: {width:?}");
    }
}

/// With `hidden` alone, for two seeds: the first verdict names `expected`
/// (ranked first), and after adding it chi-square per dof is at most 1.3 in
/// every channel and lower than before.
fn one_hidden(name: &str, hidden: Hidden, expected: &str) {
    let dir = tempfile::tempdir().unwrap();
    for seed in [11, 12] {
        let bundle = make_bundle(dir.path(), &format!("{name}-{seed}"), hidden, seed);
        let run = diagnose(&bundle, &ModelSpec::baseline(), &options(true, 1)).unwrap();
        print(&run);
        assert_eq!(
            run.steps[0].verdict,
            Verdict::MissingEffect(expected.to_string()),
            "seed {seed}"
        );
        assert_eq!(run.steps[0].candidates[0].effect, expected);
        // The hidden physics explains far more than the model's mesh could.
        let mesh = run.steps[0]
            .discretisation
            .expect("every diagnosis checks its mesh");
        let ratio = run.steps[0].candidates[0].likelihood_ratio.unwrap();
        eprintln!("mesh check {mesh:?}, likelihood ratio {ratio}");
        assert!(mesh.chi2 < ratio, "{mesh:?}");
        assert_eq!(run.steps[0].doubt, None);
        let last = &run.steps[1];
        assert_eq!(last.model, vec![expected.to_string()]);
        assert!(last.fit.chi2_marker <= 1.3, "{:?}", last.fit);
        assert!(last.fit.chi2_force <= 1.3, "{:?}", last.fit);
        assert_eq!(run.ladder.rows.len(), 2);
        assert!(
            run.ladder.rows[1].fit.chi2_marker < run.ladder.rows[0].fit.chi2_marker
                || run.ladder.rows[1].fit.chi2_force < run.ladder.rows[0].fit.chi2_force
        );
        let out = dir.path().join(format!("out-{seed}"));
        write_outputs(&run, &out).unwrap();
        let text = std::fs::read_to_string(out.join("diagnosis.ron")).unwrap();
        assert!(text.starts_with("Diagnosis("), "{text}");
        assert!(text.contains("candidates"));
        let ladder = std::fs::read_to_string(out.join("ladder.csv")).unwrap();
        assert_eq!(ladder.lines().count(), 3);
    }
}

#[test]
fn hidden_tip_cutting_force_is_named_and_fixed() {
    let hidden = Hidden {
        tip_peak: 20.0,
        ..Hidden::default()
    };
    one_hidden("tip", hidden, "tip_cutting_force");
}

#[test]
fn hidden_velocity_dependent_friction_is_named_and_fixed() {
    let hidden = Hidden {
        velocity_slope: 400.0,
        ..Hidden::default()
    };
    one_hidden("velocity", hidden, "velocity_dependent_friction");
}

#[test]
fn hidden_material_stiffening_is_named_and_fixed() {
    let hidden = Hidden {
        stiffening: 0.05,
        ..Hidden::default()
    };
    one_hidden("stiffening", hidden, "material_stiffening");
}

#[test]
fn hidden_compliant_support_is_named_and_fixed() {
    let hidden = Hidden {
        back_springs: 25.0e3 / (0.2 * support::DEPTH),
        ..Hidden::default()
    };
    one_hidden("support", hidden, "compliant_support");
}

#[test]
fn hidden_platform_friction_is_named_and_fixed() {
    let hidden = Hidden {
        platform: 6.0e4,
        ..Hidden::default()
    };
    one_hidden("platform", hidden, "platform_friction");
}

#[test]
fn hidden_lens_distortion_is_named_and_fixed() {
    let hidden = Hidden {
        lens: 4.0e-5,
        ..Hidden::default()
    };
    one_hidden("lens", hidden, "lens_distortion");
}

#[test]
fn hidden_layered_stiffness_is_named_and_fixed() {
    let hidden = Hidden {
        layer_contrast: 0.3,
        ..Hidden::default()
    };
    one_hidden("layers", hidden, "layered_stiffness");
}

#[test]
fn hidden_out_of_plane_is_named_and_fixed() {
    let hidden = Hidden {
        slab: true,
        ..Hidden::default()
    };
    one_hidden("slab", hidden, "out_of_plane");
}

/// The campaign's own loads strain the phantom far enough: the 0.3 N hold
/// on the 3 mm x 7.5 mm patch presses 13 kPa on a 25 kPa phantom, tens of
/// percent under the patch (the unit test of `body` finds the linear model
/// 75 um off a Newton solution at markers 20 mm from a 0.2 N patch), and
/// the best linear fit leaves a marker chi-square per dof near 2.7.
#[test]
fn hidden_material_nonlinearity_is_named_and_fixed() {
    let hidden = Hidden {
        neo_hookean: true,
        ..Hidden::default()
    };
    one_hidden("nonlinear", hidden, "material_nonlinearity");
}

/// The probe frames are weighed with the probe force noise carried to the
/// markers by the model's own responses. An effect can change those a great
/// deal: a foundation under a probing campaign (no needles) takes the
/// baseline's marker misfit from tens of times the noise to the noise.
/// Once the ladder adds it, its frames are weighed by the model with it,
/// and the ladder's fit is the fit of that model given.
#[test]
fn an_added_effect_weighs_the_probe_frames_by_its_own_responses() {
    let dir = tempfile::tempdir().unwrap();
    let hidden = Hidden {
        platform: 2.0e5,
        ..Hidden::default()
    };
    let written = Written {
        needles: false,
        ..Written::default()
    };
    let bundle = make_bundle_with(dir.path(), "probing", hidden, 41, written);
    let ladder = diagnose(&bundle, &ModelSpec::baseline(), &options(true, 1)).unwrap();
    print(&ladder);
    let effect = "platform_friction";
    assert_eq!(
        ladder.steps[0].verdict,
        Verdict::MissingEffect(effect.to_string())
    );
    let spec = ModelSpec::from_ids(&[effect]).unwrap();
    let given = diagnose(&bundle, &spec, &options(false, 0)).unwrap();
    print(&given);
    let (added, fitted) = (&ladder.diagnosis.fit, &given.diagnosis.fit);
    eprintln!("added {added:?}\ngiven {fitted:?}");
    let relative = (added.chi2_marker - fitted.chi2_marker).abs() / fitted.chi2_marker;
    assert!(relative < 1e-3, "chi2/dof {added:?} against {fitted:?}");
    let stiffness = |run: &DiagnosisRun| {
        let p = run
            .fitted
            .parameters
            .iter()
            .find(|p| p.name == "foundation_stiffness");
        let p = p.unwrap();
        (p.value, p.standard_error.unwrap())
    };
    let ((a, _), (b, se)) = (stiffness(&ladder), stiffness(&given));
    assert!((a - b).abs() < 0.1 * se, "{a} against {b} +- {se}");
}

/// A bundle that states no noise: the force noise comes from the sensor's
/// repeated samples, the marker noise from the fit at each step (the
/// frames are holds and depths far apart, so successive frames differ by
/// signal), the hidden effect is still named, and once it is added the
/// marker noise is the true one and the verdict consistent with noise.
#[test]
fn unstated_noise_is_estimated_and_the_hidden_effect_still_named() {
    let dir = tempfile::tempdir().unwrap();
    let hidden = Hidden {
        velocity_slope: 400.0,
        ..Hidden::default()
    };
    let written = Written {
        state_noise: false,
        ..Written::default()
    };
    let bundle = make_bundle_with(dir.path(), "unstated", hidden, 13, written);
    let run = diagnose(&bundle, &ModelSpec::baseline(), &options(true, 1)).unwrap();
    print(&run);
    let NoiseSource::Estimated { marker, force } = &run.steps[0].noise else {
        panic!("{:?}", run.steps[0].noise)
    };
    eprintln!("marker {marker:?}\nforce {force:?}");
    let NoiseBasis::RepeatedSamples(samples) = force.basis else {
        panic!("{force:?}")
    };
    assert!(
        samples.differences > 400 && samples.consistent(),
        "{samples:?}"
    );
    assert!((force.sigma / FORCE_SIGMA - 1.0).abs() < 0.1, "{force:?}");
    let NoiseBasis::Fit {
        repeated_samples: Some(frames),
    } = marker.basis
    else {
        panic!("{marker:?}")
    };
    assert!(!frames.consistent(), "{marker:?}");
    assert_eq!(
        run.steps[0].verdict,
        Verdict::MissingEffect("velocity_dependent_friction".into())
    );
    assert!(run.steps[1].fit.chi2_force <= 1.3, "{:?}", run.steps[1].fit);
    // The marker noise is taken again at the better model's fit, where
    // only the noise is left.
    let NoiseSource::Estimated { marker, .. } = &run.steps[1].noise else {
        panic!("{:?}", run.steps[1].noise)
    };
    eprintln!("after the effect: marker {marker:?}");
    assert!(
        (marker.sigma / MARKER_SIGMA - 1.0).abs() < 0.1,
        "{marker:?}"
    );
    assert_eq!(run.steps[1].verdict, Verdict::ConsistentWithNoise);
}

/// Half the markers tracked three times worse than the stated 8 um: with
/// each row of `markers.csv` giving its own `sx,sy`, null data are weighted
/// by them, fit at chi-square per dof near 1 and are consistent with
/// noise; the same data without them misfit at about the mean of 1 and 9.
#[test]
fn rows_with_their_own_noise_are_weighted_by_it() {
    let dir = tempfile::tempdir().unwrap();
    let fits: Vec<_> = [true, false]
        .into_iter()
        .map(|row_sigmas| {
            let written = Written {
                odd_noise: true,
                row_sigmas,
                ..Written::default()
            };
            let name = format!("rows-{row_sigmas}");
            let bundle = make_bundle_with(dir.path(), &name, Hidden::default(), 17, written);
            let run = diagnose(&bundle, &ModelSpec::baseline(), &options(false, 0)).unwrap();
            print(&run);
            run.diagnosis
        })
        .collect();
    let (weighted, plain) = (&fits[0], &fits[1]);
    assert_eq!(weighted.verdict, Verdict::ConsistentWithNoise);
    assert!(
        (weighted.fit.chi2_marker - 1.0).abs() < 0.1,
        "{:?}",
        weighted.fit
    );
    let expected = 0.5 * (1.0 + ODD_MARKER_NOISE.powi(2));
    assert!(
        (plain.fit.chi2_marker / expected - 1.0).abs() < 0.2,
        "{:?}",
        plain.fit
    );
    assert_ne!(plain.verdict, Verdict::ConsistentWithNoise);
}

#[test]
fn two_hidden_effects_are_found_one_after_the_other() {
    let dir = tempfile::tempdir().unwrap();
    let hidden = Hidden {
        tip_peak: 20.0,
        stiffening: 0.05,
        ..Hidden::default()
    };
    let bundle = make_bundle(dir.path(), "two", hidden, 21);
    let run = diagnose(&bundle, &ModelSpec::baseline(), &options(true, 4)).unwrap();
    print(&run);
    assert_eq!(run.ladder.rows.len(), 3);
    let mut found = run.ladder.rows[2].model.clone();
    found.sort();
    assert_eq!(found, vec!["material_stiffening", "tip_cutting_force"]);
    assert_eq!(run.diagnosis.verdict, Verdict::ConsistentWithNoise);
    assert!(run.diagnosis.fit.chi2_marker <= 1.3 && run.diagnosis.fit.chi2_force <= 1.3);
}

/// A stiff inclusion is in no catalog effect: the verdict must not be
/// `ConsistentWithNoise`, and the residual must concentrate around it.
#[test]
fn an_effect_outside_the_catalog_is_not_explained_away() {
    let dir = tempfile::tempdir().unwrap();
    let hidden = Hidden {
        inclusion: 5.0,
        ..Hidden::default()
    };
    let bundle = make_bundle(dir.path(), "inclusion", hidden, 31);
    let run = diagnose(&bundle, &ModelSpec::baseline(), &options(true, 4)).unwrap();
    print(&run);
    assert_ne!(run.diagnosis.verdict, Verdict::ConsistentWithNoise);
    // RMS residual per marker: the three worst markers lie within two
    // marker spacings of the inclusion, and markers there misfit more than
    // the rest on average.
    let mut energy = std::collections::BTreeMap::<usize, (f64, f64, f64, usize)>::new();
    for r in &run.marker_residuals {
        let e = energy.entry(r.marker).or_insert((r.x, r.y, 0.0, 0));
        e.2 += r.rx * r.rx + r.ry * r.ry;
        e.3 += 1;
    }
    let mut markers: Vec<(f64, f64)> = energy
        .values()
        .map(|&(x, y, sum, n)| {
            let distance = (x - INCLUSION_CENTRE[0]).hypot(y - INCLUSION_CENTRE[1]);
            (distance, (sum / n as f64).sqrt())
        })
        .collect();
    markers.sort_by(|a, b| b.1.total_cmp(&a.1));
    eprintln!("worst markers (distance, rms): {:?}", &markers[..5]);
    for worst in &markers[..3] {
        assert!(worst.0 < 0.02, "a worst marker is {} m away", worst.0);
    }
    let mean = |near: bool| {
        let pick: Vec<f64> = markers
            .iter()
            .filter(|m| (m.0 < 0.02) == near)
            .map(|m| m.1)
            .collect();
        pick.iter().sum::<f64>() / pick.len() as f64
    };
    eprintln!("mean rms near {} far {}", mean(true), mean(false));
    assert!(mean(true) > 1.5 * mean(false));
}

#[test]
fn bad_model_is_a_typed_error() {
    let err = ModelSpec::from_ids(&["no_such_effect"]).unwrap_err();
    assert!(err.to_string().contains("no_such_effect"));
    let err = ModelSpec::from_ids(&["lens_distortion", "lens_distortion"]).unwrap_err();
    assert!(err.to_string().contains("twice"));
}
