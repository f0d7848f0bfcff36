//! Speed of the condensed solver: the per-tick needle query, exchanges, node
//! additions and frame rotations at the paper's size (361 nodes, N = 722), the
//! cost of an exchange against N, a 3-D set of 3000 working coordinates, a full
//! sparse re-solve for comparison, and a stream copy for the machine's memory
//! bandwidth. Run with short times (2 shared cores), see docs/condense.md.

use std::hint::black_box;
use std::sync::Arc;
use std::time::{Duration, Instant};

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use needle_condense::lattice::Lattice;
use needle_condense::{CondensedSystem, Condition, FullModel, UpdatePolicy};

/// Needle nodes of a benchmark state: `count` working nodes spread over the set.
fn needle_nodes(system: &CondensedSystem, count: usize) -> Vec<usize> {
    let nodes = system.working_nodes();
    (0..count)
        .map(|k| nodes[(k * nodes.len()) / count + nodes.len() / (2 * count)])
        .collect()
}

/// A state as the haptic loop sees it: needle nodes rotated, most stuck (both
/// axes displacement-given), every third slipping (lateral axis only).
fn haptic_state(system: &mut CondensedSystem, needle: &[usize]) {
    let d = system.dim();
    for (k, &node) in needle.iter().enumerate() {
        let mut r = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let (s, c) = 0.3f64.sin_cos();
        r[0][0] = c;
        r[0][1] = -s;
        r[1][0] = s;
        r[1][1] = c;
        system.rotate_node(node, &r).unwrap();
        let axes = if k % 3 == 0 { 1 } else { d };
        for axis in 0..axes {
            system
                .set_condition(node, axis, Condition::Displacement)
                .unwrap();
            system
                .set_prescribed(
                    system.coordinate(node, axis).unwrap(),
                    1e-3 * (k + axis) as f64,
                )
                .unwrap();
        }
    }
    system.fold();
}

fn planar(policy: UpdatePolicy, working: usize) -> (Lattice, CondensedSystem) {
    let lattice = Lattice::new(&[19, 20], 1).unwrap();
    let model = Arc::new(FullModel::factor(&lattice.stiffness, 2, &lattice.fixed_dofs).unwrap());
    let free = lattice.free_nodes();
    let system = CondensedSystem::new(model, &free[..working], policy).unwrap();
    (lattice, system)
}

