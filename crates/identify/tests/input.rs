//! Bad input gives a typed error or a flagged result, never a confident
//! wrong number; and the bundle path reads what the array path fits.

mod support;

use needle_fem::mesh::Face;
use needle_identify::{
    FitFlag, IdentifyError, IdentifyOptions, extract_probe_data, identify_from_data,
    identify_material,
};
use support::Scenario;

/// A small campaign (9 x 9 markers, T6 truth 2x finer) for fast checks.
fn small() -> Scenario {
    Scenario {
        markers_per_side: 9,
        truth_refinement: 2,
        frames_per_trial: 2,
        ..Scenario::paper()
    }
}

#[test]
fn too_few_markers_is_an_error() {
    let mut data = small().probe_data(4e-6, 2);
    data.setup.markers.truncate(2);
    for frame in &mut data.frames {
        frame.displacements.retain(|d| d.marker < 2);
    }
    let error = identify_from_data(&data, &IdentifyOptions::default()).unwrap_err();
    assert!(
        matches!(error, IdentifyError::TooFewMarkers { found: 2, .. }),
        "{error}"
    );
}

#[test]
fn markers_all_near_the_probe_are_too_few() {
    let mut data = small().probe_data(4e-6, 3);
    let huge = IdentifyOptions {
        exclusion_radius: Some(1.0),
        ..IdentifyOptions::default()
    };
    let error = identify_from_data(&data, &huge).unwrap_err();
    assert!(
        matches!(error, IdentifyError::TooFewMarkers { found: 0, .. }),
        "{error}"
    );
    data.frames.clear();
    let error = identify_from_data(&data, &IdentifyOptions::default()).unwrap_err();
    assert!(
        matches!(error, IdentifyError::NoContactFrames { .. }),
        "{error}"
    );
}

#[test]
fn zero_force_is_an_error() {
    let mut data = small().probe_data(4e-6, 4);
    for frame in &mut data.frames {
        frame.force = [0.0, 0.0];
    }
    let error = identify_from_data(&data, &IdentifyOptions::default()).unwrap_err();
    assert!(
        matches!(error, IdentifyError::NoContactFrames { .. }),
        "{error}"
    );
}

#[test]
fn reversed_force_has_no_elastic_response() {
    let mut data = small().probe_data(4e-6, 5);
    for frame in &mut data.frames {
        frame.force = [-frame.force[0], -frame.force[1]];
    }
    let error = identify_from_data(&data, &IdentifyOptions::default()).unwrap_err();
    assert!(
        matches!(error, IdentifyError::NoElasticResponse { .. }),
        "{error}"
    );
}

#[test]
fn no_fixed_face_or_probe_on_fixed_face_is_an_error() {
    let mut data = small().probe_data(4e-6, 6);
    data.setup.fixed.clear();
    let error = identify_from_data(&data, &IdentifyOptions::default()).unwrap_err();
    assert!(matches!(error, IdentifyError::Inconsistent(_)), "{error}");
    data.setup.fixed = vec![Face::Front];
    let error = identify_from_data(&data, &IdentifyOptions::default()).unwrap_err();
    assert!(matches!(error, IdentifyError::LoadPoint { .. }), "{error}");
}

#[test]
fn tip_far_inside_is_an_error() {
    let mut data = small().probe_data(4e-6, 7);
    data.frames[0].tip = [0.0375, 0.0375];
    let error = identify_from_data(&data, &IdentifyOptions::default()).unwrap_err();
    assert!(matches!(error, IdentifyError::LoadPoint { .. }), "{error}");
}

#[test]
fn bad_options_are_named() {
    let data = small().probe_data(4e-6, 8);
    let options = IdentifyOptions {
        poisson_bounds: (0.0, 0.5),
        ..IdentifyOptions::default()
    };
    let error = identify_from_data(&data, &options).unwrap_err();
    assert!(error.to_string().contains("poisson_bounds"), "{error}");
    let options = IdentifyOptions {
        refinement: 0,
        ..IdentifyOptions::default()
    };
    assert!(
        identify_from_data(&data, &options)
            .unwrap_err()
            .to_string()
            .contains("refinement")
    );
}

#[test]
fn unknown_noise_is_estimated_and_flagged() {
    let mut data = small().probe_data(4e-6, 9);
    data.marker_sigma = None;
    let fit = identify_from_data(&data, &IdentifyOptions::default()).unwrap();
    let sigma = fit
        .flags
        .iter()
        .find_map(|f| {
            if let FitFlag::NoiseEstimated { sigma } = f {
                Some(*sigma)
            } else {
                None
            }
        })
        .expect("noise flagged as estimated");
    // Discretisation error adds to the 4 µm noise, so the estimate is at
    // least the noise and not wildly above it on this small model.
    assert!(sigma > 3e-6 && sigma < 4e-5, "sigma estimate {sigma:e}");
    assert!(fit.youngs_modulus.standard_error.is_some());
}

