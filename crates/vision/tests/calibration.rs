//! Calibration on synthetic correspondences: closed-form initialisation,
//! refinement to the noise floor, rectification accuracy, bad input.

use nalgebra::{Vector2, Vector3};
use needle_vision::*;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

fn true_camera() -> Camera {
    Camera {
        intrinsics: Intrinsics {
            fx: 2540.0,
            fy: 2535.0,
            cx: 1040.0,
            cy: 760.0,
            skew: 0.0,
        },
        distortion: Distortion {
            k1: -0.21,
            k2: 0.12,
            k3: -0.03,
            p1: 8e-4,
            p2: -5e-4,
        },
    }
}

/// A 15 x 11 grid of 5 mm pitch.
fn target() -> Vec<Vector2<f64>> {
    (0..11)
        .flat_map(|j| (0..15).map(move |i| Vector2::new(i as f64 * 0.005, j as f64 * 0.005)))
        .collect()
}

fn poses() -> Vec<Pose> {
    vec![
        Pose {
            rotation: [0.02, -0.01, 0.01],
            translation: [-0.035, -0.025, 0.20],
        },
        Pose {
            rotation: [0.35, 0.05, 0.1],
            translation: [-0.04, -0.02, 0.21],
        },
        Pose {
            rotation: [-0.3, 0.2, -0.05],
            translation: [-0.03, -0.03, 0.19],
        },
        Pose {
            rotation: [0.1, -0.35, 0.2],
            translation: [-0.03, -0.025, 0.2],
        },
        Pose {
            rotation: [-0.2, -0.25, -0.3],
            translation: [-0.035, -0.02, 0.22],
        },
    ]
}

fn views(noise: f64, seed: u64) -> Vec<CalibrationView> {
    let camera = true_camera();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let normal = Normal::new(0.0, noise.max(1e-300)).unwrap();
    poses()
        .iter()
        .map(|pose| {
            let target = target();
            let image = target
                .iter()
                .map(|x| {
                    let p = camera.project(pose, &Vector3::new(x.x, x.y, 0.0)).unwrap();
                    if noise > 0.0 {
                        p + Vector2::new(normal.sample(&mut rng), normal.sample(&mut rng))
                    } else {
                        p
                    }
                })
                .collect();
            CalibrationView { target, image }
        })
        .collect()
}

#[test]
fn homography_is_exact_for_a_pinhole_camera() {
    let camera = Camera {
        distortion: Distortion::NONE,
        ..true_camera()
    };
    let pose = poses()[1];
    let target = target();
    let image: Vec<_> = target
        .iter()
        .map(|x| camera.project(&pose, &Vector3::new(x.x, x.y, 0.0)).unwrap())
        .collect();
    let h = homography(&target, &image).unwrap();
    for (x, u) in target.iter().zip(&image) {
        let q = h * Vector3::new(x.x, x.y, 1.0);
        assert!((Vector2::new(q.x / q.z, q.y / q.z) - u).norm() < 1e-7);
    }
}

#[test]
fn zhang_initialisation_recovers_a_distortion_free_camera() {
    let camera = Camera {
        distortion: Distortion::NONE,
        ..true_camera()
    };
    let views: Vec<CalibrationView> = poses()
        .iter()
        .map(|pose| {
            let target = target();
            let image = target
                .iter()
                .map(|x| camera.project(pose, &Vector3::new(x.x, x.y, 0.0)).unwrap())
                .collect();
            CalibrationView { target, image }
        })
        .collect();
    let (found, found_poses) = initialise(&views, 2056, 1544).unwrap();
    let (k, t) = (found.intrinsics, camera.intrinsics);
    assert!(
        (k.fx - t.fx).abs() < 1e-3 && (k.fy - t.fy).abs() < 1e-3,
        "{k:?}"
    );
    assert!(
        (k.cx - t.cx).abs() < 1e-3 && (k.cy - t.cy).abs() < 1e-3,
        "{k:?}"
    );
    for (a, b) in found_poses.iter().zip(poses()) {
        assert!((a.translation_vector() - b.translation_vector()).norm() < 1e-8);
    }
}

#[test]
fn refinement_reaches_the_noise_floor_and_the_true_camera() {
    let noise = 0.05;
    let fit = calibrate(&views(noise, 7), 2056, 1544, &FixedParameters::default()).unwrap();
    let expected = std::f64::consts::SQRT_2 * noise;
    println!(
        "rms {:.5} px (sqrt(2) sigma = {expected:.5}), camera {:?}",
        fit.reprojection_rms, fit.camera
    );
    assert!((fit.reprojection_rms / expected - 1.0).abs() < 0.05);
    let (k, t) = (fit.camera.intrinsics, true_camera().intrinsics);
    assert!(
        (k.fx - t.fx).abs() < 2.0 && (k.cx - t.cx).abs() < 2.0 && (k.cy - t.cy).abs() < 2.0,
        "{k:?}"
    );
    assert!((fit.camera.distortion.k1 - true_camera().distortion.k1).abs() < 0.01);
}

