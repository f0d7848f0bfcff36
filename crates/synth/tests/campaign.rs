//! Whole campaigns on a small plane-strain phantom: the bundle reads back,
//! the ground truth is written outside it, generation is deterministic by
//! seed, the measured force and tracks carry the stated noise, and each
//! effect changes what it should.

use std::path::Path;

use needle_data::{TrialKind, read_bundle};
use needle_synth::truth::Discretisation;
use needle_synth::{
    EffectId, Effects, LocalRefinement, Scenario, SlabGrading, SynthError, generate, respond,
};

/// The paper phantom with a coarse mesh, few markers, short trials.
fn small() -> Scenario {
    let mut s = Scenario::null();
    s.name = "small".into();
    s.phantom.markers = (6, 6);
    s.resolution.refinement = 1;
    s.resolution.depth_step = 0.005;
    s.resolution.shaft_step = 0.002;
    s.probes.truncate(1);
    s.needles.velocities = vec![0.009];
    s.needles.days = vec![2.0, 4.0];
    s.needles.depth = 0.02;
    s.compression.as_mut().unwrap().samples = 5;
    s
}

fn files(root: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                out.push((
                    path.strip_prefix(root).unwrap().display().to_string(),
                    std::fs::read(&path).unwrap(),
                ));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn a_campaign_without_insertions_writes_its_probes_alone() {
    for effects in [Effects::none(), Effects::none().with(EffectId::OutOfPlane)] {
        let mut s = small();
        s.needles.velocities.clear();
        s.effects = effects;
        s.validate("memory").unwrap();
        let dir = tempfile::tempdir().unwrap();
        let bundle = dir.path().join("bundle");
        generate(&s, &bundle, &dir.path().join("truth.ron"), |_| {}).unwrap();
        let campaign = read_bundle(&bundle).unwrap().campaign;
        let kinds: Vec<TrialKind> = campaign.trials.iter().map(|t| t.trial.kind).collect();
        assert_eq!(kinds, [TrialKind::Probe]);
        assert!(campaign.trials[0].markers.as_ref().unwrap().frame_count() > 1);
    }
}

/// Generates `s` as the bundle `name` in `dir`: its files, and the
/// discretisation its truth file states.
fn generated(s: &Scenario, dir: &Path, name: &str) -> (Vec<(String, Vec<u8>)>, Discretisation) {
    let bundle = dir.join(name);
    let summary = generate(s, &bundle, &dir.join(format!("{name}.ron")), |_| {}).unwrap();
    (files(&bundle), summary.truth.discretisation)
}

/// The files of two bundles with the same file names whose contents
/// differ, and the names of the files `expected` selects.
fn differing_and_expected<'a>(
    a: &'a [(String, Vec<u8>)],
    b: &[(String, Vec<u8>)],
    expected: impl Fn(&str) -> bool,
) -> (Vec<&'a str>, Vec<&'a str>) {
    let names: Vec<&str> = a.iter().map(|f| f.0.as_str()).collect();
    assert_eq!(names, b.iter().map(|f| f.0.as_str()).collect::<Vec<_>>());
    let differing = a
        .iter()
        .zip(b)
        .filter(|(x, y)| x.1 != y.1)
        .map(|(x, _)| x.0.as_str())
        .collect();
    let expected = names.into_iter().filter(|n| expected(n)).collect();
    (differing, expected)
}

