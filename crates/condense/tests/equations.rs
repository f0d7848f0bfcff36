//! Equations (8), (9) and (10) and the appendix, each against the direct
//! computation it replaces; plus continuity, drift, policies and input errors.

mod support;

use std::sync::Arc;

use nalgebra::DMatrix;
use needle_condense::lattice::Lattice;
use needle_condense::{
    CondenseError, CondensedSystem, Condition, FullModel, UpdatePolicy,
    appendix_slip_inverse_columns,
};
use support::{relative_difference, rotation, to_nalgebra};

fn system(shape: &[usize], nodes: usize, policy: UpdatePolicy) -> CondensedSystem {
    let lattice = Lattice::new(shape, 11).unwrap();
    let model = FullModel::factor(
        &lattice.stiffness,
        lattice.dofs_per_node,
        &lattice.fixed_dofs,
    )
    .unwrap();
    let free = lattice.free_nodes();
    let step = free.len() / nodes;
    let working: Vec<usize> = (0..nodes).map(|k| free[k * step]).collect();
    CondensedSystem::new(Arc::new(model), &working, policy).unwrap()
}

/// The mixed matrix by re-inversion: from `K_W = C^{-1}`, with σ the
/// displacement-given set, `u_τ = K_ττ^{-1}(f_τ - K_τσ u_σ)` and
/// `f_σ = (K_σσ - K_στ K_ττ^{-1} K_τσ) u_σ + K_στ K_ττ^{-1} f_τ`.
fn mixed_by_reinversion(compliance: &DMatrix<f64>, sigma: &[bool]) -> DMatrix<f64> {
    let n = compliance.nrows();
    let k = compliance.clone().try_inverse().unwrap();
    let s: Vec<usize> = (0..n).filter(|&i| sigma[i]).collect();
    let t: Vec<usize> = (0..n).filter(|&i| !sigma[i]).collect();
    let sub = |rows: &[usize], cols: &[usize]| {
        DMatrix::from_fn(rows.len(), cols.len(), |r, c| k[(rows[r], cols[c])])
    };
    let k_tt_inv = sub(&t, &t).try_inverse().unwrap();
    let (k_ts, k_st, k_ss) = (sub(&t, &s), sub(&s, &t), sub(&s, &s));
    let mut out = DMatrix::zeros(n, n);
    let blocks = [
        (&t, &t, k_tt_inv.clone()),
        (&t, &s, -&k_tt_inv * &k_ts),
        (&s, &s, &k_ss - &k_st * &k_tt_inv * &k_ts),
        (&s, &t, &k_st * &k_tt_inv),
    ];
    for (rows, cols, block) in blocks {
        for (r, &i) in rows.iter().enumerate() {
            for (c, &j) in cols.iter().enumerate() {
                out[(i, j)] = block[(r, c)];
            }
        }
    }
    out
}

#[test]
fn exchanges_match_reinversion_and_the_printed_equation_8_does_not() {
    let mut sys = system(&[5, 6], 8, UpdatePolicy::Immediate);
    let compliance = to_nalgebra(&sys.current_matrix());
    let n = sys.len();
    let mut sigma = vec![false; n];
    for &i in &[3usize, 4, 9, 0] {
        let before = to_nalgebra(&sys.current_matrix());
        sys.exchange(i).unwrap();
        sigma[i] = true;
        let after = to_nalgebra(&sys.current_matrix());
        let direct = mixed_by_reinversion(&compliance, &sigma);
        assert!(
            relative_difference(&after, &direct) < 1e-11,
            "exchange {i}: {}",
            relative_difference(&after, &direct)
        );

        // Equation (8) as printed: [c_i]_i = [r_i]_i = p - 1.
        let p = before[(i, i)];
        let mut c = before.column(i).into_owned();
        let mut r = before.row(i).transpose();
        c[i] = p - 1.0;
        r[i] = p - 1.0;
        let printed = &before - &c * r.transpose() / p;
        assert!((printed[(i, i)] - (2.0 - 1.0 / p)).abs() < 1e-12);
        assert!(relative_difference(&printed, &direct) > 1e-3);
        // With [c_i]_i = p + 1 it is the exchange.
        c[i] = p + 1.0;
        let corrected = &before - &c * r.transpose() / p;
        assert!(relative_difference(&corrected, &direct) < 1e-11);
        // With [r_i]_i = p + 1 instead it is the exchange of the negated pair
        // (-x_i, -y_i): the same matrix with row and column i negated, diagonal kept.
        c[i] = p - 1.0;
        r[i] = p + 1.0;
        let mut negated = &before - &c * r.transpose() / p;
        let keep = negated[(i, i)];
        negated.row_mut(i).neg_mut();
        negated.column_mut(i).neg_mut();
        negated[(i, i)] = keep;
        assert!(relative_difference(&negated, &direct) < 1e-11);
    }
    // Exchanging back restores the compliance.
    for &i in &[9usize, 3, 0, 4] {
        sys.exchange(i).unwrap();
    }
    assert!(relative_difference(&to_nalgebra(&sys.current_matrix()), &compliance) < 1e-11);
}

