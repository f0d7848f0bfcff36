//! Rendered camera frames and calibration images: where they are written,
//! that the bundle with them validates, that tracking the frames gives the
//! true marker positions, and that calibrating from the written images
//! recovers the true camera and the top face's pose.

use std::path::Path;
use std::time::Instant;

use nalgebra::{Vector2, Vector3};
use needle_data::{read_bundle, read_calibration_target, validate_bundle};
use needle_synth::frames::marker_pixel;
use needle_synth::{CameraFrames, EffectId, Effects, Scenario, TrueCamera, generate};
use needle_vision::{
    Calibration, DotGrid, FixedParameters, FrameRate, GreyFrame, Pose, SearchPolicy,
    TrackFramesOptions, TrackOptions, calibrate_dot_grid, track_frames, track_untracked_trials,
};

/// The paper phantom, plane strain, coarse, 6 x 6 markers, noise-free
/// tracks (so that `markers.csv` is the truth); frames of the one probe
/// (one in 15: 7 frames) and of the first needle trial (one in 33: 3).
fn small() -> Scenario {
    let mut s = Scenario::null();
    s.name = "small-frames".into();
    s.phantom.markers = (6, 6);
    s.resolution.refinement = 1;
    s.resolution.depth_step = 0.005;
    s.resolution.shaft_step = 0.002;
    s.sensors.marker_sigma = 0.0;
    s.probes.truncate(1);
    s.needles.velocities = vec![0.009, 0.009];
    s.needles.days = vec![2.0];
    s.needles.depth = 0.02;
    s.needles.first_line = 0.03;
    s.needles.line_spacing = 0.02;
    s.compression = None;
    s.frames = Some(CameraFrames {
        tilted_views: 4,
        ..CameraFrames::paper(1, 15, 1, 33)
    });
    s
}

fn frame_numbers(dir: &Path) -> Vec<u64> {
    let mut numbers: Vec<u64> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let name = e.unwrap().file_name().to_string_lossy().into_owned();
            name.strip_suffix(".png").unwrap().parse().unwrap()
        })
        .collect();
    numbers.sort();
    numbers
}

#[test]
fn frames_are_numbered_like_the_tracks_and_track_back_to_the_truth() {
    let dir = tempfile::tempdir().unwrap();
    let (bundle, truth) = (dir.path().join("bundle"), dir.path().join("truth.ron"));
    let s = small();
    let started = Instant::now();
    let summary = generate(&s, &bundle, &truth, |_| {}).unwrap();
    println!(
        "generated {} frames and {} calibration images in {:.2} s",
        summary.frames,
        s.frames.as_ref().unwrap().tilted_views + 1,
        started.elapsed().as_secs_f64()
    );
    assert_eq!(summary.frames, 7 + 3);
    let report = validate_bundle(&bundle);
    assert!(report.issues.is_empty(), "{report}");
    let loaded = read_bundle(&bundle).unwrap();
    let probe = loaded.trial("probe-01").unwrap();
    let needles: Vec<_> = loaded
        .campaign
        .trials
        .iter()
        .filter(|t| t.trial.id.starts_with("needle"))
        .collect();
    assert_eq!(
        frame_numbers(&loaded.frames_dir("probe-01")),
        vec![0, 15, 30, 45, 60, 75, 90]
    );
    assert_eq!(
        frame_numbers(&loaded.frames_dir(&needles[0].trial.id)),
        vec![0, 33, 66]
    );
    assert!(needles[1].frames.is_empty());
    assert!(!loaded.frames_dir(&needles[1].trial.id).exists());
    let first = GreyFrame::read_png(&loaded.frames_dir("probe-01").join("000000.png")).unwrap();
    assert_eq!((first.width, first.height), (2056, 1544));

    // Track the probe's frames with the true calibration; the noise-free
    // markers.csv holds the true positions of the same frames.
    let camera = TrueCamera::new(&s);
    let calibration = camera.experiment();
    let options = TrackFramesOptions {
        track: TrackOptions {
            search_radius: 12,
            search: SearchPolicy::Always,
            ..TrackOptions::default()
        },
        ..TrackFramesOptions::default()
    };
    let rest: Vec<_> = loaded.campaign.markers_rest.as_slice().to_vec();
    let tracked = track_frames(
        &loaded.frames_dir("probe-01"),
        &calibration,
        &rest,
        &options,
    )
    .unwrap();
    assert!(tracked.lost.is_empty(), "{:?}", tracked.lost);
    let truth = probe.markers.as_ref().unwrap();
    let (mut worst_m, mut worst_px, mut sum_sq, mut count) = (0.0f64, 0.0f64, 0.0, 0.0);
    let mut largest_step = 0.0f64;
    for row in &tracked.observations {
        let frame = truth
            .frames()
            .find(|f| f.frame == row.frame)
            .expect("a rendered frame has rows in markers.csv");
        assert!((frame.t - row.t).abs() < 1e-6);
        let true_position = frame.iter().find(|m| m.0 == row.id).map(|m| m.1).unwrap();
        let error = Vector2::new(row.x - true_position[0], row.y - true_position[1]);
        let true_pixel = marker_pixel(&camera, [true_position[0], true_position[1], 0.0]).unwrap();
        let found_pixel = calibration
            .face_to_pixel(Vector2::new(row.x, row.y))
            .unwrap();
        worst_m = worst_m.max(error.norm());
        worst_px = worst_px.max((found_pixel - true_pixel).norm());
        sum_sq += error.norm_squared();
        count += 1.0;
        if row.frame > 0 {
            let previous = truth.frames().find(|f| f.frame == row.frame - 15).unwrap();
            let before = previous.iter().find(|m| m.0 == row.id).unwrap().1;
            let step = marker_pixel(&camera, [before[0], before[1], 0.0]).unwrap() - true_pixel;
            largest_step = largest_step.max(step.norm());
        }
    }
    println!(
        "tracking vs truth over {count} rows: rms {:.2} um, worst {:.2} um = {worst_px:.3} px; largest step between rendered frames {largest_step:.1} px",
        (sum_sq / count).sqrt() * 1e6,
        worst_m * 1e6
    );
    assert!(worst_px < 0.1, "worst tracking error {worst_px} px");
    assert!(worst_m < 8e-6, "worst tracking error {worst_m} m");
}