fn paper_size(c: &mut Criterion) {
    let mut group = c.benchmark_group("paper_size_N722");
    for (name, policy) in [
        ("immediate", UpdatePolicy::Immediate),
        ("buffered16", UpdatePolicy::Buffered { max_pending: 16 }),
        ("buffered32", UpdatePolicy::Buffered { max_pending: 32 }),
        ("buffered64", UpdatePolicy::Buffered { max_pending: 64 }),
    ] {
        let (_, mut system) = planar(policy, 361);
        assert_eq!(system.len(), 722);
        let needle = needle_nodes(&system, 10);
        haptic_state(&mut system, &needle);
        let coordinates: Vec<usize> = needle
            .iter()
            .flat_map(|&n| (0..2).map(move |a| (n, a)))
            .map(|(n, a)| system.coordinate(n, a).unwrap())
            .collect();
        let mut out = vec![0.0; coordinates.len()];
        // Half a buffer of pending updates, as between folds.
        for k in 0..8 {
            let i = system.coordinate(needle[k % needle.len()], 1).unwrap();
            system.exchange(i).unwrap();
            system.exchange(i).unwrap();
        }
        if let UpdatePolicy::Buffered { max_pending } = policy {
            while system.pending() != max_pending / 2 {
                let i = system.coordinate(needle[0], 1).unwrap();
                system.exchange(i).unwrap();
            }
        }
        group.bench_function(BenchmarkId::new("tick_query_20_coordinates", name), |b| {
            b.iter(|| {
                system
                    .unknowns_into(black_box(&coordinates), &mut out)
                    .unwrap()
            })
        });
        let slip = needle[0];
        let slip_axial = system.coordinate(slip, 1).unwrap();
        group.bench_function(BenchmarkId::new("exchange", name), |b| {
            b.iter(|| system.exchange(black_box(slip_axial)).unwrap())
        });
        // The exchanges above leave the axial axis either way: make the node slip again.
        system.set_condition(slip, 1, Condition::Force).unwrap();
        group.bench_function(BenchmarkId::new("rotate_slipping_node_eq10", name), |b| {
            b.iter(|| system.rotate_node_by_angle(slip, black_box(1e-3)).unwrap())
        });
        let stuck = needle[1];
        group.bench_function(BenchmarkId::new("rotate_stuck_node_eq9", name), |b| {
            b.iter(|| system.rotate_node_by_angle(stuck, black_box(1e-3)).unwrap())
        });
        let mut all = vec![0.0; system.len()];
        group.bench_function(BenchmarkId::new("graphics_query_all", name), |b| {
            b.iter(|| system.unknowns_all_into(&mut all).unwrap())
        });
    }
    // Adding a prefetched node to 360 working nodes (state with 10 needle nodes).
    let (lattice, mut system) = planar(UpdatePolicy::Buffered { max_pending: 16 }, 360);
    let needle = needle_nodes(&system, 10);
    haptic_state(&mut system, &needle);
    let extra = lattice.free_nodes()[360];
    group.bench_function("add_prefetched_node", |b| {
        b.iter_custom(|iterations| {
            let mut total = Duration::ZERO;
            for _ in 0..iterations {
                system.prefetch(&[extra]).unwrap();
                let start = Instant::now();
                system.add_node(black_box(extra)).unwrap();
                total += start.elapsed();
                system.remove_node(extra).unwrap();
            }
            total
        })
    });
    group.bench_function("add_node_with_solve", |b| {
        b.iter_custom(|iterations| {
            let mut total = Duration::ZERO;
            for _ in 0..iterations {
                let start = Instant::now();
                system.add_node(black_box(extra)).unwrap();
                total += start.elapsed();
                system.remove_node(extra).unwrap();
            }
            total
        })
    });
    group.bench_function("fold_16", |b| {
        b.iter_custom(|iterations| {
            let mut total = Duration::ZERO;
            let i = system.coordinate(needle[0], 1).unwrap();
            for _ in 0..iterations {
                while system.pending() < 16 {
                    system.exchange(i).unwrap();
                }
                let start = Instant::now();
                system.fold();
                total += start.elapsed();
            }
            total
        })
    });
    // The full sparse alternative: factorise the free-dof stiffness and solve once.
    group.bench_function("full_sparse_refactor_and_solve", |b| {
        b.iter(|| {
            let model = FullModel::factor(&lattice.stiffness, 2, &lattice.fixed_dofs).unwrap();
            let mut rhs = vec![1.0; model.n_free()];
            model.solve(&mut rhs).unwrap();
            black_box(rhs)
        })
    });
    let model = FullModel::factor(&lattice.stiffness, 2, &lattice.fixed_dofs).unwrap();
    let mut rhs = vec![1.0; model.n_free()];
    group.bench_function("full_sparse_solve_only", |b| {
        b.iter(|| model.solve(black_box(&mut rhs)).unwrap())
    });
    group.bench_function("condense_361_nodes", |b| {
        let model = Arc::new(model.clone());
        let free = lattice.free_nodes();
        b.iter(|| {
            CondensedSystem::new(model.clone(), &free[..361], UpdatePolicy::Immediate).unwrap()
        })
    });
    group.finish();
}