fn node_block_operator(
    n: usize,
    b0: usize,
    block: &[[f64; 3]; 3],
    d: usize,
    identity_elsewhere: bool,
) -> DMatrix<f64> {
    let mut a = if identity_elsewhere {
        DMatrix::identity(n, n)
    } else {
        DMatrix::zeros(n, n)
    };
    for r in 0..d {
        for c in 0..d {
            a[(b0 + r, b0 + c)] = block[r][c];
        }
    }
    a
}

#[test]
fn uniform_rotations_match_the_product_of_equation_9() {
    for (shape, d, policy) in [
        (
            &[5usize, 6][..],
            2usize,
            UpdatePolicy::Buffered { max_pending: 2 },
        ),
        (&[3, 4, 3][..], 3, UpdatePolicy::Buffered { max_pending: 2 }),
        (&[5, 6][..], 2, UpdatePolicy::Capacitance),
        (&[3, 4, 3][..], 3, UpdatePolicy::Capacitance),
    ] {
        let mut sys = system(shape, 6, policy);
        let n = sys.len();
        let nodes = sys.working_nodes().to_vec();
        // Node 1 fully displacement-given, node 2 force-given; one pending update.
        for a in 0..d {
            sys.set_condition(nodes[1], a, Condition::Displacement)
                .unwrap();
        }
        for (slot, angle) in [(1usize, 0.7), (2, -0.4)] {
            let before = to_nalgebra(&sys.current_matrix());
            let r = rotation(d, angle, [0.3, -0.5, 0.8]);
            sys.rotate_node(nodes[slot], &r).unwrap();
            let a = node_block_operator(n, slot * d, &r, d, true);
            let direct = a.transpose() * &before * &a;
            let after = to_nalgebra(&sys.current_matrix());
            assert!(
                relative_difference(&after, &direct) < 1e-13,
                "{d}-D slot {slot}"
            );
        }
    }
}

/// `(M - S N)^{-1} (S M - N)` by a dense inverse.
fn slip_direct(
    before: &DMatrix<f64>,
    b0: usize,
    r: &[[f64; 3]; 3],
    given: &[bool],
    d: usize,
) -> DMatrix<f64> {
    let n = before.nrows();
    let mut m = [[0.0; 3]; 3];
    let mut nn = [[0.0; 3]; 3];
    for a in 0..d {
        for b in 0..d {
            if given[a] == given[b] {
                m[a][b] = r[a][b]
            } else {
                nn[a][b] = r[a][b]
            }
        }
    }
    let m = node_block_operator(n, b0, &m, d, true);
    let nn = node_block_operator(n, b0, &nn, d, false);
    (&m - before * &nn).try_inverse().unwrap() * (before * &m - &nn)
}

#[test]
fn slip_rotations_match_the_inverse_of_equation_10() {
    let cases: [(&[usize], usize, &[bool]); 4] = [
        (&[5, 6], 2, &[true, false]),
        (&[5, 6], 2, &[false, true]),
        (&[3, 4, 3], 3, &[true, false, false]),
        (&[3, 4, 3], 3, &[true, true, false]),
    ];
    for (shape, d, given) in cases {
        for policy in [
            UpdatePolicy::Immediate,
            UpdatePolicy::Buffered { max_pending: 3 },
            UpdatePolicy::Capacitance,
        ] {
            let mut sys = system(shape, 6, policy);
            let nodes = sys.working_nodes().to_vec();
            sys.set_condition(nodes[0], 0, Condition::Displacement)
                .unwrap();
            for (a, &g) in given.iter().enumerate() {
                if g {
                    sys.set_condition(nodes[3], a, Condition::Displacement)
                        .unwrap();
                }
            }
            for angle in [0.3, -1.1] {
                let before = to_nalgebra(&sys.current_matrix());
                let r = rotation(d, angle, [0.2, 0.9, -0.4]);
                sys.rotate_node(nodes[3], &r).unwrap();
                let direct = slip_direct(&before, 3 * d, &r, given, d);
                let after = to_nalgebra(&sys.current_matrix());
                assert!(
                    relative_difference(&after, &direct) < 1e-12,
                    "{d}-D {given:?}: {}",
                    relative_difference(&after, &direct)
                );
            }
        }
    }
}

