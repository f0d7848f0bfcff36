//! The renderer against brute-force references: solving the plane point at
//! every pixel, and supersampling through the independent pixel-to-face map.

use nalgebra::{Vector2, Vector3};

use super::{RenderOptions, render_darkness};
use crate::{Calibration, Pose, pixel_space_view};

/// The paper's camera, or the same with the strong distortion the
/// undistortion is specified for and a tilted face.
fn cameras() -> [Calibration; 2] {
    let paper = Calibration::paper();
    let mut strong = Calibration::paper();
    strong.camera.distortion.k1 = -0.45;
    strong.camera.distortion.k2 = 0.35;
    strong.camera.distortion.k3 = -0.2;
    strong.face_pose = Pose {
        rotation: [0.35, -0.2, 0.1],
        translation: [-0.04, -0.03, 0.19],
    };
    [paper, strong]
}

/// A `count` x `count` grid of dots spanning the paper's 75 mm face, put
/// off the grid by irrational fractions of a pixel.
fn dot_grid(count: usize) -> Vec<Vector3<f64>> {
    let step = 0.075 / (count - 1) as f64;
    (0..count)
        .flat_map(|j| {
            (0..count).map(move |i| {
                Vector3::new(
                    i as f64 * step + 1.3e-5 * (i as f64).sqrt(),
                    j as f64 * step + 0.7e-5 * (j as f64).sqrt(),
                    0.0,
                )
            })
        })
        .collect()
}

fn max_difference(a: &[f32], b: &[f32]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

#[test]
fn filling_known_pixels_changes_no_pixel() {
    for calibration in cameras() {
        for blur_sigma in [0.0, 1.0] {
            let options = RenderOptions {
                blur_sigma,
                ..RenderOptions::paper()
            };
            let markers = dot_grid(6);
            let (camera, pose) = (&calibration.camera, &calibration.face_pose);
            let filled = render_darkness(camera, pose, &markers, &options, false).unwrap();
            let solved = render_darkness(camera, pose, &markers, &options, true).unwrap();
            let dark = filled.iter().filter(|&&d| d > 0.0).count();
            assert!(dark > 36 * 300, "only {dark} dark pixels");
            let worst = max_difference(&filled, &solved);
            assert!(worst <= 1e-6, "blur {blur_sigma}: {worst}");
        }
    }
    // Pixel space, dots of 3 to 40 px at subpixel positions.
    let (camera, pose) = pixel_space_view();
    for diameter in [3.0, 11.3, 25.0, 40.0] {
        let options = RenderOptions {
            width: 128,
            height: 96,
            dot_diameter: diameter,
            ..RenderOptions::paper()
        };
        let markers = [
            Vector3::new(61.37, 45.81, 0.0),
            Vector3::new(12.5, 80.05, 0.0),
        ];
        let filled = render_darkness(&camera, &pose, &markers, &options, false).unwrap();
        let solved = render_darkness(&camera, &pose, &markers, &options, true).unwrap();
        let worst = max_difference(&filled, &solved);
        assert!(worst <= 1e-6, "diameter {diameter}: {worst}");
    }
}

/// Covered fraction of pixel `(u, v)` from `n` x `n` samples, each mapped
/// onto the face by the calibration's own (undistortion and ray) inverse.
fn supersampled(
    calibration: &Calibration,
    centre: Vector2<f64>,
    radius: f64,
    u: usize,
    v: usize,
    n: usize,
) -> f64 {
    let mut inside = 0;
    for j in 0..n {
        for i in 0..n {
            let offset = Vector2::new(
                (i as f64 + 0.5) / n as f64 - 0.5,
                (j as f64 + 0.5) / n as f64 - 0.5,
            );
            let pixel = Vector2::new(u as f64, v as f64) + offset;
            let face = calibration.pixel_to_face(pixel).unwrap();
            if (face - centre).norm() < radius {
                inside += 1;
            }
        }
    }
    inside as f64 / (n * n) as f64
}

/// With 16 x 16 samples a pixel's coverage is off by at most one sample per
/// sample column the rim crosses, 16/256 = 0.0625, and by about
/// 0.29/256 per column on average, so about a thousandth RMS.
#[test]
fn coverage_matches_supersampling_through_the_inverse_map() {
    for calibration in cameras() {
        let options = RenderOptions {
            blur_sigma: 0.0,
            ..RenderOptions::paper()
        };
        let radius = 0.5 * options.dot_diameter;
        // Near a corner of the face, where distortion and perspective are strongest.
        let centre = Vector2::new(0.0713, 0.0027);
        let marker = Vector3::new(centre.x, centre.y, 0.0);
        let darkness = render_darkness(
            &calibration.camera,
            &calibration.face_pose,
            &[marker],
            &options,
            false,
        )
        .unwrap();
        let p = calibration.face_to_pixel(centre).unwrap();
        let (mut sum_square, mut worst, mut count) = (0.0, 0.0f64, 0);
        let (mut area, mut reference_area) = (0.0, 0.0);
        for v in (p.y as usize - 15)..(p.y as usize + 16) {
            for u in (p.x as usize - 15)..(p.x as usize + 16) {
                let rendered = darkness[v * options.width + u] as f64;
                let reference = supersampled(&calibration, centre, radius, u, v, 16);
                sum_square += (rendered - reference).powi(2);
                worst = worst.max((rendered - reference).abs());
                count += 1;
                area += rendered;
                reference_area += reference;
            }
        }
        let rms = (sum_square / count as f64).sqrt();
        println!(
            "vs 16 x 16 supersampling: rms {rms:.5}, worst {worst:.4}, area {area:.3} vs {reference_area:.3} px^2"
        );
        assert!(area > 300.0, "the dot is in the window: {area}");
        assert!(worst < 0.0625 && rms < 0.003, "rms {rms}, worst {worst}");
        assert!(
            (area - reference_area).abs() < 0.05,
            "area {area} vs {reference_area}"
        );
    }
}

#[test]
fn quantising_equals_rounding_then_clamping() {
    let mut levels: Vec<f32> = vec![
        -3.5, -0.5, -0.0, 0.0, 0.49999997, 0.5, 1.5, 2.5, 254.5, 255.4, 255.5, 1e9,
    ];
    levels.extend((0..200_000).map(|i| -20.0 + i as f32 * 0.003_1));
    for max in [255.0, 65535.0] {
        for &level in &levels {
            assert_eq!(
                crate::frame::quantise(level, max),
                level.round().clamp(0.0, max),
                "{level}"
            );
        }
    }
}