fn scaling(c: &mut Criterion) {
    let mut group = c.benchmark_group("exchange_vs_N");
    let lattice = Lattice::new(&[27, 28], 2).unwrap();
    let model = Arc::new(FullModel::factor(&lattice.stiffness, 2, &lattice.fixed_dofs).unwrap());
    let free = lattice.free_nodes();
    for nodes in [64usize, 128, 256, 361, 512, 729] {
        let mut system =
            CondensedSystem::new(model.clone(), &free[..nodes], UpdatePolicy::Immediate).unwrap();
        let n = system.len();
        let i = n / 2;
        group.bench_function(BenchmarkId::new("immediate", n), |b| {
            b.iter(|| system.exchange(black_box(i)).unwrap())
        });
        // A slipping node: lateral axis displacement-given, axial force-given.
        let node = system.working_nodes()[nodes / 3];
        system
            .set_condition(node, 0, Condition::Displacement)
            .unwrap();
        system.set_condition(node, 1, Condition::Force).unwrap();
        group.bench_function(BenchmarkId::new("slip_rotation_immediate", n), |b| {
            b.iter(|| system.rotate_node_by_angle(node, black_box(1e-3)).unwrap())
        });
    }
    group.finish();
}

fn spatial(c: &mut Criterion) {
    let mut group = c.benchmark_group("spatial_N3000");
    let lattice = Lattice::new(&[11, 11, 10], 3).unwrap();
    let model = Arc::new(FullModel::factor(&lattice.stiffness, 3, &lattice.fixed_dofs).unwrap());
    let free = lattice.free_nodes();
    let mut system = CondensedSystem::new(
        model,
        &free[..1000],
        UpdatePolicy::Buffered { max_pending: 32 },
    )
    .unwrap();
    assert_eq!(system.len(), 3000);
    let needle = needle_nodes(&system, 10);
    haptic_state(&mut system, &needle);
    let coordinates: Vec<usize> = needle
        .iter()
        .flat_map(|&n| (0..3).map(move |a| (n, a)))
        .map(|(n, a)| system.coordinate(n, a).unwrap())
        .collect();
    let mut out = vec![0.0; coordinates.len()];
    let slip = needle[0];
    let axial = system.coordinate(slip, 1).unwrap();
    group.bench_function("tick_exchange_and_query_amortised_fold", |b| {
        b.iter(|| {
            system.exchange(black_box(axial)).unwrap();
            system.unknowns_into(&coordinates, &mut out).unwrap();
        })
    });
    group.bench_function("tick_exchange_and_query_no_fold", |b| {
        b.iter_custom(|iterations| {
            let mut total = Duration::ZERO;
            for _ in 0..iterations {
                if system.pending() == 32 {
                    system.fold();
                }
                let start = Instant::now();
                system.exchange(black_box(axial)).unwrap();
                system.unknowns_into(&coordinates, &mut out).unwrap();
                total += start.elapsed();
            }
            total
        })
    });
    group.bench_function("fold_32", |b| {
        b.iter_custom(|iterations| {
            let mut total = Duration::ZERO;
            for _ in 0..iterations {
                while system.pending() < 32 {
                    system.exchange(axial).unwrap();
                }
                let start = Instant::now();
                system.fold();
                total += start.elapsed();
            }
            total
        })
    });
    group.finish();
}

/// Memory bandwidth: copy a buffer the size of the N = 722 matrix (L3-resident
/// here) and a 64 MiB one (DRAM).
fn stream(c: &mut Criterion) {
    let mut group = c.benchmark_group("stream_copy");
    for mib in [4usize, 64] {
        let len = mib * 1024 * 1024 / 8;
        let source = vec![1.0f64; len];
        let mut target = vec![0.0f64; len];
        group.throughput(criterion::Throughput::Bytes((2 * len * 8) as u64));
        group.bench_function(BenchmarkId::new("copy_MiB", mib), |b| {
            b.iter(|| target.copy_from_slice(black_box(&source)))
        });
    }
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(2)).sample_size(20);
    targets = paper_size, scaling, spatial, stream
}
criterion_main!(benches);