#[test]
fn appendix_inverse_matches_a_direct_inverse_with_sigma_corrected() {
    let mut sys = system(&[5, 6], 7, UpdatePolicy::Immediate);
    let nodes = sys.working_nodes().to_vec();
    sys.set_condition(nodes[2], 0, Condition::Displacement)
        .unwrap();
    sys.set_condition(nodes[5], 1, Condition::Displacement)
        .unwrap();
    let s = sys.current_matrix();
    let dense = to_nalgebra(&s);
    let n = dense.nrows();
    let a = 4;
    for theta in [0.25f64, -0.9, 2.0] {
        let (sn, c) = theta.sin_cos();
        let mut m = DMatrix::<f64>::identity(n, n);
        m[(a, a)] = c;
        m[(a + 1, a + 1)] = c;
        let mut nn = DMatrix::<f64>::zeros(n, n);
        nn[(a, a + 1)] = -sn;
        nn[(a + 1, a)] = sn;
        let inverse = (&m - &dense * &nn).try_inverse().unwrap();
        let columns = appendix_slip_inverse_columns(s.as_ref(), a, theta).unwrap();
        for j in 0..n {
            for col in 0..2 {
                assert!((columns[(j, col)] - inverse[(j, a + col)]).abs() < 1e-12 * inverse.amax());
            }
        }
        // Every other column of the inverse is a unit vector, as the appendix says.
        for col in (0..n).filter(|&col| col != a && col != a + 1) {
            let mut unit = DMatrix::<f64>::zeros(n, 1);
            unit[col] = 1.0;
            assert!((inverse.column(col) - unit.column(0)).amax() < 1e-12);
        }
        // The printed Σ, read literally, leaves k_aa k_bb without its sin^2.
        let k = |i: usize, j: usize| dense[(i, j)];
        let sigma = -c * c
            + c * sn * (k(a, a + 1) - k(a + 1, a))
            + sn * sn * (k(a, a + 1) * k(a + 1, a) - k(a, a) * k(a + 1, a + 1));
        let printed =
            -c * c + c * sn * (k(a, a + 1) - k(a + 1, a)) + sn * sn * (k(a, a + 1) * k(a + 1, a))
                - k(a, a) * k(a + 1, a + 1);
        let det = (&m - &dense * &nn).determinant();
        assert!((sigma + det).abs() < 1e-12 * det.abs());
        assert!((printed + det).abs() > 1e-3 * det.abs());
    }
}