/// With `resolution.marker_grading` the needle trials are settled on the
/// finer mesh: their tracks and tool samples come from there, and the
/// probes' stay on the placement mesh; the truth file says how large the
/// finer mesh was (or, refined locally, each insertion's own).
#[test]
fn a_slab_campaign_settles_its_needles_on_its_marker_mesh() {
    let mut placed = small();
    placed.effects = Effects::none().with(EffectId::OutOfPlane);
    placed.resolution.layers = 2;
    let mut read_finer = placed.clone();
    read_finer.resolution.marker_grading = Some(SlabGrading {
        faces: 3,
        needle_lines: 2,
        mid_plane: 1,
        top_face: 2,
        probe_edges: 0,
        local: None,
    });
    let dir = tempfile::tempdir().unwrap();
    let (alone, mesh) = generated(&placed, dir.path(), "alone");
    let (finer, finer_mesh) = generated(&read_finer, dir.path(), "finer");
    assert_eq!(mesh.marker_mesh_nodes, None);
    assert_eq!(
        (finer_mesh.nodes, finer_mesh.elements),
        (mesh.nodes, mesh.elements)
    );
    assert!(finer_mesh.marker_mesh_nodes.unwrap() > 2 * mesh.nodes);
    // Refined locally, each insertion is settled on a slab of its own,
    // along its own path.
    let mut along_paths = placed.clone();
    along_paths.resolution.marker_grading = Some(SlabGrading {
        faces: 0,
        needle_lines: 0,
        mid_plane: 0,
        top_face: 0,
        probe_edges: 0,
        local: Some(LocalRefinement {
            refinement: None,
            needle_paths: 2,
            needle_ends: 3,
            back_face: 1,
            probe_edges: 0,
            far_field: 0,
            plan_only: false,
            grading: 1.0,
        }),
    });
    let (own, own_mesh) = generated(&along_paths, dir.path(), "own");
    assert_eq!(own_mesh.marker_mesh_nodes, None);
    assert_eq!(
        own_mesh.needle_mesh_nodes.len(),
        placed.needles.plan().len()
    );
    assert!(own_mesh.needle_mesh_nodes.iter().all(|&n| n > mesh.nodes));
    for settled in [&finer, &own] {
        let (differing, needle_files) = differing_and_expected(&alone, settled, |name| {
            name.contains("needle") && (name.contains("markers") || name.contains("tool"))
        });
        assert!(!needle_files.is_empty());
        assert_eq!(
            differing, needle_files,
            "only the needles' tracks and tool samples change"
        );
    }
}

/// With `resolution.probe_grading` each probe's tracks and tool samples
/// come from a slab of its own and every other file stays the same; the
/// truth file gives each probe slab's size.
#[test]
fn a_slab_campaign_presses_its_probes_on_slabs_of_their_own() {
    let mut shared = small();
    shared.effects = Effects::none().with(EffectId::OutOfPlane);
    shared.resolution.layers = 2;
    let mut own = shared.clone();
    own.resolution.probe_grading = Some(SlabGrading {
        probe_edges: 3,
        ..SlabGrading::DEFAULT
    });
    let dir = tempfile::tempdir().unwrap();
    let (on_shared, mesh) = generated(&shared, dir.path(), "shared");
    let (on_own, own_mesh) = generated(&own, dir.path(), "own");
    assert!(mesh.probe_mesh_nodes.is_empty());
    assert_eq!(own_mesh.nodes, mesh.nodes);
    assert_eq!(own_mesh.probe_mesh_nodes.len(), shared.probes.len());
    assert!(own_mesh.probe_mesh_nodes[0] > mesh.nodes);
    let (differing, probe_data) = differing_and_expected(&on_shared, &on_own, |name| {
        name.contains("probe") && !name.ends_with("trial.ron")
    });
    assert!(probe_data.len() >= 2, "the probe's tracks and tool samples");
    assert_eq!(
        differing, probe_data,
        "only the probe's measurements change"
    );
}

#[test]
fn bundle_reads_back_and_truth_lies_beside_it() {
    let dir = tempfile::tempdir().unwrap();
    let (bundle, truth) = (dir.path().join("bundle"), dir.path().join("truth.ron"));
    let summary = generate(&small(), &bundle, &truth, |_| {}).unwrap();
    let loaded = read_bundle(&bundle).unwrap();
    let campaign = &loaded.campaign;
    assert_eq!(campaign.trials.len(), 3);
    assert_eq!(campaign.markers_rest.len(), 36);
    assert_eq!(campaign.trials[0].trial.kind, TrialKind::Probe);
    assert!(campaign.compression.as_ref().unwrap().len() == 5);
    let needle = campaign
        .trials
        .iter()
        .find(|t| t.trial.kind == TrialKind::Needle)
        .unwrap();
    // 20 mm at 9 mm/s: 2.22 s, 100 Hz and 30 Hz.
    assert_eq!(needle.tool.len(), 223);
    assert_eq!(needle.markers.as_ref().unwrap().frame_count(), 67);
    assert!(truth.is_file());
    let text = std::fs::read_to_string(&truth).unwrap();
    let parsed: needle_synth::GroundTruth = ron::from_str(&text).unwrap();
    assert_eq!(parsed, summary.truth);
    assert!(parsed.effects.is_empty());
    // Never overwrite.
    assert!(matches!(
        generate(&small(), &bundle, &dir.path().join("t2.ron"), |_| {}),
        Err(SynthError::Bundle(_))
    ));
    assert!(matches!(
        generate(&small(), &dir.path().join("b2"), &truth, |_| {}),
        Err(SynthError::TruthPath { .. })
    ));
    assert!(matches!(
        generate(
            &small(),
            &dir.path().join("b3"),
            &dir.path().join("b3/truth.ron"),
            |_| {}
        ),
        Err(SynthError::TruthPath { .. })
    ));
}