#[test]
fn rectification_error_is_below_five_hundredths_of_a_pixel_at_noise_two_hundredths() {
    let fit = calibrate(&views(0.02, 11), 2056, 1544, &FixedParameters::default()).unwrap();
    let truth = Calibration {
        width: 2056,
        height: 1544,
        camera: true_camera(),
        face_pose: poses()[0],
        reprojection_rms: 0.0,
    };
    let estimate = Calibration {
        camera: fit.camera,
        face_pose: fit.poses[0],
        reprojection_rms: fit.reprojection_rms,
        ..truth.clone()
    };
    let mut sum = 0.0;
    let mut count = 0;
    for j in 0..=20 {
        for i in 0..=20 {
            let face = Vector2::new(0.07 * i as f64 / 20.0, 0.05 * j as f64 / 20.0);
            let pixel = truth.face_to_pixel(face).unwrap();
            let error = estimate.pixel_to_face(pixel).unwrap() - face;
            let per_pixel = truth.face_per_pixel(face).unwrap();
            let in_pixels = per_pixel.try_inverse().unwrap() * error;
            sum += in_pixels.norm_squared();
            count += 1;
        }
    }
    let rms = (sum / count as f64).sqrt();
    println!("rectification rms {rms:.4} px");
    assert!(rms <= 0.05, "{rms}");
}

#[test]
fn rectification_round_trips() {
    let truth = Calibration {
        width: 2056,
        height: 1544,
        camera: true_camera(),
        face_pose: poses()[1],
        reprojection_rms: 0.0,
    };
    let face = Vector2::new(0.031, 0.022);
    let back = truth
        .pixel_to_face(truth.face_to_pixel(face).unwrap())
        .unwrap();
    assert!((back - face).norm() < 1e-12);
}

#[test]
fn calibration_with_too_few_points_is_refused() {
    let mut views = views(0.0, 1);
    views[2].target.truncate(5);
    views[2].image.truncate(5);
    let err = calibrate(&views, 2056, 1544, &FixedParameters::default()).unwrap_err();
    assert!(err.to_string().contains("view 2"), "{err}");
    assert!(calibrate(&[], 2056, 1544, &FixedParameters::default()).is_err());
    let mut mismatched = self::views(0.0, 1);
    mismatched[0].image.pop();
    assert!(calibrate(&mismatched, 2056, 1544, &FixedParameters::default()).is_err());
}

#[test]
fn fronto_parallel_single_view_is_refused() {
    let camera = true_camera();
    let pose = Pose {
        rotation: [0.0; 3],
        translation: [-0.035, -0.025, 0.2],
    };
    let target = target();
    let image = target
        .iter()
        .map(|x| camera.project(&pose, &Vector3::new(x.x, x.y, 0.0)).unwrap())
        .collect();
    let err = initialise(&[CalibrationView { target, image }], 2056, 1544).unwrap_err();
    assert!(matches!(err, VisionError::Calibration(_)), "{err}");
}

#[test]
fn calibration_survives_a_ron_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("calibration.ron");
    let calibration = Calibration {
        width: 2056,
        height: 1544,
        camera: true_camera(),
        face_pose: poses()[1],
        reprojection_rms: 0.07,
    };
    calibration.save(&path).unwrap();
    assert_eq!(Calibration::load(&path).unwrap(), calibration);
    std::fs::write(&path, "Calibration(width: 2056)").unwrap();
    assert!(matches!(
        Calibration::load(&path),
        Err(VisionError::Ron { .. })
    ));
}

mod dot_grid {
    use super::*;

    fn grid() -> DotGrid {
        DotGrid {
            columns: 11,
            rows: 8,
            pitch: 0.008,
            dot_diameter: 0.004,
        }
    }

    fn grid_poses() -> Vec<Pose> {
        vec![
            Pose {
                rotation: [0.45, 0.05, 0.02],
                translation: [-0.04, -0.028, 0.26],
            },
            Pose {
                rotation: [-0.4, 0.15, -0.05],
                translation: [-0.04, -0.028, 0.25],
            },
            Pose {
                rotation: [0.1, -0.45, 0.1],
                translation: [-0.04, -0.03, 0.26],
            },
            Pose {
                rotation: [-0.15, 0.4, -0.1],
                translation: [-0.038, -0.026, 0.27],
            },
        ]
    }