#[test]
fn adding_a_node_does_not_make_the_needle_force_jump() {
    for policy in [
        UpdatePolicy::Immediate,
        UpdatePolicy::Buffered { max_pending: 4 },
        UpdatePolicy::Capacitance,
    ] {
        let lattice = Lattice::new(&[7, 8], 5).unwrap();
        let model =
            Arc::new(FullModel::factor(&lattice.stiffness, 2, &lattice.fixed_dofs).unwrap());
        let free = lattice.free_nodes();
        let needle = [free[20], free[27], free[34]];
        let mut sys = CondensedSystem::new(
            model,
            &[free[3], needle[0], needle[1], needle[2], free[40]],
            policy,
        )
        .unwrap();
        for (k, &node) in needle.iter().enumerate() {
            sys.rotate_node_by_angle(node, 0.2).unwrap();
            sys.set_condition(node, 0, Condition::Displacement).unwrap();
            sys.set_prescribed(sys.coordinate(node, 0).unwrap(), 0.01 * (k as f64 + 1.0))
                .unwrap();
            if k < 2 {
                sys.set_condition(node, 1, Condition::Displacement).unwrap();
                sys.set_prescribed(sys.coordinate(node, 1).unwrap(), -0.02)
                    .unwrap();
            } else {
                sys.set_prescribed(sys.coordinate(node, 1).unwrap(), 0.3)
                    .unwrap();
            }
        }
        let before = sys.total_force(&needle).unwrap();
        let states_before: Vec<_> = needle.iter().map(|&n| sys.node_state(n).unwrap()).collect();
        sys.prefetch(&[free[41]]).unwrap();
        assert_eq!(sys.prefetched(), 1);
        sys.add_node(free[41]).unwrap();
        sys.add_node(free[13]).unwrap();
        assert_eq!(sys.prefetched(), 0);
        let after = sys.total_force(&needle).unwrap();
        let scale = before[0].abs().max(before[1].abs());
        assert!(scale > 0.0);
        for axis in 0..2 {
            assert!(
                (after[axis] - before[axis]).abs() <= 1e-9 * scale,
                "{before:?} vs {after:?}"
            );
        }
        for (&node, state) in needle.iter().zip(&states_before) {
            let now = sys.node_state(node).unwrap();
            for axis in 0..2 {
                assert!((now.force[axis] - state.force[axis]).abs() <= 1e-9 * scale);
            }
        }
        // The new node, stuck where it is, changes nothing either.
        sys.rotate_node_by_angle(free[41], 0.2).unwrap();
        sys.set_condition(free[41], 0, Condition::Displacement)
            .unwrap();
        sys.set_condition(free[41], 1, Condition::Displacement)
            .unwrap();
        let stuck = sys.total_force(&needle).unwrap();
        for axis in 0..2 {
            assert!((stuck[axis] - before[axis]).abs() <= 1e-9 * scale);
        }
    }
}

#[test]
fn policies_agree_and_drift_stays_small() {
    let mut immediate = system(&[6, 7], 12, UpdatePolicy::Immediate);
    let mut buffered = system(&[6, 7], 12, UpdatePolicy::Buffered { max_pending: 5 });
    let mut capacitance = system(&[6, 7], 12, UpdatePolicy::Capacitance);
    let nodes = immediate.working_nodes().to_vec();
    for step in 0..120usize {
        let node = nodes[(step * 7) % nodes.len()];
        for sys in [&mut immediate, &mut buffered, &mut capacitance] {
            if step % 3 == 0 {
                sys.rotate_node_by_angle(node, 0.05 * (step as f64).sin())
                    .unwrap();
            } else {
                sys.exchange(sys.coordinate(node, step % 2).unwrap())
                    .unwrap();
            }
        }
    }
    assert!(buffered.pending() > 0);
    let a = to_nalgebra(&immediate.current_matrix());
    let b = to_nalgebra(&buffered.current_matrix());
    assert!(relative_difference(&a, &b) < 1e-11);
    let c = to_nalgebra(&capacitance.current_matrix());
    assert!(relative_difference(&a, &c) < 1e-11);
    for sys in [&mut immediate, &mut buffered, &mut capacitance] {
        let drift = sys.drift(3);
        assert!(drift < 1e-12, "drift {drift}");
        let before = to_nalgebra(&sys.current_matrix());
        let measured = sys.refresh_if_drifted(0.0, 3).unwrap();
        assert_eq!(measured, drift);
        assert_eq!(sys.pending(), 0);
        assert!(sys.drift(3) <= drift.max(1e-14));
        assert!(relative_difference(&to_nalgebra(&sys.current_matrix()), &before) < 1e-11);
    }
}