#[test]
fn the_truth_is_never_led_into_the_bundle_and_a_failed_run_leaves_both_or_neither() {
    let dir = tempfile::tempdir().unwrap();
    let at = |name: &str| dir.path().join(name);
    let refused = |bundle: &Path, truth: &Path| {
        let result = generate(&small(), bundle, truth, |_| {});
        assert!(
            matches!(result, Err(SynthError::TruthPath { .. })),
            "{bundle:?}, {truth:?}: {result:?}"
        );
        assert!(std::fs::symlink_metadata(bundle).is_err() && !truth.exists());
    };
    // Through a folder that does not exist and back out of it.
    refused(&at("b1"), &at("x/../b1/truth.ron"));
    // Through a link made beforehand to the bundle-to-be.
    std::os::unix::fs::symlink("b2", at("link2")).unwrap();
    refused(&at("b2"), &at("link2/truth.ron"));
    std::os::unix::fs::symlink(at("b3/inner"), at("link3")).unwrap();
    refused(&at("b3"), &at("link3/../truth.ron"));
    // A link to nothing where the bundle would go is in the way, before any work.
    std::os::unix::fs::symlink("nowhere", at("dangling")).unwrap();
    assert!(matches!(
        generate(&small(), &at("dangling"), &at("d.ron"), |_| {}),
        Err(SynthError::Bundle(
            needle_data::BundleError::AlreadyExists { .. }
        ))
    ));
    assert!(!at("d.ron").exists());
    // The truth's folder is made; the run writes both files.
    let mut probes_only = small();
    probes_only.needles.velocities.clear();
    probes_only.compression = None;
    let truth = at("new/deeper/truth.ron");
    generate(&probes_only, &at("b4"), &truth, |_| {}).unwrap();
    assert!(truth.is_file() && at("b4/bundle.ron").is_file());
    // A bundle the writer refuses (here: its folder cannot be made, a file
    // being in the way) takes its truth file back.
    std::fs::write(at("file"), "x").unwrap();
    let truth = at("t5.ron");
    assert!(generate(&probes_only, &at("file/b5"), &truth, |_| {}).is_err());
    assert!(!truth.exists(), "no truth without its bundle");
    // A truth that cannot be written fails the run before the bundle is.
    assert!(matches!(
        generate(&probes_only, &at("b6"), &at("file/t6.ron"), |_| {}),
        Err(SynthError::Io { .. })
    ));
    assert!(!at("b6").exists(), "no bundle without its truth");
}

#[test]
fn same_seed_same_bundle_other_seed_other_noise() {
    let dir = tempfile::tempdir().unwrap();
    let mut s = small();
    s.probes.clear();
    s.needles.days = vec![2.0];
    s.compression = None;
    generate(&s, &dir.path().join("a"), &dir.path().join("a.ron"), |_| {}).unwrap();
    generate(&s, &dir.path().join("b"), &dir.path().join("b.ron"), |_| {}).unwrap();
    assert_eq!(files(&dir.path().join("a")), files(&dir.path().join("b")));
    s.seed += 1;
    generate(&s, &dir.path().join("c"), &dir.path().join("c.ron"), |_| {}).unwrap();
    assert_ne!(files(&dir.path().join("a")), files(&dir.path().join("c")));
}

