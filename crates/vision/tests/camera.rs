//! Camera model: analytic Jacobians against finite differences, undistortion
//! round trips and its refusal outside the invertible region.

use nalgebra::{Vector2, Vector3};
use needle_vision::*;
use proptest::prelude::*;

fn strong_camera() -> Camera {
    Camera {
        intrinsics: Intrinsics {
            fx: 2000.0,
            fy: 2010.0,
            cx: 1027.5,
            cy: 771.5,
            skew: 0.7,
        },
        distortion: Distortion {
            k1: -0.45,
            k2: 0.35,
            k3: -0.2,
            p1: 1e-3,
            p2: -2e-3,
        },
    }
}

fn pose() -> Pose {
    Pose {
        rotation: [0.2, -0.15, 0.05],
        translation: [-0.03, -0.02, 0.25],
    }
}

#[test]
fn projection_jacobians_match_central_differences() {
    let camera = strong_camera();
    let pose = pose();
    let point = Vector3::new(0.031, 0.017, 0.0038);
    let j = camera.project_with_jacobians(&pose, &point).unwrap();
    let h = 1e-6;
    let check =
        |analytic: Vector2<f64>, plus: Vector2<f64>, minus: Vector2<f64>, step: f64, what: &str| {
            let numeric = (plus - minus) / (2.0 * step);
            let error = (analytic - numeric).norm() / numeric.norm().max(1.0);
            assert!(
                error < 1e-6,
                "{what}: analytic {analytic:?} numeric {numeric:?}"
            );
        };
    for k in 0..5 {
        let perturbed = |s: f64| {
            let mut c = camera;
            let i = &mut c.intrinsics;
            *[&mut i.fx, &mut i.fy, &mut i.cx, &mut i.cy, &mut i.skew][k] += s;
            c.project(&pose, &point).unwrap()
        };
        check(
            j.intrinsics.column(k).into_owned(),
            perturbed(h),
            perturbed(-h),
            h,
            "intrinsics",
        );
        let perturbed = |s: f64| {
            let mut c = camera;
            let d = &mut c.distortion;
            *[&mut d.k1, &mut d.k2, &mut d.k3, &mut d.p1, &mut d.p2][k] += s;
            c.project(&pose, &point).unwrap()
        };
        check(
            j.distortion.column(k).into_owned(),
            perturbed(h),
            perturbed(-h),
            h,
            "distortion",
        );
    }
    for k in 0..6 {
        let perturbed = |s: f64| {
            let mut p = pose;
            if k < 3 {
                p.rotation[k] += s
            } else {
                p.translation[k - 3] += s
            }
            camera.project(&p, &point).unwrap()
        };
        check(
            j.pose.column(k).into_owned(),
            perturbed(h),
            perturbed(-h),
            h,
            "pose",
        );
    }
    for k in 0..3 {
        let perturbed = |s: f64| {
            let mut x = point;
            x[k] += s;
            camera.project(&pose, &x).unwrap()
        };
        check(
            j.point.column(k).into_owned(),
            perturbed(h),
            perturbed(-h),
            h,
            "point",
        );
    }
}

#[test]
fn distortion_jacobian_matches_central_differences() {
    let d = strong_camera().distortion;
    let n = Vector2::new(0.31, -0.22);
    let (_, j) = d.distort_with_jacobian(n);
    let h = 1e-7;
    for k in 0..2 {
        let mut e = Vector2::zeros();
        e[k] = h;
        let numeric = (d.distort(n + e) - d.distort(n - e)) / (2.0 * h);
        assert!((j.column(k) - numeric).norm() < 1e-8);
    }
}

#[test]
fn monotone_radius_of_the_strong_lens_is_one() {
    // 1 + 3 k1 r^2 + 5 k2 r^4 + 7 k3 r^6 = 1 - 1.35 + 1.75 - 1.4 = 0 at r = 1.
    let d = Distortion {
        k1: -0.45,
        k2: 0.35,
        k3: -0.2,
        p1: 0.0,
        p2: 0.0,
    };
    assert!((d.monotone_radius() - 1.0).abs() < 1e-9);
    assert_eq!(Distortion::NONE.monotone_radius(), f64::INFINITY);
}

#[test]
fn undistortion_round_trips_within_1e9_px_over_the_whole_frame() {
    let camera = strong_camera();
    let mut worst: f64 = 0.0;
    for v in (0..=1543).step_by(31).chain([1543]) {
        for u in (0..=2055).step_by(37).chain([2055]) {
            let pixel = Vector2::new(u as f64, v as f64);
            let n = camera.undistort_pixel(pixel).unwrap();
            let back = camera.intrinsics.to_pixel(camera.distortion.distort(n));
            worst = worst.max((back - pixel).norm());
        }
    }
    assert!(worst < 1e-9, "round trip error {worst} px");
}

#[test]
fn undistortion_refuses_points_beyond_the_fold() {
    // Radially, d(r) = r L(r^2) peaks at 0.7 for r = 1: nothing maps beyond.
    let d = Distortion {
        k1: -0.45,
        k2: 0.35,
        k3: -0.2,
        p1: 0.0,
        p2: 0.0,
    };
    for radius in [0.71, 0.8, 1.5, 10.0] {
        let err = d
            .undistort(Vector2::new(radius * 0.6, radius * 0.8))
            .unwrap_err();
        assert!(matches!(err, VisionError::NotInvertible { .. }), "{err}");
    }
    // Just inside the fold it still converges, to the right branch.
    let n = d.undistort(Vector2::new(0.0, 0.699)).unwrap();
    assert!(n.norm() < 1.0 && (d.distort(n) - Vector2::new(0.0, 0.699)).norm() < 1e-12);
    assert!(d.undistort(Vector2::new(f64::NAN, 0.0)).is_err());
}

#[test]
fn points_behind_the_camera_are_refused() {
    let camera = strong_camera();
    let p = Pose {
        rotation: [0.0; 3],
        translation: [0.0, 0.0, -1.0],
    };
    assert!(matches!(
        camera.project(&p, &Vector3::zeros()),
        Err(VisionError::BehindCamera { .. })
    ));
}

proptest! {
    #[test]
    fn undistort_inverts_distort_inside_the_monotone_disc(r in 0.0..0.97f64, angle in 0.0..std::f64::consts::TAU) {
        let d = strong_camera().distortion;
        let n = Vector2::new(r * angle.cos(), r * angle.sin());
        let back = d.undistort(d.distort(n)).unwrap();
        prop_assert!((back - n).norm() < 1e-10);
    }
}