/// Copies a bundle folder (files and subfolders).
fn copy_tree(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_tree(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), target).unwrap();
        }
    }
}

/// All files under `root` with their sizes, to see that nothing was written.
fn listing(root: &Path) -> Vec<(std::path::PathBuf, u64)> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(root).unwrap() {
        let entry = entry.unwrap();
        if entry.file_type().unwrap().is_dir() {
            out.extend(listing(&entry.path()));
        } else {
            out.push((entry.path(), entry.metadata().unwrap().len()));
        }
    }
    out.sort();
    out
}

#[test]
fn trials_with_frames_and_no_markers_csv_get_the_tracks_of_their_frames() {
    let dir = tempfile::tempdir().unwrap();
    let (bundle, truth) = (dir.path().join("bundle"), dir.path().join("truth.ron"));
    generate(&small(), &bundle, &truth, |_| {}).unwrap();
    let original = read_bundle(&bundle).unwrap();
    let with_frames: Vec<String> = original
        .campaign
        .trials
        .iter()
        .filter(|t| !t.frames.is_empty())
        .map(|t| t.trial.id.clone())
        .collect();
    assert_eq!(with_frames.len(), 2, "the probe and the first needle trial");
    // A lab's bundle that hands over frames instead of tracks for them.
    let frames_only = dir.path().join("frames-only");
    copy_tree(&bundle, &frames_only);
    for id in &with_frames {
        std::fs::remove_file(frames_only.join("trials").join(id).join("markers.csv")).unwrap();
    }
    let before = listing(&frames_only);
    let mut loaded = read_bundle(&frames_only).unwrap();
    assert!(
        with_frames
            .iter()
            .all(|id| loaded.trial(id).unwrap().markers.is_none())
    );
    let done = track_untracked_trials(&mut loaded).unwrap();
    assert_eq!(
        listing(&frames_only),
        before,
        "nothing written to the bundle"
    );
    assert!(done.uncalibrated.is_empty());
    assert!(done.calibration.is_some());
    let tracked: Vec<&str> = done.tracked.iter().map(|t| t.id.as_str()).collect();
    assert_eq!(tracked, with_frames);
    for line in done.summary() {
        println!("{line}");
    }

    let (mut worst, mut sum_sq, mut rows) = (0.0f64, 0.0, 0usize);
    for t in &done.tracked {
        // The other needle trial still has its markers.csv, at the camera's 30 Hz.
        match &t.rate {
            FrameRate::OtherTrial { rate, .. } => assert!((rate - 30.0).abs() < 1e-4, "{rate}"),
            other => panic!("rate {other:?}"),
        }
        assert_eq!(t.lost, 0);
        let given = original.trial(&t.id).unwrap().markers.as_ref().unwrap();
        let found = loaded.trial(&t.id).unwrap().markers.as_ref().unwrap();
        let found_frames: Vec<_> = found.frames().collect();
        assert_eq!(found_frames.len(), t.frames);
        for frame in found_frames {
            // markers.csv of the scenario is noise-free: the true positions.
            let truth = given
                .frames()
                .find(|f| f.frame == frame.frame)
                .expect("every rendered frame has rows in markers.csv");
            // Times are written to the microsecond.
            assert!((truth.t - frame.t).abs() < 1e-6, "{} {}", truth.t, frame.t);
            for (id, position) in frame.iter() {
                let expected = truth.position(id).unwrap();
                let error = ((position[0] - expected[0]).powi(2)
                    + (position[1] - expected[1]).powi(2))
                .sqrt();
                worst = worst.max(error);
                sum_sq += error * error;
                rows += 1;
            }
        }
        assert!(!found.has_sigma(), "weighed by the bundle's marker noise");
    }
    assert_eq!(rows, (7 + 3) * 36);
    let rms = (sum_sq / rows as f64).sqrt();
    println!(
        "tracked with the bundle's own calibration against the truth over {rows} rows: rms {:.2} um, worst {:.2} um",
        rms * 1e6,
        worst * 1e6
    );
    assert!(worst < 3e-6, "worst {worst} m");

    // Without calibration/ nothing can be tracked: said, and nothing invented.
    std::fs::remove_dir_all(frames_only.join("calibration")).unwrap();
    let mut loaded = read_bundle(&frames_only).unwrap();
    let done = track_untracked_trials(&mut loaded).unwrap();
    assert!(done.tracked.is_empty() && done.calibration.is_none());
    assert_eq!(done.uncalibrated, with_frames);
    assert!(
        with_frames
            .iter()
            .all(|id| loaded.trial(id).unwrap().markers.is_none())
    );
    assert!(done.summary()[0].contains("no calibration/ folder"));
}

