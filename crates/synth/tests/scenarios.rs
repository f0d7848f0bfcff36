//! Scenario files: the stored fixtures agree with the built-in presets,
//! and bad files give typed errors naming the file, line and field.

use std::path::PathBuf;

use needle_synth::{
    EffectId, LocalRefinement, Resolution, Scenario, SlabGrading, SynthError, load_scenario,
};

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/scenarios")
        .join(format!("{name}.ron"))
}

#[test]
fn stored_fixtures_equal_the_presets() {
    let mut presets = vec![
        Scenario::paper_default(),
        Scenario::paper_default_fine(),
        Scenario::quick(),
        Scenario::null(),
        Scenario::two_effects(),
    ];
    presets.extend(EffectId::ALL.into_iter().map(Scenario::effect_alone));
    for preset in presets {
        let loaded =
            load_scenario(fixture(&preset.name)).unwrap_or_else(|e| panic!("{}: {e}", preset.name));
        assert_eq!(
            loaded, preset,
            "fixture {} differs from its preset",
            preset.name
        );
    }
}

#[test]
fn effect_alone_scenarios_hold_exactly_one_effect() {
    for id in EffectId::ALL {
        assert_eq!(Scenario::effect_alone(id).effects.present(), vec![id]);
    }
    assert!(Scenario::null().effects.present().is_empty());
    assert_eq!(Scenario::two_effects().effects.present().len(), 2);
    assert_eq!(
        Scenario::paper_default().effects.present(),
        vec![
            EffectId::OutOfPlane,
            EffectId::VelocityDependentFriction,
            EffectId::TipCuttingForce,
            EffectId::MaterialStiffening
        ]
    );
}

#[test]
fn default_campaign_follows_the_paper() {
    let s = Scenario::paper_default();
    assert_eq!(
        (s.phantom.width, s.phantom.depth, s.phantom.thickness),
        (0.075, 0.075, 0.0075)
    );
    assert_eq!(
        (
            s.phantom.youngs_modulus,
            s.phantom.poisson_ratio,
            s.phantom.markers
        ),
        (25_300.0, 0.48, (21, 21))
    );
    assert!(s.probes.len() >= 4);
    assert_eq!(
        s.needles.velocities,
        vec![0.001, 0.003, 0.005, 0.007, 0.009]
    );
    // Every insertion on its own line.
    let lines: Vec<f64> = s.needles.plan().iter().map(|p| p.line).collect();
    assert!(lines.windows(2).all(|w| w[1] - w[0] > 0.004), "{lines:?}");
    let test = s.compression.unwrap();
    assert_eq!((test.side, test.height), (0.03, 0.01));
}

fn write_temp(text: &str) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.ron");
    std::fs::write(&path, text).unwrap();
    (dir, path)
}

#[test]
fn unknown_field_is_named_with_its_line() {
    let text = Scenario::null().to_ron().replace(
        "poisson_ratio: 0.48,",
        "poisson_ratio: 0.48,\n        colour: 3,",
    );
    let (_dir, path) = write_temp(&text);
    match load_scenario(&path) {
        Err(SynthError::Parse {
            path: p,
            line,
            message,
            ..
        }) => {
            assert_eq!(p, path);
            assert!(message.contains("colour"), "{message}");
            let expected = text.lines().position(|l| l.contains("colour")).unwrap() + 1;
            assert_eq!(line, expected);
        }
        other => panic!("expected a parse error, got {other:?}"),
    }
}

#[test]
fn missing_field_is_named() {
    let text = Scenario::null()
        .to_ron()
        .replace("        seed: 2005,\n", "")
        .replace("    seed: 2005,\n", "");
    let (_dir, path) = write_temp(&text);
    match load_scenario(&path) {
        Err(SynthError::Parse { message, .. }) => assert!(message.contains("seed"), "{message}"),
        other => panic!("expected a parse error, got {other:?}"),
    }
}

