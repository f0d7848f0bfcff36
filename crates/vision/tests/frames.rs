//! Rendering, frame files and `track_frames` end to end, with bad input.

use std::path::Path;

use nalgebra::{Vector2, Vector3};
use needle_data::MarkerRest;
use needle_vision::*;

fn calibration() -> Calibration {
    Calibration {
        width: 320,
        height: 256,
        camera: Camera {
            intrinsics: Intrinsics {
                fx: 2530.0,
                fy: 2528.0,
                cx: 161.0,
                cy: 127.0,
                skew: 0.0,
            },
            distortion: Distortion {
                k1: -0.25,
                k2: 0.1,
                k3: 0.0,
                p1: 5e-4,
                p2: -3e-4,
            },
        },
        face_pose: Pose {
            rotation: [0.06, -0.04, 0.02],
            translation: [-0.0075, -0.0058, 0.2],
        },
        reprojection_rms: 0.0,
    }
}

/// A 5 x 4 grid at 3.75 mm pitch (the paper's pitch), ids row-major.
fn rest() -> Vec<MarkerRest> {
    (0..4)
        .flat_map(|j| (0..5).map(move |i| (i, j)))
        .map(|(i, j)| MarkerRest {
            id: (j * 5 + i) as u32,
            x: i as f64 * 0.00375,
            y: j as f64 * 0.00375,
        })
        .collect()
}

fn render_options() -> RenderOptions {
    RenderOptions {
        width: 320,
        height: 256,
        illumination_gradient: [0.05, -0.03],
        ..RenderOptions::paper()
    }
}

/// Marker positions at frame `k`: a uniform stretch plus a drift.
fn displaced(k: usize) -> Vec<Vector3<f64>> {
    rest()
        .iter()
        .map(|m| {
            Vector3::new(
                m.x * (1.0 + 0.002 * k as f64) + 2.3e-5 * k as f64,
                m.y - 1.7e-5 * k as f64,
                0.0,
            )
        })
        .collect()
}

fn write_sequence(dir: &Path, frames: usize) {
    let c = calibration();
    for k in 0..frames {
        let frame = render_frame(
            &c.camera,
            &c.face_pose,
            &displaced(k),
            &render_options(),
            k as u64,
        )
        .unwrap();
        frame.write_png(&dir.join(format!("{k:06}.png"))).unwrap();
    }
}

#[test]
fn rendering_is_deterministic_by_seed_and_conserves_dot_area() {
    let c = calibration();
    let a = render_frame(&c.camera, &c.face_pose, &displaced(0), &render_options(), 5).unwrap();
    let b = render_frame(&c.camera, &c.face_pose, &displaced(0), &render_options(), 5).unwrap();
    let other = render_frame(&c.camera, &c.face_pose, &displaced(0), &render_options(), 6).unwrap();
    assert_eq!(a, b);
    assert_ne!(a, other);
    // In pixel space, the summed darkness of a blurred disc is its area.
    let (camera, pose) = pixel_space_view();
    let options = RenderOptions {
        width: 64,
        height: 64,
        dot_diameter: 25.0,
        background: 100.0,
        contrast: 1.0,
        read_noise_sigma: 0.0,
        ..RenderOptions::paper()
    };
    let frame = render_ideal(&camera, &pose, &[Vector3::new(31.37, 32.81, 0.0)], &options).unwrap();
    let area: f64 = frame.pixels.iter().map(|&p| 100.0 - p as f64).sum();
    let exact = std::f64::consts::PI * 12.5 * 12.5;
    assert!((area - exact).abs() < 0.01, "area {area} vs {exact}");
}

#[test]
fn png_round_trip_in_8_and_16_bits() {
    let dir = tempfile::tempdir().unwrap();
    for depth in [BitDepth::Eight, BitDepth::Sixteen] {
        let mut frame = GreyFrame::filled(7, 5, depth, 0.0);
        for (i, p) in frame.pixels.iter_mut().enumerate() {
            *p = (i * 7) as f32;
        }
        let path = dir.path().join("f.png");
        frame.write_png(&path).unwrap();
        assert_eq!(GreyFrame::read_png(&path).unwrap(), frame);
    }
}

#[test]
fn track_frames_follows_markers_onto_the_face() {
    let dir = tempfile::tempdir().unwrap();
    write_sequence(dir.path(), 3);
    let tracked = track_frames(
        dir.path(),
        &calibration(),
        &rest(),
        &TrackFramesOptions::default(),
    )
    .unwrap();
    assert!(tracked.lost.is_empty(), "{:?}", tracked.lost);
    assert_eq!(tracked.observations.len(), 3 * rest().len());
    let metres_per_pixel = 0.2 / 2530.0;
    let mut sum = 0.0;
    let mut worst: f64 = 0.0;
    for row in &tracked.observations {
        let truth = displaced(row.frame as usize)[row.id as usize];
        let error = Vector2::new(row.x - truth.x, row.y - truth.y).norm() / metres_per_pixel;
        sum += error * error;
        worst = worst.max(error);
        let sigma = row.sigma.unwrap();
        assert!(sigma[0] > 0.0 && sigma[0] < 0.05 * metres_per_pixel);
        assert!((row.t - row.frame as f64 / 30.0).abs() < 1e-12);
    }
    let rms = (sum / tracked.observations.len() as f64).sqrt();
    println!("track_frames error rms {rms:.4} px, worst {worst:.4} px");
    assert!(rms < 0.02 && worst < 0.05);
}

