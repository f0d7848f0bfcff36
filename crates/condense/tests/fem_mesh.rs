//! On a real finite-element mesh (needle-fem, plane-strain T3 and T6
//! rectangles fixed on the back face): a needle enters from the front face,
//! its nodes are brought in one by one, stuck or slipping, and the condensed
//! system agrees with needle-fem's own direct solve (global frames) and with
//! the dense reference (rotated needle frames).

mod support;

use std::sync::Arc;

use needle_condense::{CondensedSystem, Condition, FullModel, UpdatePolicy};
use needle_fem::{
    Assembler, Dirichlet, ElementKind, Face, Formulation, LinearProblem, Material, Materials,
    RectangleMesh,
};
use support::{Reference, WorkingNode, rotation};

const TOLERANCE: f64 = 1e-9;

#[test]
fn needle_insertion_matches_needle_fem() {
    for (kind, policy) in [
        (ElementKind::Tri3, UpdatePolicy::Buffered { max_pending: 4 }),
        (ElementKind::Tri6, UpdatePolicy::Buffered { max_pending: 4 }),
        (ElementKind::Tri6, UpdatePolicy::Capacitance),
    ] {
        let mesh = RectangleMesh::uniform(0.075, 0.075, 6, 6)
            .unwrap()
            .build(kind)
            .unwrap();
        let formulation = Formulation::PlaneStrain { thickness: 0.0075 };
        let materials = Materials::homogeneous(Material::new(25.3e3, 0.48).unwrap());
        let assembler = Assembler::new(mesh.clone(), formulation).unwrap();
        let stiffness = assembler.stiffness(&materials).unwrap();
        let back = Dirichlet::fixed_face(&mesh, Face::Back);
        let fixed: Vec<usize> = back.iter().map(|(dof, _)| dof).collect();
        let model = Arc::new(FullModel::factor(&stiffness, 2, &fixed).unwrap());

        let needle = mesh.nodes_along_segment([0.0375, 0.0], [0.0375, 0.04], 1e-6);
        assert!(needle.len() >= 3, "needle nodes {needle:?}");
        let visible: Vec<usize> = mesh
            .nodes_on_face(Face::Front)
            .into_iter()
            .filter(|n| !needle.contains(n))
            .step_by(2)
            .collect();
        let mut system = CondensedSystem::new(model, &visible, policy).unwrap();
        system.reserve(needle.len());
        // Insertion: each needle node is prefetched, added, and stuck; the tip one slips.
        for (k, &node) in needle.iter().enumerate() {
            if let Some(&next) = needle.get(k + 1) {
                system.prefetch(&[next]).unwrap();
            }
            system.add_node(node).unwrap();
            system
                .set_condition(node, 0, Condition::Displacement)
                .unwrap();
            system
                .set_condition(node, 1, Condition::Displacement)
                .unwrap();
        }
        let tip = *needle.last().unwrap();
        system.set_condition(tip, 1, Condition::Force).unwrap();
        let mut record = Vec::new();
        for &node in system.working_nodes().to_vec().iter() {
            let on_needle = needle.iter().position(|&n| n == node);
            let mut w = WorkingNode {
                node,
                frame: rotation(2, 0.0, [0.0; 3]),
                displacement_given: [false; 3],
                prescribed: [0.0; 3],
            };
            if let Some(k) = on_needle {
                w.displacement_given = [true, node != tip, false];
                w.prescribed = [
                    2e-4 * (k as f64 + 1.0),
                    if node == tip { -0.05 } else { -1e-3 },
                    0.0,
                ];
            } else {
                w.prescribed = [0.0, 0.01, 0.0];
            }
            for axis in 0..2 {
                system
                    .set_prescribed(system.coordinate(node, axis).unwrap(), w.prescribed[axis])
                    .unwrap();
            }
            record.push(w);
        }

        // needle-fem's own solve: displacement-given coordinates as Dirichlet values.
        let mut dirichlet = back.clone();
        let mut loads = vec![0.0; mesh.dof_count()];
        for w in &record {
            for axis in 0..2 {
                let dof = 2 * w.node + axis;
                if w.displacement_given[axis] {
                    dirichlet.set(dof, w.prescribed[axis]).unwrap();
                } else {
                    loads[dof] = w.prescribed[axis];
                }
            }
        }
        let mut problem = LinearProblem::new(assembler, vec![], dirichlet).unwrap();
        problem.factorize(&materials).unwrap();
        let solution = problem.solve(&loads).unwrap();
        let scale_u = solution
            .displacement
            .iter()
            .fold(0.0f64, |m, v| m.max(v.abs()));
        let scale_f = solution
            .reactions
            .iter()
            .chain(&loads)
            .fold(0.0f64, |m, v| m.max(v.abs()));
        for w in &record {
            let state = system.node_state(w.node).unwrap();
            for axis in 0..2 {
                let dof = 2 * w.node + axis;
                let force = loads[dof] + solution.reactions[dof];
                assert!(
                    (state.displacement[axis] - solution.displacement[dof]).abs()
                        <= TOLERANCE * scale_u
                );
                assert!(
                    (state.force[axis] - force).abs() <= TOLERANCE * scale_f,
                    "{kind:?} node {} axis {axis}: {} vs {force}",
                    w.node,
                    state.force[axis]
                );
            }
        }

        // Tilt the needle: every needle node's frame follows (eq. (9) for stuck
        // nodes, eq. (10) for the slipping tip); compare with the dense reference.
        let reference = Reference::from_stiffness(&stiffness, 2, &fixed);
        for w in record.iter_mut().filter(|w| needle.contains(&w.node)) {
            system.rotate_node_by_angle(w.node, 0.15).unwrap();
            w.frame = rotation(2, 0.15, [0.0; 3]);
            for axis in 0..2 {
                system
                    .set_prescribed(system.coordinate(w.node, axis).unwrap(), w.prescribed[axis])
                    .unwrap();
            }
        }
        let expected = reference.solve(&record);
        let scale_u = expected
            .iter()
            .flat_map(|e| e[..2].iter().map(|p| p.0.abs()))
            .fold(0.0, f64::max);
        let scale_f = expected
            .iter()
            .flat_map(|e| e[..2].iter().map(|p| p.1.abs()))
            .fold(0.0, f64::max);
        for (w, e) in record.iter().zip(&expected) {
            let state = system.node_state(w.node).unwrap();
            for axis in 0..2 {
                assert!((state.displacement[axis] - e[axis].0).abs() <= TOLERANCE * scale_u);
                assert!((state.force[axis] - e[axis].1).abs() <= TOLERANCE * scale_f);
            }
        }
        assert!(system.drift(1) < 1e-10);
    }
}