#[test]
fn out_of_range_value_names_the_dotted_field() {
    let text = Scenario::null()
        .to_ron()
        .replace("poisson_ratio: 0.48", "poisson_ratio: 0.5");
    let (_dir, path) = write_temp(&text);
    let line_of = |text: &str, needle: &str| {
        text.lines().position(|l| l.contains(needle)).unwrap() as u64 + 1
    };
    let error = load_scenario(&path).unwrap_err();
    let shown = error.to_string();
    let SynthError::InvalidField {
        source_name,
        field,
        line,
        ..
    } = error
    else {
        panic!("expected an invalid field, got {error:?}");
    };
    assert_eq!(field, "phantom.poisson_ratio");
    assert!(source_name.contains("bad.ron"));
    let expected = line_of(&text, "poisson_ratio: 0.5");
    assert_eq!(line, Some(expected));
    assert!(
        shown.contains(&format!(
            "bad.ron:{expected}: field `phantom.poisson_ratio`"
        )),
        "{shown}"
    );
    // An element of a list is reported at its list's line.
    let text = Scenario::null()
        .to_ron()
        .replace("days: [", "days: [-1.0, ");
    let (_dir, path) = write_temp(&text);
    match load_scenario(&path) {
        Err(SynthError::InvalidField { field, line, .. }) => {
            assert_eq!(field, "needles.days[0]");
            assert_eq!(line, Some(line_of(&text, "days: [-1.0")));
        }
        other => panic!("expected an invalid field, got {other:?}"),
    }
    let mut s = Scenario::null();
    s.needles.line_spacing = 0.01;
    let e = s.validate("memory").unwrap_err();
    assert!(
        matches!(e, SynthError::InvalidField { ref field, .. } if field == "needles.first_line"),
        "{e}"
    );
    for radius in [-1e-4, 0.25 * 0.0075, f64::NAN] {
        let mut s = Scenario::paper_default();
        s.needles.radius = radius;
        let e = s.validate("memory").unwrap_err();
        assert!(
            matches!(e, SynthError::InvalidField { ref field, .. } if field == "needles.radius"),
            "{e}"
        );
    }
    // A probe's rounded edges: inside half its width, and only where the
    // truth solves contact (the neo-Hookean material).
    for (effect, radius) in [
        (EffectId::MaterialNonlinearity, 0.0),
        (EffectId::MaterialNonlinearity, -1e-4),
        (EffectId::MaterialNonlinearity, f64::NAN),
        (EffectId::MaterialNonlinearity, 0.0021),
        (EffectId::LayeredStiffness, 0.0005),
    ] {
        let mut s = Scenario::effect_alone(effect);
        s.probes[1].width = 0.004;
        s.probes[1].edge_radius = Some(radius);
        let e = s.validate("memory").unwrap_err();
        assert!(
            matches!(e, SynthError::InvalidField { ref field, .. } if field == "probes[1].edge_radius"),
            "{effect:?} {radius}: {e}"
        );
    }
    let mut s = Scenario::effect_alone(EffectId::MaterialNonlinearity);
    s.probes[1].width = 0.004;
    s.probes[1].edge_radius = Some(0.002);
    s.validate("memory").unwrap();
    let mut s = Scenario::effect_alone(EffectId::LayeredStiffness);
    s.effects.layered_stiffness.as_mut().unwrap().moduli.pop();
    let e = s.validate("memory").unwrap_err();
    assert!(
        matches!(e, SynthError::InvalidField { ref field, .. } if field == "effects.layered_stiffness.moduli"),
        "{e}"
    );
    let too_fine = [
        SlabGrading {
            mid_plane: SlabGrading::MAX_LEVELS + 1,
            ..SlabGrading::DEFAULT
        },
        SlabGrading {
            top_face: SlabGrading::MAX_LEVELS + 1,
            ..SlabGrading::DEFAULT
        },
        SlabGrading {
            probe_edges: SlabGrading::MAX_LEVELS + 1,
            ..SlabGrading::DEFAULT
        },
    ];
    type SetGrading = fn(&mut Resolution, SlabGrading);
    let fields: [(&str, SetGrading); 3] = [
        ("resolution.slab_grading", |r, g| r.slab_grading = Some(g)),
        ("resolution.marker_grading", |r, g| {
            r.marker_grading = Some(g)
        }),
        ("resolution.probe_grading", |r, g| r.probe_grading = Some(g)),
    ];
    for (name, set) in fields {
        for grading in too_fine {
            let mut s = Scenario::paper_default();
            set(&mut s.resolution, grading);
            let e = s.validate("memory").unwrap_err();
            assert!(
                matches!(e, SynthError::InvalidField { ref field, .. } if field == name),
                "{name}, {grading:?}: {e}"
            );
        }
    }
    let local = LocalRefinement {
        refinement: None,
        needle_paths: 2,
        needle_ends: 4,
        back_face: 2,
        probe_edges: 2,
        far_field: 0,
        plan_only: false,
        grading: 1.0,
    };
    let bad_local = [
        (
            LocalRefinement {
                needle_ends: SlabGrading::MAX_LEVELS + 1,
                ..local
            },
            "local",
        ),
        (
            LocalRefinement {
                far_field: SlabGrading::MAX_LEVELS + 1,
                ..local
            },
            "local",
        ),
        (
            LocalRefinement {
                refinement: Some(0),
                ..local
            },
            "local.refinement",
        ),
        (
            LocalRefinement {
                grading: LocalRefinement::GRADING.0 / 2.0,
                ..local
            },
            "local.grading",
        ),
        (
            LocalRefinement {
                grading: f64::NAN,
                ..local
            },
            "local.grading",
        ),
    ];
    for (name, set) in fields {
        for (bad, part) in bad_local {
            let mut s = Scenario::paper_default();
            let grading = SlabGrading {
                local: Some(bad),
                ..SlabGrading::DEFAULT
            };
            set(&mut s.resolution, grading);
            let e = s.validate("memory").unwrap_err();
            let expected = format!("{name}.{part}");
            assert!(
                matches!(e, SynthError::InvalidField { ref field, .. } if *field == expected),
                "{expected}, {bad:?}: {e}"
            );
        }
    }
    let mut s = Scenario::null();
    s.resolution.plane_grading = Some(Resolution::MAX_PLANE_GRADING + 1);
    let e = s.validate("memory").unwrap_err();
    assert!(
        matches!(e, SynthError::InvalidField { ref field, .. } if field == "resolution.plane_grading"),
        "{e}"
    );
    s.resolution.plane_grading = Some(Resolution::MAX_PLANE_GRADING);
    s.validate("memory").unwrap();
}

