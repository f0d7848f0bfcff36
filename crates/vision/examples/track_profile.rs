//! The frame-to-frame case of `benches/track.rs` (441 markers, 2056 x 1544,
//! templates cut from the first frame, second frame displaced by about
//! 0.2 px) as a plain program, for instruction counting and for timing on a
//! loaded machine by thread CPU time rather than wall time:
//!
//! `cargo run --release -p needle-vision --example track_profile -- [REPEATS]`
//!
//! `valgrind --tool=callgrind --toggle-collect='*track_markers*' <binary> 1`
//! counts the instructions of one frame (rendering excluded).

use nalgebra::{Vector2, Vector3};
use needle_vision::*;

fn grid(shift: Vector2<f64>) -> Vec<Vector3<f64>> {
    (0..21)
        .flat_map(|j| (0..21).map(move |i| (i, j)))
        .map(|(i, j)| {
            Vector3::new(
                i as f64 * 0.00375 + shift.x,
                j as f64 * 0.00375 + shift.y,
                0.0,
            )
        })
        .collect()
}

/// CPU time of the calling thread (s), from `/proc/thread-self/stat`
/// (user + system clock ticks at 100 Hz); `None` where that file is absent.
fn thread_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/thread-self/stat").ok()?;
    // Fields after the parenthesised command name; utime and stime are the
    // 14th and 15th fields of the whole line.
    let rest = &stat[stat.rfind(')')? + 2..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = fields[11].parse::<f64>().ok()? + fields[12].parse::<f64>().ok()?;
    Some(ticks / 100.0)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let repeats: usize = std::env::args()
        .nth(1)
        .map(|a| a.parse())
        .transpose()?
        .unwrap_or(200);
    let calibration = Calibration::paper();
    let options = RenderOptions::paper();
    let first = grid(Vector2::zeros());
    let second = grid(Vector2::new(2.1e-5, -1.3e-5));
    let pose = &calibration.face_pose;
    let frame0 = render_frame(&calibration.camera, pose, &first, &options, 1)?;
    let frame1 = render_frame(&calibration.camera, pose, &second, &options, 2)?;
    let positions = first
        .iter()
        .map(|m| calibration.face_to_pixel(m.xy()))
        .collect::<Result<Vec<_>, _>>()?;
    let truth = second
        .iter()
        .map(|m| calibration.face_to_pixel(m.xy()))
        .collect::<Result<Vec<_>, _>>()?;
    let templates = positions
        .iter()
        .map(|p| MarkerTemplate::from_frame(&frame0, *p, 16))
        .collect::<Result<Vec<_>, _>>()?;
    let single_core = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let track = TrackOptions::default();
    let (seconds, outcomes) = single_core.install(|| {
        let start = thread_cpu_seconds();
        let mut outcomes = Vec::new();
        for _ in 0..repeats {
            outcomes = track_markers(&frame1, &templates, &positions, &track)?;
        }
        let seconds = start
            .zip(thread_cpu_seconds())
            .map(|(a, b)| (b - a) / repeats as f64);
        Ok::<_, VisionError>((seconds, outcomes))
    })?;
    let iterations: usize = outcomes.iter().map(|o| o.iterations).sum();
    let searched = outcomes.iter().filter(|o| o.searched).count();
    let mut worst: f64 = 0.0;
    for (o, t) in outcomes.iter().zip(&truth) {
        let found = o.position.map_err(|r| format!("lost: {r:?}"))?;
        worst = worst.max((found - t).abs().max());
    }
    println!(
        "{} markers, {} searched, {:.2} IC-GN iterations per marker, worst error {:.4} px",
        outcomes.len(),
        searched,
        iterations as f64 / outcomes.len() as f64,
        worst
    );
    match seconds {
        Some(s) => println!(
            "thread CPU time per frame: {:.3} ms over {repeats} repeats",
            s * 1e3
        ),
        None => println!("no thread CPU clock on this system"),
    }
    Ok(())
}
