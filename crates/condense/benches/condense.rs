//! Speed of the condensed solver: the per-tick needle query, exchanges, node
//! additions and frame rotations at the paper's size (361 nodes, N = 722) for
//! every update policy side by side, the cost of an exchange against N, a 3-D
//! set of 3000 working coordinates, a full sparse re-solve for comparison, the
//! dense kernels the stored-`S` forms could use (full or half storage, f64 or
//! f32), and a stream copy for the machine's memory bandwidth. Run with short
//! times (2 shared cores), see docs/condense.md.

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
        ("capacitance", UpdatePolicy::Capacitance),
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
    for (name, policy) in [
        ("buffered16", UpdatePolicy::Buffered { max_pending: 16 }),
        ("capacitance", UpdatePolicy::Capacitance),
    ] {
        let (lattice, mut system) = planar(policy, 360);
        let needle = needle_nodes(&system, 10);
        haptic_state(&mut system, &needle);
        let extra = lattice.free_nodes()[360];
        group.bench_function(BenchmarkId::new("add_prefetched_node", name), |b| {
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
    }
    let (lattice, mut system) = planar(UpdatePolicy::Buffered { max_pending: 16 }, 360);
    let needle = needle_nodes(&system, 10);
    haptic_state(&mut system, &needle);
    let extra = lattice.free_nodes()[360];
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
        // The capacitance form with 10 needle nodes (|σ| = 16-17) as in the haptic state.
        let mut system =
            CondensedSystem::new(model.clone(), &free[..nodes], UpdatePolicy::Capacitance).unwrap();
        let needle = needle_nodes(&system, 10);
        haptic_state(&mut system, &needle);
        let axial = system.coordinate(needle[0], 1).unwrap();
        group.bench_function(BenchmarkId::new("capacitance", n), |b| {
            b.iter(|| system.exchange(black_box(axial)).unwrap())
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
    drop(system);
    let mut system = CondensedSystem::new(
        Arc::new(FullModel::factor(&lattice.stiffness, 3, &lattice.fixed_dofs).unwrap()),
        &free[..1000],
        UpdatePolicy::Capacitance,
    )
    .unwrap();
    haptic_state(&mut system, &needle);
    group.bench_function("capacitance_tick_exchange_and_query", |b| {
        b.iter(|| {
            system.exchange(black_box(axial)).unwrap();
            system.unknowns_into(&coordinates, &mut out).unwrap();
        })
    });
    group.bench_function("capacitance_tick_query", |b| {
        b.iter(|| {
            system
                .unknowns_into(black_box(&coordinates), &mut out)
                .unwrap()
        })
    });
    let extra = free[1000];
    group.bench_function("capacitance_add_prefetched_node", |b| {
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
    group.finish();
}

/// The dense kernels a stored `S` would stream at N = 722: a rank-one update
/// of the full matrix or of its lower half (half storage of the symmetric
/// `diag(s) S`), in f64 and f32, and a fold of 16 pending terms (GEMM).
fn kernels(c: &mut Criterion) {
    use faer::linalg::matmul::matmul;
    use faer::linalg::matmul::triangular::{self, BlockStructure};
    use faer::{Accum, Mat, Par};
    let mut group = c.benchmark_group("kernels_N722");
    let n = 722;
    let mut full = Mat::<f64>::from_fn(n, n, |i, j| 1.0 / (1.0 + (i + j) as f64));
    let u = Mat::<f64>::from_fn(n, 16, |i, j| ((i * 7 + j) % 13) as f64 * 1e-3);
    let w = Mat::<f64>::from_fn(n, 16, |i, j| ((i * 5 + j) % 11) as f64 * 1e-3);
    group.bench_function("rank_one_full_f64", |b| {
        b.iter(|| {
            matmul(
                full.as_mut(),
                Accum::Add,
                u.col(0).as_mat(),
                w.col(0).transpose().as_mat(),
                -1.0,
                Par::Seq,
            )
        })
    });
    group.bench_function("rank_one_lower_half_f64", |b| {
        b.iter(|| {
            triangular::matmul(
                full.as_mut(),
                BlockStructure::TriangularLower,
                Accum::Add,
                u.col(0).as_mat(),
                BlockStructure::Rectangular,
                u.col(0).transpose().as_mat(),
                BlockStructure::Rectangular,
                -1.0,
                Par::Seq,
            )
        })
    });
    let mut single = Mat::<f32>::from_fn(n, n, |i, j| 1.0 / (1.0 + (i + j) as f32));
    let u32 = Mat::<f32>::from_fn(n, 1, |i, _| (i % 13) as f32 * 1e-3);
    let w32 = Mat::<f32>::from_fn(n, 1, |i, _| (i % 11) as f32 * 1e-3);
    group.bench_function("rank_one_full_f32", |b| {
        b.iter(|| {
            matmul(
                single.as_mut(),
                Accum::Add,
                u32.as_ref(),
                w32.transpose(),
                -1.0,
                Par::Seq,
            )
        })
    });
    group.bench_function("fold16_full_f64", |b| {
        b.iter(|| {
            matmul(
                full.as_mut(),
                Accum::Add,
                u.as_ref(),
                w.transpose(),
                -1.0,
                Par::Seq,
            )
        })
    });
    group.bench_function("fold16_lower_half_f64", |b| {
        b.iter(|| {
            triangular::matmul(
                full.as_mut(),
                BlockStructure::TriangularLower,
                Accum::Add,
                u.as_ref(),
                BlockStructure::Rectangular,
                u.transpose(),
                BlockStructure::Rectangular,
                -1.0,
                Par::Seq,
            )
        })
    });
    black_box((&full, &single));
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
    targets = paper_size, scaling, spatial, kernels, stream
}
criterion_main!(benches);