#[test]
fn calibrating_from_the_written_images_recovers_the_camera_and_the_face() {
    let dir = tempfile::tempdir().unwrap();
    let (bundle, truth) = (dir.path().join("bundle"), dir.path().join("truth.ron"));
    let mut s = small();
    s.probes.clear();
    s.needles.velocities.truncate(1);
    generate(&s, &bundle, &truth, |_| {}).unwrap();
    let target = read_calibration_target(&bundle).unwrap().unwrap();
    let images: Vec<GreyFrame> = target
        .images
        .iter()
        .map(|name| GreyFrame::read_png(&bundle.join("calibration").join(name)).unwrap())
        .collect();
    let grid = DotGrid {
        columns: target.columns,
        rows: target.rows,
        pitch: target.pitch,
        dot_diameter: target.dot_diameter,
    };
    let started = Instant::now();
    let fit = calibrate_dot_grid(&images, &grid, 4, &FixedParameters::default(), 3).unwrap();
    let seconds = started.elapsed().as_secs_f64();
    // The face pose from the view lying on the face: X_c = R (X_f - o) + t.
    let view = fit.poses[target.face_view];
    let rotation = view.rotation_matrix();
    let origin = Vector3::new(target.face_origin.0, target.face_origin.1, 0.0);
    let face_pose =
        Pose::from_rotation_translation(&rotation, view.translation_vector() - rotation * origin);
    let truth = TrueCamera::new(&s).calibration;
    let found = Calibration {
        camera: fit.camera,
        face_pose,
        reprojection_rms: fit.reprojection_rms,
        ..truth.clone()
    };
    // Every marker-grid point of the face, seen by the true camera, then
    // rectified with the fitted calibration.
    let (mut worst, mut sum_sq, mut n) = (0.0f64, 0.0, 0.0);
    for j in 0..=20 {
        for i in 0..=20 {
            let p = Vector2::new(0.075 * i as f64 / 20.0, 0.075 * j as f64 / 20.0);
            let pixel = truth.face_to_pixel(p).unwrap();
            let error = (found.pixel_to_face(pixel).unwrap() - p).norm();
            worst = worst.max(error);
            sum_sq += error * error;
            n += 1.0;
        }
    }
    let metres_per_pixel = 0.075
        / (truth.face_to_pixel(Vector2::new(0.075, 0.0375)).unwrap()
            - truth.face_to_pixel(Vector2::new(0.0, 0.0375)).unwrap())
        .norm();
    println!(
        "calibration from {} images in {seconds:.2} s: rms {:.4} px, fx {:.2} (true {}), rectified face rms {:.3} um, worst {:.3} um = {:.4} px",
        images.len(),
        fit.reprojection_rms,
        fit.camera.intrinsics.fx,
        truth.camera.intrinsics.fx,
        (sum_sq / n).sqrt() * 1e6,
        worst * 1e6,
        worst / metres_per_pixel
    );
    assert!(
        fit.reprojection_rms < 0.05,
        "rms {} px",
        fit.reprojection_rms
    );
    assert!((fit.camera.intrinsics.fx - truth.camera.intrinsics.fx).abs() < 3.0);
    assert!(worst < 0.05 * metres_per_pixel, "worst {worst} m");
}