#[test]
fn bad_input_is_a_typed_error() {
    assert_eq!(
        Lattice::new(&[3], 0).unwrap_err(),
        CondenseError::Dimension(1)
    );
    assert!(matches!(
        Lattice::new(&[1, 4], 0),
        Err(CondenseError::Length { got: 1, .. })
    ));
    let lattice = Lattice::new(&[4, 4], 1).unwrap();
    let k = &lattice.stiffness;
    assert_eq!(
        FullModel::factor(k, 4, &[]).unwrap_err(),
        CondenseError::Dimension(4)
    );
    assert!(matches!(
        FullModel::factor(k, 2, &[999]),
        Err(CondenseError::FixedDofOutOfRange { dof: 999, .. })
    ));
    // No fixed dof: the Laplacian is singular.
    assert!(matches!(
        FullModel::factor(k, 2, &[]),
        Err(CondenseError::NotPositiveDefinite(_))
    ));
    let rect = faer::sparse::SparseColMat::<usize, f64>::try_new_from_triplets(4, 6, &[]).unwrap();
    assert_eq!(
        FullModel::factor(&rect, 2, &[]).unwrap_err(),
        CondenseError::NotSquare { rows: 4, cols: 6 }
    );
    let odd = faer::sparse::SparseColMat::<usize, f64>::try_new_from_triplets(5, 5, &[]).unwrap();
    assert!(matches!(
        FullModel::factor(&odd, 2, &[]),
        Err(CondenseError::Layout { .. })
    ));

    let model = Arc::new(FullModel::factor(k, 2, &lattice.fixed_dofs).unwrap());
    assert!(matches!(
        CondensedSystem::new(model.clone(), &[0], UpdatePolicy::Immediate),
        Err(CondenseError::NodeFixed { node: 0 })
    ));
    assert!(matches!(
        CondensedSystem::new(model.clone(), &[5, 5], UpdatePolicy::Immediate),
        Err(CondenseError::AlreadyWorking { node: 5 })
    ));
    let mut sys = CondensedSystem::new(model, &[5, 6], UpdatePolicy::Immediate).unwrap();
    assert!(matches!(
        sys.add_node(99),
        Err(CondenseError::NodeOutOfRange { node: 99, .. })
    ));
    assert!(matches!(
        sys.add_node(6),
        Err(CondenseError::AlreadyWorking { node: 6 })
    ));
    assert!(matches!(
        sys.remove_node(7),
        Err(CondenseError::NotWorking { node: 7 })
    ));
    assert!(matches!(
        sys.coordinate(5, 2),
        Err(CondenseError::AxisOutOfRange { axis: 2, dim: 2 })
    ));
    assert!(matches!(
        sys.exchange(4),
        Err(CondenseError::CoordinateOutOfRange {
            coordinate: 4,
            len: 4
        })
    ));
    let mut shear = rotation(2, 0.0, [0.0; 3]);
    shear[0][1] = 0.5;
    assert!(matches!(
        sys.rotate_node(5, &shear),
        Err(CondenseError::InvalidRotation { .. })
    ));
    let mut out = [0.0; 3];
    assert!(matches!(
        sys.unknowns_into(&[0, 1], &mut out),
        Err(CondenseError::Length { .. })
    ));
}

/// The capacitance form gathers the few loaded entries of `f` when the load
/// is sparse (forces only at the needle) and streams columns otherwise; both
/// must give the unknowns of the stored-`S` form.
#[test]
fn capacitance_queries_match_the_stored_form_for_sparse_and_dense_loads() {
    let mut stored = system(&[9, 10], 40, UpdatePolicy::Immediate);
    let mut capacitance = system(&[9, 10], 40, UpdatePolicy::Capacitance);
    let nodes = stored.working_nodes().to_vec();
    let n = stored.len();
    for sys in [&mut stored, &mut capacitance] {
        for (k, &node) in nodes[10..13].iter().enumerate() {
            sys.rotate_node_by_angle(node, 0.4).unwrap();
            sys.set_condition(node, 0, Condition::Displacement).unwrap();
            sys.set_prescribed(sys.coordinate(node, 0).unwrap(), 0.01 * (k as f64 + 1.0))
                .unwrap();
        }
        // One force-given needle coordinate carries a load: 4 loaded of N = 80.
        sys.set_prescribed(sys.coordinate(nodes[11], 1).unwrap(), 0.5)
            .unwrap();
    }
    let all: Vec<usize> = (0..n).collect();
    for dense_load in [false, true] {
        if dense_load {
            for sys in [&mut stored, &mut capacitance] {
                for &node in &nodes[20..40] {
                    sys.set_prescribed(sys.coordinate(node, 1).unwrap(), -0.2)
                        .unwrap();
                }
            }
        }
        let mut expected = vec![0.0; n];
        stored.unknowns_into(&all, &mut expected).unwrap();
        let mut got = vec![0.0; n];
        capacitance.unknowns_into(&all, &mut got).unwrap();
        let scale = expected.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(scale > 0.0);
        for (a, b) in expected.iter().zip(&got) {
            assert!((a - b).abs() <= 1e-11 * scale, "{dense_load}: {a} vs {b}");
        }
        let mut graphics = vec![0.0; n];
        capacitance.unknowns_all_into(&mut graphics).unwrap();
        for (a, b) in expected.iter().zip(&graphics) {
            assert!((a - b).abs() <= 1e-11 * scale, "{dense_load}: {a} vs {b}");
        }
    }
}
