//! Time to render one camera frame of the default phantom (441 markers,
//! 2056 x 1544, 8 bit) through the true camera, and to render it and write
//! it as PNG, as the truth world does for every rendered frame. Run with
//! `cargo bench -p needle-synth --bench frames -- --warm-up-time 1 --measurement-time 20`.

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::Vector3;
use needle_synth::camera::face_point;
use needle_synth::{Scenario, TrueCamera};
use needle_vision::render_frame;

fn frames(c: &mut Criterion) {
    let scenario = Scenario::paper_default();
    let camera = TrueCamera::new(&scenario);
    let options = scenario.frames.as_ref().unwrap().render_options();
    let (nx, ny) = scenario.phantom.markers;
    let markers: Vec<Vector3<f64>> = (0..ny)
        .flat_map(|j| {
            (0..nx).map(move |i| {
                face_point([
                    0.075 * i as f64 / (nx - 1) as f64,
                    0.075 * j as f64 / (ny - 1) as f64,
                    0.0,
                ])
            })
        })
        .collect();
    let render = || {
        render_frame(
            &camera.experiment_camera,
            &camera.calibration.face_pose,
            &markers,
            &options,
            7,
        )
        .unwrap()
    };
    let mut group = c.benchmark_group("frame");
    group.sample_size(10);
    group.bench_function("render", |b| b.iter(render));
    let dir = tempfile::tempdir().unwrap();
    group.bench_function("render_and_png", |b| {
        b.iter(|| render().write_png(&dir.path().join("000000.png")).unwrap())
    });
    group.finish();
}

criterion_group!(benches, frames);
criterion_main!(benches);
