//! Tracking precision, bias and lost-marker detection on rendered frames.

use nalgebra::{Vector2, Vector3};
use needle_vision::*;

/// The brief's dot: 25 px, blur 1 px, contrast 180 on background 220.
const DIAMETER: f64 = 25.0;
const BLUR: f64 = 1.0;
const BACKGROUND: f64 = 220.0;
const CONTRAST: f64 = 180.0;
const HALF: usize = 16;

fn crop_options(size: usize, noise: f64) -> RenderOptions {
    RenderOptions {
        width: size,
        height: size,
        dot_diameter: DIAMETER,
        background: BACKGROUND,
        contrast: CONTRAST,
        blur_sigma: BLUR,
        illumination_gradient: [0.0, 0.0],
        read_noise_sigma: noise,
        electrons_per_grey: None,
        bit_depth: BitDepth::Eight,
    }
}

/// Four dots at subpixel positions in a 120 px crop (pixel-space camera).
fn dots(shift: Vector2<f64>) -> Vec<Vector3<f64>> {
    [(30.0, 30.0), (88.0, 31.0), (31.0, 89.0), (90.0, 90.0)]
        .iter()
        .map(|&(x, y)| Vector3::new(x + shift.x, y + shift.y, 0.0))
        .collect()
}

fn template() -> MarkerTemplate {
    MarkerTemplate::synthetic(DIAMETER, BLUR, BACKGROUND, CONTRAST, HALF).unwrap()
}

/// Cramer-Rao bound of one coordinate for a known template in white noise:
/// var >= sigma^2 (F^-1)_xx, F = sum grad I grad I^T, with grad I from
/// central differences of the noise-free rendering with respect to the dot
/// position (not from the tracker's spline).
fn cramer_rao(noise_variance: f64) -> f64 {
    let (camera, pose) = pixel_space_view();
    let options = crop_options(64, 0.0);
    let eps = 1e-3;
    let at = |dx: f64, dy: f64| {
        render_ideal(
            &camera,
            &pose,
            &[Vector3::new(32.3 + dx, 31.8 + dy, 0.0)],
            &options,
        )
        .unwrap()
        .pixels
    };
    let (xp, xm, yp, ym) = (at(eps, 0.0), at(-eps, 0.0), at(0.0, eps), at(0.0, -eps));
    let mut fisher = nalgebra::Matrix2::<f64>::zeros();
    for r in 32 - HALF..=32 + HALF {
        for c in 32 - HALF..=32 + HALF {
            let i = r * 64 + c;
            let g = Vector2::new(
                (xp[i] - xm[i]) as f64 / (2.0 * eps),
                (yp[i] - ym[i]) as f64 / (2.0 * eps),
            );
            fisher += g * g.transpose();
        }
    }
    (noise_variance * fisher.try_inverse().unwrap()[(0, 0)]).sqrt()
}

