//! Time to generate a whole campaign (mesh, factorisations, every trial,
//! noise, writing the bundle). Run with
//! `cargo bench -p needle-synth --bench campaign -- --warm-up-time 1 --measurement-time 60`.
//! The target is 20 s for the paper's default campaign.

use criterion::{Criterion, criterion_group, criterion_main};
use needle_synth::{Scenario, generate};

fn campaign(c: &mut Criterion) {
    let mut group = c.benchmark_group("campaign");
    group.sample_size(10);
    for scenario in [Scenario::quick(), Scenario::paper_default()] {
        group.bench_function(scenario.name.clone(), |b| {
            b.iter(|| {
                let dir = tempfile::tempdir().unwrap();
                generate(
                    &scenario,
                    &dir.path().join("bundle"),
                    &dir.path().join("truth.ron"),
                    |_| {},
                )
                .unwrap()
            })
        });
    }
    group.finish();
}

criterion_group!(benches, campaign);
criterion_main!(benches);