/// The field `s` is refused for, failing unless it is refused.
fn refused_field(s: &Scenario) -> String {
    match s.validate("memory") {
        Err(SynthError::InvalidField { field, .. }) => field,
        other => panic!("expected an invalid field, got {other:?}"),
    }
}

#[test]
fn stiffening_keeps_the_modulus_in_range_on_every_day_used() {
    // The file names the first day used, the compression test's (day 6),
    // where 1 - 0.19 * 6 is negative.
    let text = Scenario::paper_default()
        .to_ron()
        .replace("rate_per_day: 0.012", "rate_per_day: -0.19");
    let (_dir, path) = write_temp(&text);
    match load_scenario(&path) {
        Err(SynthError::InvalidField {
            source_name, field, ..
        }) => {
            assert_eq!(field, "compression.day");
            assert!(source_name.contains("bad.ron"));
        }
        other => panic!("expected an invalid field, got {other:?}"),
    }
    let softening = |s: &mut Scenario, rate: f64| {
        s.effects.material_stiffening.as_mut().unwrap().rate_per_day = rate;
    };
    let mut s = Scenario::paper_default();
    softening(&mut s, -0.19);
    s.compression.as_mut().unwrap().day = 1.0;
    s.needles.days = vec![2.0, 4.0];
    s.probes[2].day = 4.0;
    // 1 - 0.19 * 4 = 0.24: soft, but a solid.
    s.validate("memory").unwrap();
    s.needles.days = vec![2.0, 10.0];
    assert_eq!(refused_field(&s), "needles.days[1]");
    s.needles.days = vec![2.0];
    s.probes[2].day = 4.8;
    assert_eq!(refused_field(&s), "probes[2].day");
    // Tenfold and more.
    let mut s = Scenario::paper_default();
    softening(&mut s, 0.5);
    s.probes[1].day = 19.0;
    assert_eq!(refused_field(&s), "probes[1].day");
    // Without stiffening the same day is only a day.
    s.effects.material_stiffening = None;
    s.validate("memory").unwrap();
}