#[test]
fn markers_leaving_the_frame_or_occluded_are_reported_lost_then_reacquired() {
    let dir = tempfile::tempdir().unwrap();
    let c = calibration();
    let options = render_options();
    let mut markers = displaced(0);
    let occluded = 7;
    for k in 0..3 {
        // Marker 0 slides out of the frame at frame 2.
        markers[0].x = if k < 2 { 0.0 } else { -0.004 };
        let mut frame = render_frame(&c.camera, &c.face_pose, &markers, &options, k).unwrap();
        if k == 1 {
            // Cover marker 7 with a bright blob (a finger, a reflection).
            let p = c.face_to_pixel(markers[occluded].xy()).unwrap();
            for v in (p.y as usize - 16)..(p.y as usize + 16) {
                for u in (p.x as usize - 16)..(p.x as usize + 16) {
                    frame.pixels[v * frame.width + u] = 240.0;
                }
            }
        }
        frame
            .write_png(&dir.path().join(format!("{k:06}.png")))
            .unwrap();
    }
    let tracked = track_frames(dir.path(), &c, &rest(), &TrackFramesOptions::default()).unwrap();
    let lost: Vec<(u64, u32)> = tracked.lost.iter().map(|l| (l.frame, l.id)).collect();
    assert_eq!(lost, vec![(1, 7), (2, 0)], "{:?}", tracked.lost);
    assert!(matches!(
        tracked.lost[0].reason,
        LostReason::LowContrast | LostReason::LowCorrelation
    ));
    // Marker 0 jumped 75 px towards the edge: where the tracker looks there is
    // only background (or the frame's edge).
    assert!(matches!(
        tracked.lost[1].reason,
        LostReason::OutOfFrame | LostReason::LowContrast
    ));
    // Marker 7 is back in frame 2, at the right place.
    let row = tracked
        .observations
        .iter()
        .find(|r| r.frame == 2 && r.id == 7)
        .unwrap();
    assert!((row.x - markers[7].x).abs() < 2e-6 && (row.y - markers[7].y).abs() < 2e-6);
}

#[test]
fn markers_csv_is_written_in_format_1() {
    let dir = tempfile::tempdir().unwrap();
    write_sequence(dir.path(), 2);
    let out = tempfile::tempdir().unwrap();
    let path = out.path().join("markers.csv");
    track_frames_to_csv(
        dir.path(),
        &calibration(),
        &rest(),
        &path,
        &TrackFramesOptions::default(),
    )
    .unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(
        text.starts_with("frame,t,id,x,y,sx,sy\n"),
        "{}",
        &text[..40]
    );
    assert_eq!(text.lines().count(), 1 + 2 * rest().len());
    // Never overwritten.
    assert!(
        track_frames_to_csv(
            dir.path(),
            &calibration(),
            &rest(),
            &path,
            &TrackFramesOptions::default()
        )
        .is_err()
    );
}

#[test]
fn bad_frames_give_typed_errors_naming_the_file() {
    let c = calibration();
    let options = TrackFramesOptions::default();
    // No frames.
    let empty = tempfile::tempdir().unwrap();
    assert!(matches!(
        track_frames(empty.path(), &c, &rest(), &options),
        Err(VisionError::NoFrames { .. })
    ));
    // Wrong size.
    let dir = tempfile::tempdir().unwrap();
    GreyFrame::filled(100, 80, BitDepth::Eight, 100.0)
        .write_png(&dir.path().join("000000.png"))
        .unwrap();
    let err = track_frames(dir.path(), &c, &rest(), &options).unwrap_err();
    assert!(
        matches!(err, VisionError::FrameSize { .. }) && err.to_string().contains("000000.png"),
        "{err}"
    );
    // Flat frame.
    GreyFrame::filled(320, 256, BitDepth::Eight, 100.0)
        .write_png(&dir.path().join("000000.png"))
        .unwrap();
    assert!(matches!(
        track_frames(dir.path(), &c, &rest(), &options),
        Err(VisionError::LowContrast { .. })
    ));
    // Colour PNG.
    image::RgbImage::new(320, 256)
        .save(dir.path().join("000000.png"))
        .unwrap();
    assert!(matches!(
        track_frames(dir.path(), &c, &rest(), &options),
        Err(VisionError::PixelFormat { .. })
    ));
    // Corrupt PNG.
    std::fs::write(
        dir.path().join("000000.png"),
        b"\x89PNG\r\n\x1a\nnot really",
    )
    .unwrap();
    assert!(matches!(
        track_frames(dir.path(), &c, &rest(), &options),
        Err(VisionError::Png { .. })
    ));
    // Bad calibration.
    let mut bad = c.clone();
    bad.camera.intrinsics.fx = -1.0;
    assert!(matches!(
        track_frames(dir.path(), &bad, &rest(), &options),
        Err(VisionError::InvalidParameter { .. })
    ));
}

#[test]
fn bad_render_options_are_refused() {
    let c = calibration();
    let mut options = render_options();
    options.blur_sigma = -1.0;
    assert!(render_frame(&c.camera, &c.face_pose, &displaced(0), &options, 0).is_err());
    let mut markers = displaced(0);
    markers[3].x = f64::NAN;
    assert!(render_frame(&c.camera, &c.face_pose, &markers, &render_options(), 0).is_err());
}
