//! Tracking 441 markers (the paper's 21 x 21 grid) in one 2056 x 1544 frame
//! on one core. Run with
//! `cargo bench -p needle-vision --bench track -- --warm-up-time 1 --measurement-time 5`.

use criterion::{Criterion, criterion_group, criterion_main};
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

fn bench(c: &mut Criterion) {
    let calibration = Calibration::paper();
    let options = RenderOptions::paper();
    let first = grid(Vector2::zeros());
    let second = grid(Vector2::new(2.1e-5, -1.3e-5));
    let frame0 = render_frame(
        &calibration.camera,
        &calibration.face_pose,
        &first,
        &options,
        1,
    )
    .unwrap();
    let frame1 = render_frame(
        &calibration.camera,
        &calibration.face_pose,
        &second,
        &options,
        2,
    )
    .unwrap();
    let positions: Vec<Vector2<f64>> = first
        .iter()
        .map(|m| calibration.face_to_pixel(m.xy()).unwrap())
        .collect();
    let templates: Vec<MarkerTemplate> = positions
        .iter()
        .map(|p| MarkerTemplate::from_frame(&frame0, *p, 16).unwrap())
        .collect();
    let single_core = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    for (name, search) in [
        ("441 markers, search when needed", SearchPolicy::WhenNeeded),
        ("441 markers, search always", SearchPolicy::Always),
    ] {
        let track = TrackOptions {
            search,
            ..TrackOptions::default()
        };
        let outcomes = track_markers(&frame1, &templates, &positions, &track).unwrap();
        assert!(outcomes.iter().all(|o| o.position.is_ok()));
        c.bench_function(name, |b| {
            b.iter(|| {
                single_core
                    .install(|| track_markers(&frame1, &templates, &positions, &track).unwrap())
            })
        });
    }
    let mut render = c.benchmark_group("render");
    render.sample_size(10);
    render.bench_function("2056 x 1544 frame, 441 dots, 2 threads", |b| {
        b.iter(|| {
            render_frame(
                &calibration.camera,
                &calibration.face_pose,
                &second,
                &options,
                3,
            )
            .unwrap()
        })
    });
    render.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
