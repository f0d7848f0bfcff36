//! Reading and writing a full-size campaign: 30 trials x 300 frames x 441
//! markers (about 4 million marker rows), the default phantom's grid.
//!
//! `cargo bench -p needle-data --bench read -- --warm-up-time 1 --measurement-time 20`

use std::hint::black_box;
use std::time::Instant;

use criterion::{Criterion, criterion_group, criterion_main};
use needle_data::{
    BundleBuilder, Campaign, Face, MarkerRest, Phantom, ToolSample, Trial, TrialKind, WriteOptions,
    read_bundle, write_bundle,
};

const TRIALS: usize = 30;
const FRAMES: u64 = 300;
const GRID: u32 = 21;

fn campaign() -> Campaign {
    let size = 0.075;
    let phantom = Phantom {
        width: size,
        depth: size,
        thickness: 0.0075,
        fixed: vec![Face::Back],
    };
    let spacing = size / f64::from(GRID + 1);
    let rest: Vec<MarkerRest> = (0..GRID * GRID)
        .map(|id| MarkerRest {
            id,
            x: spacing * f64::from(id % GRID + 1),
            y: spacing * f64::from(id / GRID + 1),
        })
        .collect();
    let mut builder = BundleBuilder::new("bench", phantom);
    builder.markers_rest(rest.clone());
    for trial in 0..TRIALS {
        let data = builder.trial(Trial {
            id: format!("needle-{trial:02}"),
            kind: TrialKind::Needle,
            velocity: 0.001,
            day: trial as f64,
        });
        for frame in 0..FRAMES {
            let t = frame as f64 / 30.0;
            let depth = 0.001 * t;
            data.tool.push(ToolSample {
                t,
                tip_x: 0.0375,
                tip_y: depth,
                theta: 0.0,
                fx: 1e-3 * (frame as f64).sin(),
                fy: 0.3 * depth / 0.01,
                mz: 0.0,
            });
            let markers = rest.iter().map(|m| {
                let pull = depth * (-((m.x - 0.0375).powi(2)) / 1e-4).exp() * 0.1;
                (m.id, [m.x + 1e-7 * f64::from(m.id % 7), m.y + pull])
            });
            data.markers_mut().push_frame(frame, t, markers).unwrap();
        }
    }
    builder.finish()
}

fn bench(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("campaign");
    let campaign = campaign();
    let start = Instant::now();
    write_bundle(&path, &campaign, WriteOptions::default()).unwrap();
    eprintln!(
        "write_bundle (write + validate + rename) of {} marker rows: {:.2} s",
        campaign
            .trials
            .iter()
            .filter_map(|t| t.markers.as_ref())
            .map(|m| m.row_count())
            .sum::<usize>(),
        start.elapsed().as_secs_f64()
    );
    let mut group = c.benchmark_group("campaign_30x300x441");
    group.sample_size(10);
    group.bench_function("read_bundle", |b| {
        b.iter(|| black_box(read_bundle(&path).unwrap()))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
