//! Render frames for the OpenCV peer comparison and track them with ours.
//!
//! `cargo run --release -p needle-vision --example render_peer_frames -- OUT_DIR [FRAMES]`
//!
//! Writes into OUT_DIR (which must not exist): `NNNNNN.png` (the paper's
//! camera, 441 dots at random subpixel positions, noise 2 grey levels, 8 bit),
//! `template.png` (the noise-free synthetic dot, 16 bit, marker at its centre
//! pixel), `truth.csv` (`frame,id,u,v,pred_u,pred_v`: true and predicted
//! pixel positions; predictions are up to 3 px off) and `ours.csv` (our
//! tracked positions and the single-core time per frame). Then run
//! `bench/peers/vision_opencv_peer.py OUT_DIR`.

use std::fmt::Write as _;
use std::time::Instant;

use nalgebra::{Vector2, Vector3};
use needle_vision::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const HALF: usize = 16;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let out = std::path::PathBuf::from(
        args.next()
            .ok_or("usage: render_peer_frames OUT_DIR [FRAMES]")?,
    );
    let frames: usize = args.next().map(|a| a.parse()).transpose()?.unwrap_or(5);
    if out.exists() {
        return Err(format!("{} exists; give a fresh folder", out.display()).into());
    }
    std::fs::create_dir_all(&out)?;
    let calibration = Calibration::paper();
    let options = RenderOptions::paper();
    let mut rng = ChaCha8Rng::seed_from_u64(2026);

    // The template: the paper dot is 2 mm at about 0.079 mm/px.
    let diameter = 0.002 * calibration.camera.intrinsics.fx / 0.2;
    let (camera, pose) = pixel_space_view();
    let size = 2 * HALF + 1 + 2 * 6;
    let centre = (size / 2) as f64;
    let template_options = RenderOptions {
        width: size,
        height: size,
        dot_diameter: diameter,
        read_noise_sigma: 0.0,
        bit_depth: BitDepth::Sixteen,
        ..options.clone()
    };
    let mut template_frame = render_ideal(
        &camera,
        &pose,
        &[Vector3::new(centre, centre, 0.0)],
        &template_options,
    )?;
    // Keep 16-bit precision: scale grey levels by 256 in the file.
    for p in template_frame.pixels.iter_mut() {
        *p *= 256.0;
    }
    template_frame.write_png(&out.join("template.png"))?;
    let template = MarkerTemplate::synthetic(
        diameter,
        options.blur_sigma,
        options.background,
        options.contrast,
        HALF,
    )?;

    let single_core = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let mut truth_csv = String::from("frame,id,u,v,pred_u,pred_v\n");
    let mut ours_csv = String::from("frame,id,u,v,status,seconds_per_frame\n");
    let mut errors = Vec::new();
    let mut seconds = Vec::new();
    for k in 0..frames {
        let markers: Vec<Vector3<f64>> = (0..441)
            .map(|i| {
                Vector3::new(
                    (i % 21) as f64 * 0.00375 + rng.random_range(-4e-5..4e-5),
                    (i / 21) as f64 * 0.00375 + rng.random_range(-4e-5..4e-5),
                    0.0,
                )
            })
            .collect();
        let frame = render_frame(
            &calibration.camera,
            &calibration.face_pose,
            &markers,
            &options,
            k as u64,
        )?;
        frame.write_png(&out.join(format!("{k:06}.png")))?;
        // The 8-bit file is what both trackers see.
        let frame = GreyFrame::read_png(&out.join(format!("{k:06}.png")))?;
        let truth: Vec<Vector2<f64>> = markers
            .iter()
            .map(|m| calibration.face_to_pixel(m.xy()))
            .collect::<Result<_, _>>()?;
        let predictions: Vec<Vector2<f64>> = truth
            .iter()
            .map(|t| t + Vector2::new(rng.random_range(-3.0..3.0), rng.random_range(-3.0..3.0)))
            .collect();
        let templates = vec![template.clone(); truth.len()];
        let track = TrackOptions {
            search: SearchPolicy::Always,
            ..TrackOptions::default()
        };
        let start = Instant::now();
        let outcomes =
            single_core.install(|| track_markers(&frame, &templates, &predictions, &track))?;
        let elapsed = start.elapsed().as_secs_f64();
        seconds.push(elapsed);
        for (i, ((t, p), o)) in truth.iter().zip(&predictions).zip(&outcomes).enumerate() {
            writeln!(
                truth_csv,
                "{k},{i},{:.6},{:.6},{:.6},{:.6}",
                t.x, t.y, p.x, p.y
            )?;
            match o.position {
                Ok(found) => {
                    errors.push(found - t);
                    writeln!(
                        ours_csv,
                        "{k},{i},{:.6},{:.6},tracked,{elapsed:.6}",
                        found.x, found.y
                    )?;
                }
                Err(reason) => writeln!(ours_csv, "{k},{i},,,{reason:?},{elapsed:.6}")?,
            }
        }
    }
    std::fs::write(out.join("truth.csv"), truth_csv)?;
    std::fs::write(out.join("ours.csv"), ours_csv)?;
    let n = errors.len() as f64;
    let mean = errors.iter().sum::<Vector2<f64>>() / n;
    let rms = (errors
        .iter()
        .map(|e| (e - mean).norm_squared())
        .sum::<f64>()
        / (2.0 * n))
        .sqrt();
    seconds.sort_by(f64::total_cmp);
    println!(
        "needle-vision: {} of {} markers tracked, error per coordinate std {rms:.5} px, mean ({:.5}, {:.5}) px, median {:.2} ms per frame (one core, search always)",
        errors.len(),
        441 * frames,
        mean.x,
        mean.y,
        1e3 * seconds[seconds.len() / 2]
    );
    Ok(())
}