fn precision(noise: f64, frames: usize) -> (f64, f64) {
    let (camera, pose) = pixel_space_view();
    let options = crop_options(120, noise);
    let template = template();
    let track = TrackOptions::default();
    let mut errors = Vec::new();
    for k in 0..frames {
        // Quasi-random subpixel shifts.
        let shift = Vector2::new((k as f64 * 0.618_034) % 1.0, (k as f64 * 0.754_877_7) % 1.0);
        let markers = dots(shift);
        let frame = render_frame(&camera, &pose, &markers, &options, 1000 + k as u64).unwrap();
        for m in &markers {
            let predicted = Vector2::new(m.x.round(), m.y.round());
            let outcome = track_marker(&frame, &template, predicted, &track);
            let found = outcome.position.expect("tracked");
            errors.push(found.x - m.x);
            errors.push(found.y - m.y);
        }
    }
    let n = errors.len() as f64;
    let mean = errors.iter().sum::<f64>() / n;
    let std = (errors.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    (mean, std)
}

#[test]
fn precision_is_within_fifteen_percent_of_cramer_rao_at_noise_2_and_5() {
    for noise in [2.0, 5.0] {
        // Rounding to 8 bits adds variance 1/12 to the read noise.
        let bound = cramer_rao(noise * noise + 1.0 / 12.0);
        let (mean, std) = precision(noise, 120);
        println!(
            "noise {noise}: CRB {bound:.5} px, measured std {std:.5} px ({:.3} x CRB), mean {mean:.5}",
            std / bound
        );
        assert!(std <= 1.15 * bound, "std {std} vs CRB {bound}");
        assert!(mean.abs() < 4.0 * std / (960.0f64).sqrt() + 1e-3);
    }
}

#[test]
fn bias_over_subpixel_shifts_is_below_a_thousandth_of_a_pixel() {
    let (camera, pose) = pixel_space_view();
    let mut options = crop_options(120, 0.0);
    options.bit_depth = BitDepth::Sixteen;
    let template = template();
    let track = TrackOptions::default();
    let mut worst: f64 = 0.0;
    for k in 0..=10 {
        let shift = Vector2::new(k as f64 / 10.0, 0.37 * k as f64 / 10.0);
        let markers = dots(shift);
        let frame = render_ideal(&camera, &pose, &markers, &options).unwrap();
        for m in &markers {
            let outcome = track_marker(
                &frame,
                &template,
                Vector2::new(m.x.round(), m.y.round()),
                &track,
            );
            let error = outcome.position.unwrap() - m.xy();
            worst = worst.max(error.abs().max());
        }
    }
    println!("worst bias {worst:.2e} px");
    assert!(worst < 1e-3, "bias {worst}");
}

#[test]
fn markers_at_the_frame_edge_or_in_flat_or_foreign_patches_are_lost_with_a_reason() {
    let (camera, pose) = pixel_space_view();
    let options = crop_options(120, 2.0);
    let frame = render_frame(&camera, &pose, &dots(Vector2::new(0.3, 0.6)), &options, 3).unwrap();
    let template = template();
    let track = TrackOptions::default();
    // The window around a prediction near the edge leaves the frame.
    let outcome = track_marker(&frame, &template, Vector2::new(5.0, 60.0), &track);
    assert_eq!(outcome.position, Err(LostReason::OutOfFrame));
    // Flat, noisy background: no dot anywhere near.
    let flat = render_frame(&camera, &pose, &[], &options, 4).unwrap();
    let outcome = track_marker(&flat, &template, Vector2::new(60.0, 60.0), &track);
    assert_eq!(outcome.position, Err(LostReason::LowContrast));
    // A bright dot on a dark ground (inverted contrast) does not correlate.
    let mut inverted = frame.clone();
    for p in inverted.pixels.iter_mut() {
        *p = 255.0 - *p;
    }
    let outcome = track_marker(&inverted, &template, Vector2::new(30.0, 31.0), &track);
    assert_eq!(outcome.position, Err(LostReason::LowCorrelation));
    // And the real dot is found from a prediction 5 px off, with a sane
    // quality report.
    let outcome = track_marker(&frame, &template, Vector2::new(34.0, 27.0), &track);
    let found = outcome.position.unwrap();
    assert!((found - Vector2::new(30.3, 30.6)).norm() < 0.05);
    assert!(outcome.zncc > 0.99, "{outcome:?}");
    let always = TrackOptions {
        search: SearchPolicy::Always,
        ..TrackOptions::default()
    };
    let searched = track_marker(&frame, &template, Vector2::new(34.0, 27.0), &always);
    assert!(searched.searched && (searched.position.unwrap() - found).norm() < 1e-4);
    assert!(outcome.standard_deviation.x > 0.001 && outcome.standard_deviation.x < 0.01);
}

#[test]
fn templates_cut_from_a_frame_track_the_next_frame_without_search() {
    let (camera, pose) = pixel_space_view();
    let options = crop_options(120, 2.0);
    let first = dots(Vector2::new(0.2, 0.4));
    let second = dots(Vector2::new(0.9, -0.3));
    let frame0 = render_frame(&camera, &pose, &first, &options, 1).unwrap();
    let frame1 = render_frame(&camera, &pose, &second, &options, 2).unwrap();
    let track = TrackOptions::default();
    for (a, b) in first.iter().zip(&second) {
        let template = MarkerTemplate::from_frame(&frame0, a.xy(), HALF).unwrap();
        let outcome = track_marker(&frame1, &template, a.xy(), &track);
        assert!(!outcome.searched);
        assert!((outcome.position.unwrap() - b.xy()).norm() < 0.03);
    }
    let outcomes = track_markers(
        &frame1,
        &[template()],
        &[Vector2::zeros(), Vector2::zeros()],
        &track,
    );
    assert!(outcomes.is_err());
}