    fn images() -> Vec<GreyFrame> {
        let options = RenderOptions {
            dot_diameter: grid().dot_diameter,
            ..RenderOptions::paper()
        };
        let nodes: Vec<Vector3<f64>> = grid()
            .nodes()
            .iter()
            .map(|n| Vector3::new(n.x, n.y, 0.0))
            .collect();
        grid_poses()
            .iter()
            .enumerate()
            .map(|(i, pose)| {
                render_frame(&true_camera(), pose, &nodes, &options, i as u64).unwrap()
            })
            .collect()
    }

    #[test]
    fn dots_are_found_in_grid_order_near_their_centres() {
        let frame = &images()[0];
        let found = detect_dot_grid(frame, &grid(), 4).unwrap();
        for (node, p) in grid().nodes().iter().zip(&found) {
            let truth = true_camera()
                .project(&grid_poses()[0], &Vector3::new(node.x, node.y, 0.0))
                .unwrap();
            assert!(
                (p - truth).norm() < 0.3,
                "node {node:?}: found {p:?}, truth {truth:?}"
            );
        }
    }

    #[test]
    fn circle_centre_bias_explains_the_centroid_offset() {
        // The centroid of the projected disc, from a noise-free rendering,
        // minus the projected centre, equals the computed bias.
        let pose = grid_poses()[0];
        let options = RenderOptions {
            dot_diameter: 0.004,
            read_noise_sigma: 0.0,
            ..RenderOptions::paper()
        };
        let centre = Vector2::new(0.0, 0.0);
        let frame = render_ideal(&true_camera(), &pose, &[Vector3::zeros()], &options).unwrap();
        let truth = true_camera().project(&pose, &Vector3::zeros()).unwrap();
        let (mut sum, mut weighted) = (0.0, Vector2::zeros());
        for v in (truth.y as usize - 40)..(truth.y as usize + 40) {
            for u in (truth.x as usize - 40)..(truth.x as usize + 40) {
                let darkness = 220.0 - frame.at(u, v) as f64;
                sum += darkness;
                weighted += darkness * Vector2::new(u as f64, v as f64);
            }
        }
        let measured = weighted / sum - truth;
        let bias = circle_centre_bias(&true_camera(), &pose, centre, 0.004).unwrap();
        println!("centroid offset {measured:?}, computed bias {bias:?}");
        assert!(bias.norm() > 0.02);
        assert!((measured - bias).norm() < 0.1 * bias.norm());
    }

    #[test]
    fn dot_grid_calibration_with_bias_correction_reaches_the_noise_floor() {
        let images = images();
        let fixed = FixedParameters::default();
        let plain = calibrate_dot_grid(&images, &grid(), 4, &fixed, 0).unwrap();
        let corrected = calibrate_dot_grid(&images, &grid(), 4, &fixed, 3).unwrap();
        // How far each fit puts the images of the true dot centres.
        let centre_error = |fit: &CalibrationFit| {
            let mut sum = 0.0;
            let mut count = 0.0;
            for (pose, true_pose) in fit.poses.iter().zip(grid_poses()) {
                for node in grid().nodes() {
                    let x = Vector3::new(node.x, node.y, 0.0);
                    sum += (fit.camera.project(pose, &x).unwrap()
                        - true_camera().project(&true_pose, &x).unwrap())
                    .norm_squared();
                    count += 1.0;
                }
            }
            (sum / count).sqrt()
        };
        let (plain_error, corrected_error) = (centre_error(&plain), centre_error(&corrected));
        println!(
            "uncorrected: rms {:.4} px, dot-centre error {plain_error:.4} px, {:?}",
            plain.reprojection_rms, plain.camera.intrinsics
        );
        println!(
            "corrected:   rms {:.4} px, dot-centre error {corrected_error:.4} px, {:?}",
            corrected.reprojection_rms, corrected.camera.intrinsics
        );
        assert!(corrected.reprojection_rms < 0.03);
        assert!(corrected_error < 0.5 * plain_error);
        assert!((corrected.camera.intrinsics.fx - true_camera().intrinsics.fx).abs() < 2.0);
    }

    #[test]
    fn a_frame_without_the_grid_is_refused() {
        let blank = GreyFrame::filled(2056, 1544, BitDepth::Eight, 200.0);
        assert!(matches!(
            detect_dot_grid(&blank, &grid(), 4),
            Err(VisionError::DotGrid(_))
        ));
    }
}
