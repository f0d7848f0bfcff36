//! Deterministic cost figures: runs the haptic operations of the benchmarks
//! under one update policy so that callgrind can count their instructions.
//!
//! ```text
//! instruction_counts <immediate|buffered16|capacitance> <2d NODES (< 729) | 3d>
//! ```
//!
//! Each operation is repeated inside its own `measured_*` function, so
//! `valgrind --tool=callgrind --collect-atstart=no
//! --toggle-collect='instruction_counts::measured_*'` counts only those, and
//! `callgrind_annotate --inclusive=yes` gives each one's total; divide by the
//! repetitions printed here. See `docs/condense.md` for the exact commands.

use std::hint::black_box;
use std::sync::Arc;

use needle_condense::lattice::Lattice;
use needle_condense::{CondensedSystem, Condition, FullModel, UpdatePolicy};

/// Repetitions of each operation: a multiple of 32, so that buffered folds
/// (every 16 exchanges) are amortised over whole cycles and exchanges come in
/// pairs (joining and leaving σ).
const REPETITIONS: usize = 64;

#[inline(never)]
fn measured_tick_query(system: &mut CondensedSystem, coordinates: &[usize], out: &mut [f64]) {
    for _ in 0..REPETITIONS {
        system
            .unknowns_into(black_box(coordinates), black_box(&mut *out))
            .expect("coordinates are working");
    }
}

#[inline(never)]
fn measured_exchange(system: &mut CondensedSystem, coordinate: usize) {
    for _ in 0..REPETITIONS {
        system
            .exchange(black_box(coordinate))
            .expect("the model is positive definite");
    }
}

#[inline(never)]
fn measured_add_node(system: &mut CondensedSystem, node: usize) {
    system
        .add_node(black_box(node))
        .expect("the node is free and not working");
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let usage = "usage: instruction_counts <immediate|buffered16|capacitance> <2d NODES | 3d>";
    let policy = match args.get(1).map(String::as_str) {
        Some("immediate") => UpdatePolicy::Immediate,
        Some("buffered16") => UpdatePolicy::Buffered { max_pending: 16 },
        Some("capacitance") => UpdatePolicy::Capacitance,
        _ => panic!("{usage}"),
    };
    let (lattice, nodes) = match args.get(2).map(String::as_str) {
        Some("2d") => {
            let nodes: usize = args.get(3).and_then(|s| s.parse().ok()).expect(usage);
            (Lattice::new(&[27, 28], 2).expect("valid lattice"), nodes)
        }
        Some("3d") => (Lattice::new(&[11, 11, 10], 3).expect("valid lattice"), 1000),
        _ => panic!("{usage}"),
    };
    let d = lattice.dofs_per_node;
    let model =
        Arc::new(FullModel::factor(&lattice.stiffness, d, &lattice.fixed_dofs).expect("SPD"));
    let free = lattice.free_nodes();
    assert!(
        nodes < free.len(),
        "at most {} working nodes on this lattice",
        free.len() - 1
    );
    let mut system =
        CondensedSystem::new(model, &free[..nodes], policy).expect("valid working set");
    system.reserve(1);
    let needle = needle_nodes(&system, 10);
    haptic_state(&mut system, &needle);
    let coordinates: Vec<usize> = needle
        .iter()
        .flat_map(|&n| (0..d).map(move |a| (n, a)))
        .map(|(n, a)| system.coordinate(n, a).expect("working"))
        .collect();
    let mut out = vec![0.0; coordinates.len()];
    let axial = system.coordinate(needle[0], 1).expect("working");

    measured_tick_query(&mut system, &coordinates, &mut out);
    measured_exchange(&mut system, axial);
    let extra = free[nodes];
    for _ in 0..REPETITIONS {
        system.prefetch(&[extra]).expect("free node");
        measured_add_node(&mut system, extra);
        system.remove_node(extra).expect("working");
    }
    println!(
        "N = {}, |σ| = {}, {REPETITIONS} repetitions of each (measured_add_node: 1 per call); x[0] = {:e}",
        system.len(),
        (0..system.len())
            .filter(|&i| system.condition(i) == Condition::Displacement)
            .count(),
        out[0]
    );
}

/// `count` working nodes spread over the set, as the needle's.
fn needle_nodes(system: &CondensedSystem, count: usize) -> Vec<usize> {
    let nodes = system.working_nodes();
    (0..count)
        .map(|k| nodes[(k * nodes.len()) / count + nodes.len() / (2 * count)])
        .collect()
}

/// The benchmarks' haptic state: needle nodes rotated, two in three stuck
/// (every axis displacement-given), one in three slipping (lateral axis only).
fn haptic_state(system: &mut CondensedSystem, needle: &[usize]) {
    let d = system.dim();
    let (s, c) = 0.3f64.sin_cos();
    let rotation = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]];
    for (k, &node) in needle.iter().enumerate() {
        system
            .rotate_node(node, &rotation)
            .expect("proper rotation");
        let axes = if k % 3 == 0 { 1 } else { d };
        for axis in 0..axes {
            system
                .set_condition(node, axis, Condition::Displacement)
                .expect("positive pivot");
            let coordinate = system.coordinate(node, axis).expect("working");
            system
                .set_prescribed(coordinate, 1e-3 * (k + axis) as f64)
                .expect("working");
        }
    }
    system.fold();
}