#[test]
fn bundle_path_matches_array_path_and_skips_bad_trials() {
    let scenario = small();
    let data = scenario.probe_data(4e-6, 10);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bundle");
    scenario.write_bundle(&data, &path);
    let bundle = needle_data::read_bundle(&path).unwrap();
    let options = IdentifyOptions::default();
    let (extracted, flags) = extract_probe_data(&bundle, &options).unwrap();
    assert!(flags.is_empty(), "{flags:?}");
    assert_eq!(
        extracted.frames.len(),
        data.frames.len(),
        "rest frame excluded, every loaded frame kept"
    );
    for (a, b) in extracted.frames.iter().zip(&data.frames) {
        for c in 0..2 {
            assert!(
                (a.force[c] - b.force[c]).abs() < 1e-12,
                "force interpolated at the frame time"
            );
        }
        assert_eq!(a.displacements.len(), b.displacements.len());
        for (p, q) in a.displacements.iter().zip(&b.displacements) {
            assert_eq!(p.marker, q.marker);
            assert!((p.displacement[0] - q.displacement[0]).abs() < 1e-12);
        }
    }
    let from_bundle = identify_material(&bundle, &options).unwrap();
    let from_arrays = identify_from_data(&data, &options).unwrap();
    let relative = from_bundle.youngs_modulus.value / from_arrays.youngs_modulus.value - 1.0;
    assert!(relative.abs() < 1e-6, "{relative:e}");

    // A trial whose force is zero throughout is skipped and flagged.
    let mut campaign = bundle.campaign.clone();
    for sample in &mut campaign.trials[0].tool {
        sample.fx = 0.0;
        sample.fy = 0.0;
    }
    let zero = dir.path().join("zero-force");
    needle_data::write_bundle(&zero, &campaign, needle_data::WriteOptions::default()).unwrap();
    let bundle = needle_data::read_bundle(&zero).unwrap();
    let fit = identify_material(&bundle, &options).unwrap();
    assert!(
        fit.flags
            .iter()
            .any(|f| matches!(f, FitFlag::TrialSkipped { trial, .. } if trial == "probe-01"))
    );
    assert_eq!(fit.trials.len(), data.trials.len() - 1);

    // No trial in contact at all: an error that lists why.
    for trial in &mut campaign.trials {
        for sample in &mut trial.tool {
            sample.fx = 0.0;
            sample.fy = 0.0;
        }
    }
    let none = dir.path().join("no-contact");
    needle_data::write_bundle(&none, &campaign, needle_data::WriteOptions::default()).unwrap();
    let bundle = needle_data::read_bundle(&none).unwrap();
    let error = identify_material(&bundle, &options).unwrap_err();
    assert!(
        matches!(error, IdentifyError::NoContactFrames { .. }),
        "{error}"
    );
    assert!(error.to_string().contains("probe-04"), "{error}");
}

#[test]
fn fit_round_trips_through_ron_and_scales_with_the_data() {
    let data = small().probe_data(4e-6, 15);
    let options = IdentifyOptions::default();
    let fit = identify_from_data(&data, &options).unwrap();
    let text = ron::to_string(&fit).unwrap();
    let back: needle_identify::MaterialFit = ron::from_str(&text).unwrap();
    assert_eq!(back, fit);
    assert!(fit.to_string().contains("Young's modulus"));

    // Displacements twice as large (noise included) mean a body half as
    // stiff with the same Poisson's ratio: the modulus enters in closed form.
    let mut doubled = data.clone();
    for frame in &mut doubled.frames {
        for d in &mut frame.displacements {
            d.displacement = [2.0 * d.displacement[0], 2.0 * d.displacement[1]];
        }
    }
    doubled.marker_sigma = data.marker_sigma.map(|s| 2.0 * s);
    let half = identify_from_data(&doubled, &options).unwrap();
    assert!((2.0 * half.youngs_modulus.value / fit.youngs_modulus.value - 1.0).abs() < 1e-6);
    assert!((half.poisson_ratio.value - fit.poisson_ratio.value).abs() < 1e-6);
}

mod properties {
    use needle_data::ToolSample;
    use needle_fem::mesh::Face;
    use needle_identify::{ProbeSetup, project_to_boundary, sample_at};
    use proptest::prelude::*;

    fn setup() -> ProbeSetup {
        ProbeSetup {
            width: 0.075,
            depth: 0.05,
            thickness: 0.0075,
            fixed: vec![Face::Back],
            markers: Vec::new(),
        }
    }

    proptest! {
        /// A projected load point lies on a free side of the phantom, no
        /// farther from the tip than the tip is from any side.
        #[test]
        fn load_points_lie_on_a_free_side(x in -0.01f64..0.085, y in -0.01f64..0.06) {
            let s = setup();
            if let Ok(p) = project_to_boundary(&s, [x, y]) {
                let on_side = p[0] == 0.0 || p[0] == s.width || p[1] == 0.0;
                prop_assert!(on_side, "{p:?}");
                prop_assert!(p[1] < s.depth);
                let cx = x.clamp(0.0, s.width);
                let cy = y.clamp(0.0, s.depth);
                let nearest = cx.min(s.width - cx).min(cy).min(s.depth - cy);
                let distance = (p[0] - cx).hypot(p[1] - cy);
                prop_assert!((distance - nearest).abs() < 1e-12);
            }
        }

        /// Interpolated tool samples lie between the samples around them,
        /// and none exist outside the record.
        #[test]
        fn tool_interpolation_is_bracketed(forces in proptest::collection::vec(-1.0f64..1.0, 2..8), t in -1.0f64..10.0) {
            let tool: Vec<ToolSample> = forces
                .iter()
                .enumerate()
                .map(|(k, &f)| ToolSample { t: k as f64, tip_x: 0.0, tip_y: 0.0, theta: 0.0, fx: f, fy: -f, mz: 0.0 })
                .collect();
            let last = (tool.len() - 1) as f64;
            match sample_at(&tool, t) {
                None => prop_assert!(t < 0.0 || t > last),
                Some(s) => {
                    let k = (t.floor() as usize).min(tool.len() - 1);
                    let j = (t.ceil() as usize).min(tool.len() - 1);
                    let (lo, hi) = (tool[k].fx.min(tool[j].fx), tool[k].fx.max(tool[j].fx));
                    prop_assert!(s.fx >= lo - 1e-15 && s.fx <= hi + 1e-15);
                    prop_assert!((s.fx + s.fy).abs() < 1e-15);
                }
            }
        }
    }
}