#[test]
fn lens_distortion_goes_through_the_experiment_camera() {
    // Rectifying the experiment camera's pixels with the calibrated camera
    // moves a face point at distance rho from where the optical axis meets
    // the face outward by about k1 rho^3, the effect's field.
    let mut s = Scenario::null();
    s.effects = Effects::none().with(EffectId::LensDistortion);
    s.frames = Some(CameraFrames::paper(1, 10, 0, 1));
    s.validate("test").unwrap();
    let k1 = s.effects.lens_distortion.unwrap().k1;
    let camera = TrueCamera::new(&s);
    assert!(camera.experiment_camera.distortion.k1 > camera.calibration.camera.distortion.k1);
    let axis = camera
        .calibration
        .pixel_to_face(Vector2::new(
            camera.calibration.camera.intrinsics.cx,
            camera.calibration.camera.intrinsics.cy,
        ))
        .unwrap();
    println!(
        "optical axis meets the face at ({:.2}, {:.2}) mm",
        axis.x * 1e3,
        axis.y * 1e3
    );
    for p in [
        Vector2::new(0.0, 0.0),
        Vector2::new(0.075, 0.02),
        Vector2::new(0.05, 0.075),
    ] {
        let pixel = marker_pixel(&camera, [p.x, p.y, 0.0]).unwrap();
        let seen = camera.calibration.pixel_to_face(pixel).unwrap();
        let rho = (p - axis).norm();
        let radial = (seen - p).dot(&(p - axis)) / rho;
        let expected = k1 * rho.powi(3);
        println!(
            "rho {:.1} mm: outward {:.2} um, k1 rho^3 {:.2} um",
            rho * 1e3,
            radial * 1e6,
            expected * 1e6
        );
        assert!(
            (radial - expected).abs() < 0.1 * expected,
            "{radial} vs {expected}"
        );
    }
    // Without the effect the two cameras are the same.
    s.effects = Effects::none();
    let plain = TrueCamera::new(&s);
    assert_eq!(plain.experiment_camera, plain.calibration.camera);
}

#[test]
fn a_lifted_marker_is_nearer_the_camera() {
    // The camera sits above the top face: on the face frame's -z side.
    let camera = TrueCamera::new(&Scenario::quick());
    let pose = camera.calibration.face_pose;
    let centre = -(pose.rotation_matrix().inverse() * pose.translation_vector());
    assert!(centre.z < -0.1);
    let lifted = needle_synth::camera::face_point([0.03, 0.04, 1e-4]);
    assert_eq!(lifted, Vector3::new(0.03, 0.04, -1e-4));
}

#[test]
fn a_phantom_too_large_for_the_view_is_refused() {
    let mut s = Scenario::quick();
    s.phantom.width = 0.3;
    s.phantom.depth = 0.3;
    let error = s.validate("test").unwrap_err().to_string();
    assert!(error.contains("frames"), "{error}");
}

#[test]
fn frames_and_calibration_images_are_deterministic_by_seed() {
    let mut s = small();
    s.needles.velocities.truncate(1);
    s.frames = Some(CameraFrames {
        tilted_views: 0,
        ..CameraFrames::paper(1, 45, 0, 1)
    });
    let dir = tempfile::tempdir().unwrap();
    let image = |name: &str, s: &Scenario| {
        let bundle = dir.path().join(name);
        generate(s, &bundle, &dir.path().join(format!("{name}.ron")), |_| {}).unwrap();
        [
            "trials/probe-01/frames/000045.png",
            "calibration/view-00.png",
        ]
        .map(|file| std::fs::read(bundle.join(file)).unwrap())
    };
    let (a, b) = (image("a", &s), image("b", &s));
    assert_eq!(a, b);
    s.seed += 1;
    let c = image("c", &s);
    assert_ne!(a[0], c[0]);
    assert_ne!(a[1], c[1]);
}
