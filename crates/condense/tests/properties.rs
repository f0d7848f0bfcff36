//! Exact agreement with the full model: after any random sequence of node
//! additions and removals, exchanges, rotations (equation (9)) and slip
//! rotations (equation (10)), every displacement and force of the condensed
//! system equals the direct solve of the same mixed problem on the full mesh.

mod support;

use std::sync::Arc;

use needle_condense::lattice::Lattice;
use needle_condense::{CondensedSystem, FullModel, UpdatePolicy};
use proptest::prelude::*;
use support::{Reference, WorkingNode, compose, rotation};

/// Relative tolerance of the comparison with the direct solve.
const TOLERANCE: f64 = 1e-9;

#[derive(Debug, Clone)]
enum Op {
    Add(usize),
    Remove(usize),
    Exchange(usize, usize),
    Rotate(usize, f64, [f64; 3]),
    Refresh,
}

fn op() -> impl Strategy<Value = Op> {
    prop_oneof![
        2 => any::<usize>().prop_map(Op::Add),
        1 => any::<usize>().prop_map(Op::Remove),
        3 => (any::<usize>(), 0usize..3).prop_map(|(n, a)| Op::Exchange(n, a)),
        3 => (any::<usize>(), -1.0f64..1.0, [0.1f64..1.0, -1.0f64..1.0, -1.0f64..1.0])
            .prop_map(|(n, angle, axis)| Op::Rotate(n, angle, axis)),
        1 => Just(Op::Refresh),
    ]
}

/// Runs `ops` on both the condensed system and the test's own record of the
/// problem, then prescribes `values` and compares every unknown.
fn check(
    shape: &[usize],
    seed: u64,
    policy: UpdatePolicy,
    ops: &[Op],
    values: &[f64],
) -> Result<(), TestCaseError> {
    let lattice = Lattice::new(shape, seed).unwrap();
    let d = lattice.dofs_per_node;
    let model = Arc::new(FullModel::factor(&lattice.stiffness, d, &lattice.fixed_dofs).unwrap());
    let reference = Reference::new(&lattice);
    let free_nodes = lattice.free_nodes();
    let initial = [free_nodes[0], free_nodes[free_nodes.len() / 2]];
    let mut system = CondensedSystem::new(model, &initial, policy).unwrap();
    let identity = rotation(d, 0.0, [1.0, 0.0, 0.0]);
    let mut record: Vec<WorkingNode> = initial
        .iter()
        .map(|&node| WorkingNode {
            node,
            frame: identity,
            displacement_given: [false; 3],
            prescribed: [0.0; 3],
        })
        .collect();
    for op in ops {
        match *op {
            Op::Add(pick) => {
                let candidates: Vec<usize> = free_nodes
                    .iter()
                    .copied()
                    .filter(|&n| !system.is_working(n))
                    .collect();
                if let Some(&node) = candidates.get(pick % candidates.len().max(1)) {
                    if pick % 2 == 0 {
                        system.prefetch(&[node]).unwrap();
                    }
                    system.add_node(node).unwrap();
                    record.push(WorkingNode {
                        node,
                        frame: identity,
                        displacement_given: [false; 3],
                        prescribed: [0.0; 3],
                    });
                }
            }
            Op::Remove(pick) => {
                if record.len() > 1 {
                    let w = record.remove(pick % record.len());
                    system.remove_node(w.node).unwrap();
                }
            }
            Op::Exchange(pick, axis) => {
                let axis = axis % d;
                let len = record.len();
                let w = &mut record[pick % len];
                // Keep at least one force-given coordinate somewhere is not needed: the
                // fixed bottom layer keeps every mixed problem well posed.
                system
                    .exchange(system.coordinate(w.node, axis).unwrap())
                    .unwrap();
                w.displacement_given[axis] = !w.displacement_given[axis];
            }
            Op::Rotate(pick, angle, axis) => {
                let len = record.len();
                let w = &mut record[pick % len];
                let r = rotation(d, angle, axis);
                system.rotate_node(w.node, &r).unwrap();
                w.frame = compose(&w.frame, &r);
            }
            Op::Refresh => system.refresh().unwrap(),
        }
    }
    // Prescribe fresh values everywhere and compare.
    for (k, w) in record.iter_mut().enumerate() {
        for axis in 0..d {
            let value = values[(k * d + axis) % values.len()];
            // Displacements and forces on comparable scales for this lattice.
            w.prescribed[axis] = if w.displacement_given[axis] {
                0.1 * value
            } else {
                value
            };
            system
                .set_prescribed(system.coordinate(w.node, axis).unwrap(), w.prescribed[axis])
                .unwrap();
        }
    }
    let expected = reference.solve(&record);
    let scale_u = expected
        .iter()
        .flat_map(|e| e[..d].iter().map(|p| p.0.abs()))
        .fold(0.0, f64::max);
    let scale_f = expected
        .iter()
        .flat_map(|e| e[..d].iter().map(|p| p.1.abs()))
        .fold(0.0, f64::max);
    for (w, e) in record.iter().zip(&expected) {
        let state = system.node_state(w.node).unwrap();
        for axis in 0..d {
            let (u, f) = e[axis];
            prop_assert!(
                (state.displacement[axis] - u).abs() <= TOLERANCE * scale_u,
                "node {} axis {axis}: displacement {} vs direct {u}",
                w.node,
                state.displacement[axis]
            );
            prop_assert!(
                (state.force[axis] - f).abs() <= TOLERANCE * scale_f,
                "node {} axis {axis}: force {} vs direct {f}",
                w.node,
                state.force[axis]
            );
        }
        let frame = system.frame(w.node).unwrap();
        for r in 0..d {
            for c in 0..d {
                prop_assert!((frame[r][c] - w.frame[r][c]).abs() < 1e-12);
            }
        }
    }
    // The per-tick query agrees with the per-node one.
    let coordinates: Vec<usize> = (0..system.len()).collect();
    let mut tick = vec![0.0; coordinates.len()];
    system.unknowns_into(&coordinates, &mut tick).unwrap();
    let mut all = vec![0.0; coordinates.len()];
    system.unknowns_all_into(&mut all).unwrap();
    for (a, b) in tick.iter().zip(&all) {
        prop_assert!((a - b).abs() <= TOLERANCE * scale_u.max(scale_f));
    }
    prop_assert!(system.drift(7) < 1e-10, "drift {}", system.drift(7));
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    #[test]
    fn planar_sequences_match_the_full_model(
        seed in 0u64..1000,
        ops in prop::collection::vec(op(), 1..24),
        values in prop::collection::vec(-1.0f64..1.0, 8),
        form in 0usize..3,
    ) {
        let policy = [UpdatePolicy::Immediate, UpdatePolicy::Buffered { max_pending: 3 }, UpdatePolicy::Capacitance][form];
        check(&[4, 5], seed, policy, &ops, &values)?;
    }

    #[test]
    fn spatial_sequences_match_the_full_model(
        seed in 0u64..1000,
        ops in prop::collection::vec(op(), 1..20),
        values in prop::collection::vec(-1.0f64..1.0, 9),
        form in 0usize..3,
    ) {
        let policy = [UpdatePolicy::Immediate, UpdatePolicy::Buffered { max_pending: 4 }, UpdatePolicy::Capacitance][form];
        check(&[3, 3, 3], seed, policy, &ops, &values)?;
    }
}