#[test]
fn days_beyond_ten_years_are_refused() {
    let mut s = Scenario::null();
    s.probes[0].day = Scenario::MAX_DAY;
    s.validate("memory").unwrap();
    for day in [
        Scenario::MAX_DAY + 1.0,
        1e300,
        f64::INFINITY,
        -1.0,
        f64::NAN,
    ] {
        let mut s = Scenario::null();
        s.probes[0].day = day;
        assert_eq!(refused_field(&s), "probes[0].day", "{day}");
        let mut s = Scenario::null();
        s.needles.days[0] = day;
        assert_eq!(refused_field(&s), "needles.days[0]", "{day}");
        let mut s = Scenario::null();
        s.compression.as_mut().unwrap().day = day;
        assert_eq!(refused_field(&s), "compression.day", "{day}");
    }
}

#[test]
fn needle_rims_stay_clear_of_the_side_faces() {
    let s = Scenario::paper_default();
    let (radius, width) = (s.needles.radius, s.phantom.width);
    let lines = s.needles.plan().len() as f64;
    let span = (lines - 1.0) * s.needles.line_spacing;
    // The audit's line 0.1 mm from the side, inside the needle's radius.
    for first in [1e-4, radius, width - span - radius, width - span - 1e-4] {
        let mut s = s.clone();
        s.needles.first_line = first;
        assert_eq!(refused_field(&s), "needles.first_line", "{first}");
    }
    for first in [radius + 1e-5, width - span - radius - 1e-5] {
        let mut s = s.clone();
        s.needles.first_line = first;
        s.validate("memory").unwrap();
    }
}

#[test]
fn insertion_lines_are_a_needle_diameter_apart() {
    let s = Scenario::paper_default();
    let diameter = 2.0 * s.needles.radius;
    for spacing in [1e-9, diameter - 1e-6] {
        let mut s = s.clone();
        s.needles.line_spacing = spacing;
        assert_eq!(refused_field(&s), "needles.line_spacing", "{spacing}");
    }
    let mut s = s.clone();
    s.needles.line_spacing = diameter;
    s.validate("memory").unwrap();
}

#[test]
fn sizes_that_would_exhaust_memory_are_refused() {
    type Change = fn(&mut Scenario);
    let cases: [(Change, &str); 10] = [
        (
            |s| s.compression.as_mut().unwrap().samples = Scenario::MAX_ROWS + 1,
            "compression.samples",
        ),
        (|s| s.sensors.force_rate = 1e12, "sensors.force_rate"),
        (|s| s.sensors.camera_rate = 1e12, "sensors.camera_rate"),
        (|s| s.probes[0].velocity = 1e-12, "probes[0].velocity"),
        (|s| s.needles.velocities[0] = 1e-12, "needles.velocities[0]"),
        // Half the highest rate: a probe's 3 s are 1.5 million samples,
        // an insertion's 50 s 25 million.
        (
            |s| s.sensors.force_rate = 0.5 * needle_synth::scenario::Sensors::MAX_RATE,
            "needles.velocities[0]",
        ),
        // 30 001 frames of 441 markers.
        (|s| s.sensors.camera_rate = 1e4, "probes[0].velocity"),
        (|s| s.resolution.shaft_step = 1e-15, "resolution.shaft_step"),
        (|s| s.resolution.depth_step = 1e-12, "resolution.depth_step"),
        (
            |s| s.resolution.indentation_step = 1e-12,
            "resolution.indentation_step",
        ),
    ];
    for (change, name) in cases {
        let mut s = Scenario::paper_default();
        change(&mut s);
        assert_eq!(refused_field(&s), name);
    }
    // Just within: as many steps as accepted.
    let mut s = Scenario::paper_default();
    s.resolution.shaft_step = s.needles.depth / Resolution::MAX_STEPS as f64;
    s.resolution.depth_step = s.resolution.shaft_step;
    s.compression.as_mut().unwrap().samples = Scenario::MAX_ROWS;
    s.validate("memory").unwrap();
}