#[test]
fn measurements_carry_the_stated_noise() {
    let dir = tempfile::tempdir().unwrap();
    let mut s = small();
    s.needles.days = vec![2.0];
    s.needles.depth = 0.04;
    s.needles.velocities = vec![0.001];
    s.probes.clear();
    s.compression = None;
    generate(&s, &dir.path().join("b"), &dir.path().join("t.ron"), |_| {}).unwrap();
    let truth = respond(&s).unwrap();
    let campaign = read_bundle(dir.path().join("b")).unwrap().campaign;
    let trial = &campaign.trials[0];
    let sigma = s.sensors.marker_sigma;
    // Markers far from the needle barely move between frames, so frame to
    // frame differences of a still marker (the back row, fixed) are noise.
    let track = trial.markers.as_ref().unwrap();
    let fixed: Vec<u32> = (30..36).collect();
    let mut residuals = Vec::new();
    for frame in track.frames() {
        for &id in &fixed {
            let p = frame.position(id).unwrap();
            let rest = campaign.markers_rest.get(id).unwrap();
            residuals.push(p[0] - rest.x);
            residuals.push(p[1] - rest.y);
        }
    }
    let n = residuals.len() as f64;
    let mean = residuals.iter().sum::<f64>() / n;
    let std = (residuals.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / n).sqrt();
    assert!(n > 5000.0);
    assert!(
        (std / sigma - 1.0).abs() < 0.05,
        "marker std {std} vs sigma {sigma}"
    );
    assert!(mean.abs() < 4.0 * sigma / n.sqrt(), "marker mean {mean}");
    // Force: fx has no true force; readings are multiples of the resolution.
    let stated = campaign.noise.unwrap().force_sigma;
    let fx: Vec<f64> = trial.tool.iter().map(|t| t.fx).collect();
    for f in &fx {
        let k = f / s.sensors.force_resolution;
        assert!(
            (k - k.round()).abs() < 1e-9,
            "{f} is not a multiple of the resolution"
        );
    }
    let rms = (fx.iter().map(|f| f * f).sum::<f64>() / fx.len() as f64).sqrt();
    assert!(
        (rms / stated - 1.0).abs() < 0.1,
        "fx rms {rms} vs stated {stated}"
    );
    // The true base force at the end is the density times the inserted length.
    let last = truth[0].force.last().unwrap();
    assert!(
        *last > 0.9 * s.shaft.density * 0.03 && *last < s.shaft.density * 0.04,
        "{last}"
    );
}

/// The largest change of a final marker displacement and of a final force
/// between two responses.
fn change(a: &[needle_synth::TrialResponse], b: &[needle_synth::TrialResponse]) -> (f64, f64) {
    let mut du = 0.0f64;
    let mut df = 0.0f64;
    for (a, b) in a.iter().zip(b) {
        for (p, q) in a
            .markers
            .last()
            .unwrap()
            .iter()
            .zip(b.markers.last().unwrap())
        {
            du = du.max((p[0] - q[0]).hypot(p[1] - q[1]));
        }
        df = df.max((a.force.last().unwrap() - b.force.last().unwrap()).abs());
    }
    (du, df)
}

#[test]
fn each_physical_effect_changes_what_it_should() {
    let base = small();
    let null = respond(&base).unwrap();
    let marker_sigma = base.sensors.marker_sigma;
    let force_resolution = base.sensors.force_resolution;
    let with = |id: EffectId| {
        let mut s = base.clone();
        s.effects = Effects::none().with(id);
        respond(&s).unwrap()
    };
    // Loads: the force changes; velocity by far more than the sensor
    // resolution, the tip peak by its integral (about 1.7 resolutions,
    // a constant offset over thousands of samples) and clearly in the
    // markers around the tip.
    let (du, df) = change(&with(EffectId::VelocityDependentFriction), &null);
    assert!(
        df > 3.0 * force_resolution && du > 3.0 * marker_sigma,
        "velocity: du {du} df {df}"
    );
    let (du, df) = change(&with(EffectId::TipCuttingForce), &null);
    assert!(
        df > force_resolution && du > 3.0 * marker_sigma,
        "tip: du {du} df {df}"
    );
    // Material and supports: the markers move differently; the needle
    // force (a prescribed shaft load) only through the entry point.
    for id in [
        EffectId::LayeredStiffness,
        EffectId::MaterialStiffening,
        EffectId::CompliantSupport,
        EffectId::PlatformFriction,
    ] {
        let (du, _) = change(&with(id), &null);
        assert!(du > 3.0 * marker_sigma, "{id:?}: du {du}");
    }
    // Lens distortion touches only the written tracks, not the physics.
    let (du, df) = change(&with(EffectId::LensDistortion), &null);
    assert_eq!((du, df), (0.0, 0.0));
}