#[test]
fn a_phantom_softer_than_a_pascal_is_refused() {
    let text = Scenario::null()
        .to_ron()
        .replace("youngs_modulus: 25300.0", "youngs_modulus: 1e-300");
    let (_dir, path) = write_temp(&text);
    match load_scenario(&path) {
        Err(SynthError::InvalidField {
            source_name, field, ..
        }) => {
            assert_eq!(field, "phantom.youngs_modulus");
            assert!(source_name.contains("bad.ron"));
        }
        other => panic!("expected an invalid field, got {other:?}"),
    }
    for modulus in [0.5, 0.0, f64::INFINITY, f64::NAN] {
        let mut s = Scenario::null();
        s.phantom.youngs_modulus = modulus;
        assert_eq!(refused_field(&s), "phantom.youngs_modulus", "{modulus}");
    }
    let mut s = Scenario::null();
    s.phantom.youngs_modulus = 1.0;
    s.validate("memory").unwrap();
}

#[test]
fn an_overflowing_shaft_load_is_a_typed_error_not_a_panic() {
    // A small plane-strain campaign of one insertion whose shaft load
    // overflows the phantom's field: the needle's material points cannot
    // be found, which must fail as a Newton failure, not a panic. (The tip
    // peak of 1e300 that found the panic is now refused at load, below.)
    let mut s = Scenario::effect_alone(EffectId::TipCuttingForce);
    s.phantom.markers = (6, 6);
    s.resolution.refinement = 1;
    s.resolution.depth_step = 0.005;
    s.resolution.shaft_step = 0.002;
    s.probes.clear();
    s.compression = None;
    s.needles.velocities = vec![0.009];
    s.needles.days = vec![2.0];
    s.needles.depth = 0.02;
    s.shaft.density = 1e300;
    match needle_synth::respond(&s) {
        Err(e @ SynthError::NoConvergence { .. }) => {
            let text = e.to_string();
            assert!(
                text.contains("material point of the needle shaft"),
                "{text}"
            );
            assert!(text.contains("the needle on the line x = "), "{text}");
        }
        other => panic!("expected a Newton failure, got {:?}", other.err()),
    }
}

#[test]
fn a_tip_peak_or_a_layer_beyond_a_solid_s_range_is_refused() {
    let mut s = Scenario::effect_alone(EffectId::TipCuttingForce);
    for (amplitude, refused) in [(1.0, false), (99.0, false), (100.0, true), (1e300, true)] {
        s.effects.tip_cutting_force.as_mut().unwrap().amplitude = amplitude;
        let result = s.validate("memory");
        assert_eq!(result.is_err(), refused, "{amplitude}: {result:?}");
        if refused {
            assert_eq!(refused_field(&s), "effects.tip_cutting_force.amplitude");
        }
    }
    let mut s = Scenario::effect_alone(EffectId::LayeredStiffness);
    s.effects.layered_stiffness.as_mut().unwrap().moduli[1] = 1e-300;
    assert_eq!(refused_field(&s), "effects.layered_stiffness.moduli[1]");
}

#[test]
fn a_byte_order_mark_is_skipped() {
    let text = format!("\u{feff}{}", Scenario::null().to_ron());
    let (_dir, path) = write_temp(&text);
    assert_eq!(load_scenario(&path).unwrap(), Scenario::null());
    // Only at the start: anywhere else it is a stray character.
    let text = Scenario::null().to_ron().replace("seed:", "\u{feff}seed:");
    let (_dir, path) = write_temp(&text);
    assert!(matches!(
        load_scenario(&path),
        Err(SynthError::Parse { .. })
    ));
}

#[test]
fn missing_file_is_an_io_error_naming_it() {
    let e = load_scenario("/nonexistent/scenario.ron").unwrap_err();
    assert!(matches!(e, SynthError::Io { .. }));
    assert!(e.to_string().contains("/nonexistent/scenario.ron"));
}
