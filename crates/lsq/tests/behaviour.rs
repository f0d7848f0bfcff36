//! Behaviour of the engine around the optimisation proper: bounds, fixed
//! parameters, finite differences, failing evaluations, bad input.

mod mgh;

use nalgebra::DMatrix;
use needle_lsq::{
    Differences, EvaluationError, LevenbergMarquardt, LsqError, Parameter, ParameterStatus,
    Problem, Termination, finite_difference_jacobian,
};
use proptest::prelude::*;

/// `r_i = (a + b t_i) - y_i` on data from a line; `fail_beyond` makes the
/// residuals fail when `b` exceeds it (a model that cannot be evaluated).
struct Line {
    t: Vec<f64>,
    y: Vec<f64>,
    fail_beyond: f64,
}

impl Line {
    fn new(intercept: f64, slope: f64) -> Self {
        let t: Vec<f64> = (0..20).map(|i| f64::from(i) * 0.1).collect();
        let y = t.iter().map(|t| intercept + slope * t).collect();
        Self {
            t,
            y,
            fail_beyond: f64::INFINITY,
        }
    }
}

impl Problem for Line {
    fn num_parameters(&self) -> usize {
        2
    }
    fn num_residuals(&self) -> usize {
        self.t.len()
    }
    fn residuals(&self, p: &[f64], out: &mut [f64]) -> Result<(), EvaluationError> {
        if p[1] > self.fail_beyond {
            return Err(format!("slope {} beyond the evaluable range", p[1]).into());
        }
        for ((o, t), y) in out.iter_mut().zip(&self.t).zip(&self.y) {
            *o = p[0] + p[1] * t - y;
        }
        Ok(())
    }
}

#[test]
fn an_optimum_outside_the_box_ends_on_the_violated_bound() {
    // Unconstrained minimum (1, 3); the slope is boxed into [0, 2].
    let problem = Line::new(1.0, 3.0);
    let parameters = [
        Parameter::new("intercept", 0.0),
        Parameter::new("slope", 0.5).with_bounds(0.0, 2.0),
    ];
    let report = LevenbergMarquardt::default()
        .minimize(&problem, &parameters)
        .unwrap();
    assert!(
        report.termination.is_converged(),
        "{:?}",
        report.termination
    );
    let slope = report.params[1];
    assert!(slope <= 2.0 && slope > 2.0 - 1e-6, "slope {slope}");
    // With the slope held at 2 the best intercept is mean(y - 2 t) = 1 + mean(t).
    let mean_t = problem.t.iter().sum::<f64>() / problem.t.len() as f64;
    assert!(
        (report.params[0] - (1.0 + mean_t)).abs() < 1e-5,
        "{}",
        report.params[0]
    );
    assert_eq!(report.uncertainty.status[1], ParameterStatus::AtBound);
    assert_eq!(report.uncertainty.status[0], ParameterStatus::Estimated);
    assert!(report.standard_error(1).is_none());
}

#[test]
fn one_sided_bounds_hold_and_stop_on_the_bound() {
    let problem = Line::new(1.0, -3.0);
    for (parameter, bound) in [
        (Parameter::new("slope", 1.0).with_lower(-1.0), -1.0),
        (Parameter::new("slope", -5.0).with_upper(-4.0), -4.0),
    ] {
        let parameters = [Parameter::new("intercept", 0.0), parameter];
        let report = LevenbergMarquardt::default()
            .minimize(&problem, &parameters)
            .unwrap();
        assert!(report.termination.is_converged());
        assert!(
            (report.params[1] - bound).abs() < 1e-6,
            "{} vs {bound}",
            report.params[1]
        );
        assert!(parameters[1].lower.is_none_or(|l| report.params[1] >= l));
        assert!(parameters[1].upper.is_none_or(|u| report.params[1] <= u));
    }
}

#[test]
fn interior_optimum_of_a_bounded_fit_is_the_unbounded_one() {
    let problem = Line::new(1.0, 3.0);
    let parameters = [
        Parameter::new("intercept", 0.0).with_lower(-10.0),
        Parameter::new("slope", 0.5).with_bounds(-5.0, 5.0),
    ];
    let report = LevenbergMarquardt::default()
        .minimize(&problem, &parameters)
        .unwrap();
    assert!((report.params[0] - 1.0).abs() < 1e-8 && (report.params[1] - 3.0).abs() < 1e-8);
    assert!(report.chi2 < 1e-16);
}

#[test]
fn a_start_on_a_bound_still_moves() {
    let problem = Line::new(1.0, 3.0);
    let parameters = [
        Parameter::new("intercept", 0.0),
        Parameter::new("slope", 0.0).with_bounds(0.0, 5.0),
    ];
    let report = LevenbergMarquardt::default()
        .minimize(&problem, &parameters)
        .unwrap();
    assert!(
        (report.params[1] - 3.0).abs() < 1e-8,
        "{}",
        report.params[1]
    );
}

/// Records the parameters of its first evaluation.
struct FirstEvaluation {
    line: Line,
    first: std::sync::Mutex<Option<Vec<f64>>>,
}

impl Problem for FirstEvaluation {
    fn num_parameters(&self) -> usize {
        2
    }
    fn num_residuals(&self) -> usize {
        self.line.num_residuals()
    }
    fn residuals(&self, p: &[f64], out: &mut [f64]) -> Result<(), EvaluationError> {
        self.first.lock().unwrap().get_or_insert_with(|| p.to_vec());
        self.line.residuals(p, out)
    }
}

#[test]
fn a_start_next_to_a_bound_is_evaluated_where_it_was_given() {
    // A start a millionth of the interval above its lower bound (as a
    // score test's step towards a small support compliance gives): it once
    // became 2.5e-5 of the width, 25 times further from the bound.
    for (lower, upper, start) in [
        (0.0, 5.0, 5e-6),
        (0.0, 5.0, 5.0 - 5e-6),
        (-1.0, 3.0, -1.0 + 1e-8),
    ] {
        for bounded in [
            Parameter::new("slope", start).with_bounds(lower, upper),
            Parameter::new("slope", start).with_lower(lower),
        ] {
            let problem = FirstEvaluation {
                line: Line::new(1.0, 3.0),
                first: std::sync::Mutex::new(None),
            };
            LevenbergMarquardt::default()
                .minimize(&problem, &[Parameter::new("intercept", 0.0), bounded])
                .unwrap();
            let first = problem.first.lock().unwrap().clone().unwrap();
            let distance = (start - lower).min(upper - start);
            let ulps = 4.0 * f64::EPSILON * start.abs();
            assert!(
                (first[1] - start).abs() <= 1e-6 * distance + ulps,
                "start {start} in [{lower}, {upper}] evaluated at {}",
                first[1]
            );
        }
    }
}

#[test]
fn a_start_on_a_bound_to_rounding_still_moves() {
    // As a fit that ended on the bound hands its value to the next one.
    let problem = Line::new(1.0, 3.0);
    for (slope, expected) in [
        (
            Parameter::new("slope", 5.0 - 6e-14).with_bounds(0.0, 5.0),
            3.0,
        ),
        (Parameter::new("slope", 2.0 + 6e-14).with_lower(2.0), 3.0),
    ] {
        let parameters = [Parameter::new("intercept", 0.0), slope];
        let report = LevenbergMarquardt::default()
            .minimize(&problem, &parameters)
            .unwrap();
        assert!(
            (report.params[1] - expected).abs() < 1e-6,
            "{:?}: {}",
            parameters[1],
            report.params[1]
        );
    }
}

#[test]
fn fixed_parameters_stay_fixed_and_the_others_fit_around_them() {
    let problem = Line::new(1.0, 3.0);
    let parameters = [
        Parameter::new("intercept", 0.25).fix(),
        Parameter::new("slope", 0.5),
    ];
    let report = LevenbergMarquardt::default()
        .minimize(&problem, &parameters)
        .unwrap();
    assert_eq!(report.params[0], 0.25);
    assert_eq!(report.uncertainty.status[0], ParameterStatus::Fixed);
    assert_eq!(report.dof, problem.t.len() - 1);
    // Best slope with the intercept held: Σ t (y - 0.25) / Σ t².
    let (num, den) = problem
        .t
        .iter()
        .zip(&problem.y)
        .fold((0.0, 0.0), |(n, d), (t, y)| (n + t * (y - 0.25), d + t * t));
    assert!((report.params[1] - num / den).abs() < 1e-9);
}

#[test]
fn fixing_every_parameter_is_an_error() {
    let parameters = [
        Parameter::new("a", 1.0).fix(),
        Parameter::new("b", 1.0).fix(),
    ];
    let error = LevenbergMarquardt::default()
        .minimize(&Line::new(1.0, 3.0), &parameters)
        .unwrap_err();
    assert!(matches!(error, LsqError::NoFreeParameters));
}

#[test]
fn failing_trial_evaluations_are_rejected_steps() {
    // The slope may not exceed 2.5 during the search; the optimum (3) is
    // unreachable, so the fit must end below 2.5, not crash.
    let mut problem = Line::new(1.0, 3.0);
    problem.fail_beyond = 2.5;
    let parameters = [
        Parameter::new("intercept", 0.0),
        Parameter::new("slope", 0.0),
    ];
    let report = LevenbergMarquardt::default()
        .minimize(&problem, &parameters)
        .unwrap();
    assert!(report.params[1] <= 2.5);
    assert!(report.evaluations.residuals > report.iterations);
    // The failing region was hit, yet the fit made progress from cost 30+.
    let start_cost = 0.5 * problem.y.iter().map(|y| y * y).sum::<f64>();
    assert!(
        report.cost < 0.1 * start_cost,
        "{} vs {start_cost}",
        report.cost
    );
}

#[test]
fn failing_trials_do_not_prevent_reaching_a_reachable_optimum() {
    // Fails only far from the path: slope > 10 (the first steps overshoot
    // there from a far start is not guaranteed, but any failures are absorbed).
    let mut problem = Line::new(1.0, 3.0);
    problem.fail_beyond = 3.5;
    let parameters = [
        Parameter::new("intercept", 50.0),
        Parameter::new("slope", -40.0),
    ];
    let report = LevenbergMarquardt::default()
        .minimize(&problem, &parameters)
        .unwrap();
    assert!(
        report.termination.is_converged(),
        "{:?}",
        report.termination
    );
    assert!((report.params[1] - 3.0).abs() < 1e-8);
}

#[test]
fn failure_at_the_start_is_a_typed_error() {
    let mut problem = Line::new(1.0, 3.0);
    problem.fail_beyond = 0.0;
    let parameters = [
        Parameter::new("intercept", 0.0),
        Parameter::new("slope", 1.0),
    ];
    let error = LevenbergMarquardt::default()
        .minimize(&problem, &parameters)
        .unwrap_err();
    assert!(
        matches!(error, LsqError::InitialEvaluation { .. }),
        "{error}"
    );
    assert!(error.to_string().contains("slope 1 beyond"), "{error}");
}

#[test]
fn bad_specifications_name_the_parameter() {
    let problem = Line::new(1.0, 3.0);
    let cases = [
        Parameter::new("slope", 3.0).with_bounds(0.0, 2.0),
        Parameter::new("slope", 1.0).with_bounds(2.0, 2.0),
        Parameter::new("slope", f64::NAN),
        Parameter::new("slope", 1.0).with_scale(0.0),
        Parameter::new("slope", 1.0).with_lower(f64::NEG_INFINITY),
    ];
    for bad in cases {
        let parameters = [Parameter::new("intercept", 0.0), bad.clone()];
        let error = LevenbergMarquardt::default()
            .minimize(&problem, &parameters)
            .unwrap_err();
        assert!(
            matches!(&error, LsqError::InvalidParameter { name, .. } if name == "slope"),
            "{bad:?}: {error}"
        );
    }
    let error = LevenbergMarquardt::default()
        .minimize(&problem, &[Parameter::new("a", 0.0)])
        .unwrap_err();
    assert!(matches!(
        error,
        LsqError::ParameterCount {
            expected: 2,
            given: 1
        }
    ));
}

#[test]
fn finite_differences_match_the_analytic_jacobians() {
    for problem in mgh::ALL {
        let parameters = problem.parameters();
        // Away from the start too: a point on the path to the optimum.
        let start: Vec<f64> = problem.start.iter().map(|x| 0.9 * x + 0.05).collect();
        let mut analytic = DMatrix::zeros(problem.m, problem.n);
        problem.jacobian(&start, &mut analytic).unwrap().unwrap();
        let mut residuals = vec![0.0; problem.m];
        problem.residuals(&start, &mut residuals).unwrap();
        let largest_residual = residuals.iter().fold(0.0_f64, |a, r| a.max(r.abs()));
        for (differences, truncation, eta) in [
            (Differences::Forward, 1e-6, f64::EPSILON.sqrt()),
            (Differences::Central, 1e-8, f64::EPSILON.cbrt()),
        ] {
            let numerical =
                finite_difference_jacobian(&problem, &parameters, &start, differences).unwrap();
            for j in 0..problem.n {
                let scale = analytic.column(j).amax().max(1e-300);
                // Rounding of r(p ± h) limits any difference quotient to
                // ~eps |r| / h (Brown's residual 1e6 - x1 is the extreme).
                let step = eta * start[j].abs().max(parameters[j].effective_scale());
                let rounding = 4.0 * f64::EPSILON * largest_residual / step / scale;
                let tolerance = truncation + rounding;
                let error = (numerical.column(j) - analytic.column(j)).amax() / scale;
                assert!(
                    error < tolerance,
                    "{} column {j} {differences:?}: relative error {error:e}",
                    problem.name
                );
            }
        }
    }
}

#[test]
fn central_differences_reach_the_same_minimum() {
    let options = needle_lsq::Options {
        differences: Differences::Central,
        ..Default::default()
    };
    let problem = mgh::MEYER.numerical();
    let report = LevenbergMarquardt::new(options)
        .minimize(&problem, &problem.parameters())
        .unwrap();
    assert!(report.termination.is_converged());
    assert!(((report.chi2 - 87.945_855_170_395) / 87.945_855_170_395).abs() < 1e-8);
    assert!(report.evaluations.finite_difference_residuals >= 6 * report.evaluations.jacobians - 6);
}

#[test]
fn a_point_where_every_trial_fails_is_kept() {
    // Residuals evaluable only at exactly the starting slope.
    struct Island;
    impl Problem for Island {
        fn num_parameters(&self) -> usize {
            1
        }
        fn num_residuals(&self) -> usize {
            1
        }
        fn residuals(&self, p: &[f64], out: &mut [f64]) -> Result<(), EvaluationError> {
            if p[0] != 1.0 {
                return Err("off the island".into());
            }
            out[0] = p[0];
            Ok(())
        }
        fn jacobian(
            &self,
            _: &[f64],
            out: &mut DMatrix<f64>,
        ) -> Option<Result<(), EvaluationError>> {
            out[(0, 0)] = 1.0;
            Some(Ok(()))
        }
    }
    let report = LevenbergMarquardt::default()
        .minimize(&Island, &[Parameter::new("x", 1.0)])
        .unwrap();
    // The damping grows until the step is negligible; the start is returned.
    assert!(matches!(
        report.termination,
        Termination::StepSize | Termination::DampingExhausted
    ));
    assert_eq!(report.params[0], 1.0);
    assert!(report.evaluations.residuals > 10);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// A value next to a bound maps back to itself to a small part of its
    /// distance from the bound.
    #[test]
    fn transforms_keep_a_value_next_to_a_bound(
        lower in -1e3..1e3f64,
        width in 1e-3..1e3f64,
        exponent in -9.0..-2.0f64,
        from_upper in any::<bool>(),
    ) {
        use needle_lsq::transform::Transform;
        let upper = lower + width;
        let distance = width * 10f64.powf(exponent);
        let value = if from_upper { upper - distance } else { lower + distance };
        let scale = width;
        let one_sided = if from_upper {
            Transform::Upper { upper, scale }
        } else {
            Transform::Lower { lower, scale }
        };
        for transform in [Transform::Interval { lower, upper }, one_sided] {
            let back = transform.external(transform.internal(value));
            // Rounding of the bound itself: a few ulps of its magnitude.
            let ulps = 8.0 * f64::EPSILON * lower.abs().max(upper.abs());
            prop_assert!(
                (back - value).abs() <= 1e-6 * distance + ulps,
                "{transform:?}: {back} vs {value}"
            );
        }
    }

    /// The bound transforms map back and forth and never leave the box.
    #[test]
    fn transforms_round_trip_inside_the_bounds(
        lower in -1e3..1e3f64,
        width in 1e-3..1e3f64,
        fraction in 0.01..0.99f64,
        u in -50.0..50.0f64,
    ) {
        use needle_lsq::transform::Transform;
        let upper = lower + width;
        let value = lower + fraction * width;
        let scale = 1.0 + value.abs();
        for transform in [
            Transform::Interval { lower, upper },
            Transform::Lower { lower, scale },
            Transform::Upper { upper, scale },
            Transform::Unbounded { scale },
        ] {
            let back = transform.external(transform.internal(value));
            prop_assert!((back - value).abs() <= 1e-9 * width.max(value.abs()), "{transform:?}: {back} vs {value}");
            let image = transform.external(u);
            let (low, high) = match transform {
                Transform::Interval { .. } => (lower, upper),
                Transform::Lower { .. } => (lower, f64::INFINITY),
                Transform::Upper { .. } => (f64::NEG_INFINITY, upper),
                Transform::Unbounded { .. } => (f64::NEG_INFINITY, f64::INFINITY),
            };
            prop_assert!(image >= low && image <= high);
            // dp/du against a central difference.
            let h = 1e-6;
            let numeric = (transform.external(u + h) - transform.external(u - h)) / (2.0 * h);
            let analytic = transform.derivative(u);
            prop_assert!((numeric - analytic).abs() <= 1e-6 * (1.0 + analytic.abs()) * width.max(scale));
        }
    }
}

/// `r_i = a (1 + z) t_i + b - y_i` with `z` the fixed point of
/// `z = cos(z) / 2 + b / 5` (a contraction by `sin(z) / 2`): a model with
/// an inner iteration. `residuals` converges it from 0; `residuals_near`
/// starts it from its solution at the base point and runs `rounds`.
struct Dragged {
    t: Vec<f64>,
    y: Vec<f64>,
    rounds: usize,
}

impl Dragged {
    fn new(rounds: usize) -> Self {
        let t: Vec<f64> = (0..20).map(|i| f64::from(i) * 0.1).collect();
        let truth = Self {
            t: t.clone(),
            y: vec![0.0; t.len()],
            rounds,
        };
        let mut y = vec![0.0; t.len()];
        truth.model(&[2.0, 1.0], Self::solved(1.0), &mut y);
        // Residuals that do not vanish at the optimum.
        for (i, y) in y.iter_mut().enumerate() {
            *y += 0.01 * (i as f64).sin();
        }
        Self { t, y, rounds }
    }

    fn iterate(mut z: f64, b: f64, rounds: usize) -> f64 {
        for _ in 0..rounds {
            z = 0.5 * z.cos() + 0.2 * b;
        }
        z
    }

    fn solved(b: f64) -> f64 {
        Self::iterate(0.0, b, 200)
    }

    fn model(&self, p: &[f64], z: f64, out: &mut [f64]) {
        for ((o, t), y) in out.iter_mut().zip(&self.t).zip(&self.y) {
            *o = p[0] * (1.0 + z) * t + p[1] - y;
        }
    }
}

impl Problem for Dragged {
    fn num_parameters(&self) -> usize {
        2
    }
    fn num_residuals(&self) -> usize {
        self.t.len()
    }
    fn residuals(&self, p: &[f64], out: &mut [f64]) -> Result<(), EvaluationError> {
        self.model(p, Self::solved(p[1]), out);
        Ok(())
    }
    fn residuals_near(
        &self,
        base: &[f64],
        p: &[f64],
        out: &mut [f64],
    ) -> Option<Result<(), EvaluationError>> {
        let z = Self::iterate(Self::solved(base[1]), p[1], self.rounds);
        self.model(p, z, out);
        Some(Ok(()))
    }
}

#[test]
fn a_near_map_differs_in_its_derivative_by_the_contraction_of_the_rounds_left_out() {
    // k rounds from the fixed point z* give dz/db = g (1 - c^k) / (1 - c)
    // with c = -sin(z*)/2 and g = 1/5, against g / (1 - c) converged: the
    // relative error of the b column's fixed-point part is exactly -c^k.
    let at = [1.5, 0.7];
    let z = Dragged::solved(at[1]);
    let c = -0.5 * z.sin();
    let converged = 0.2 / (1.0 - c);
    let parameters = [Parameter::new("a", at[0]), Parameter::new("b", at[1])];
    for rounds in 1..=3 {
        let problem = Dragged::new(rounds);
        let numerical =
            finite_difference_jacobian(&problem, &parameters, &at, Differences::Central).unwrap();
        for (i, t) in problem.t.iter().enumerate().skip(1) {
            // d r_i / d b = a t dz/db + 1.
            let dz = (numerical[(i, 1)] - 1.0) / (at[0] * t);
            let error = dz / converged - 1.0;
            let expected = -c.powi(rounds as i32);
            assert!(
                (error - expected).abs() < 1e-6,
                "rounds {rounds}, row {i}: {error:e} against {expected:e}"
            );
        }
        // The a column has no inner iteration: exact.
        for (i, t) in problem.t.iter().enumerate() {
            assert!((numerical[(i, 0)] - (1.0 + z) * t).abs() < 1e-8);
        }
    }
}

#[test]
fn a_fit_through_a_near_map_reaches_the_converged_maps_minimum() {
    let start = [Parameter::new("a", 1.0), Parameter::new("b", 0.0)];
    let engine = LevenbergMarquardt::default();
    let converged = engine.minimize(&Dragged::new(200), &start).unwrap();
    let near = engine.minimize(&Dragged::new(2), &start).unwrap();
    assert!(near.termination.is_converged(), "{:?}", near.termination);
    for (p, q) in near.params.iter().zip(converged.params.iter()) {
        assert!((p - q).abs() < 1e-6, "{p} against {q}");
    }
    assert!((near.chi2 - converged.chi2).abs() < 1e-9 * converged.chi2);
}

#[test]
fn without_uncertainty_the_same_optimum_costs_one_jacobian_fewer() {
    let without = LevenbergMarquardt::new(needle_lsq::Options {
        uncertainty: false,
        ..Default::default()
    });
    let mut skipped = 0;
    for problem in mgh::ALL.map(mgh::Mgh::numerical) {
        let parameters = problem.parameters();
        let full = LevenbergMarquardt::default()
            .minimize(&problem, &parameters)
            .unwrap();
        let lean = without.minimize(&problem, &parameters).unwrap();
        let name = problem.name;
        // The final Jacobian steers nothing: the same steps, to the bit.
        assert_eq!(lean.params, full.params, "{name}");
        assert_eq!(lean.termination, full.termination, "{name}");
        assert_eq!(lean.iterations, full.iterations, "{name}");
        let spared = full.evaluations.jacobians - lean.evaluations.jacobians;
        let columns = parameters.len();
        assert_eq!(
            full.evaluations.finite_difference_residuals
                - lean.evaluations.finite_difference_residuals,
            spared * columns,
            "{name}"
        );
        if spared == 1 {
            skipped += 1;
            assert!(lean.gradient_norm.is_nan(), "{name}");
            assert!(
                lean.uncertainty
                    .status
                    .iter()
                    .all(|&s| s == ParameterStatus::NotComputed),
                "{name}"
            );
            assert!(lean.standard_error(0).is_none(), "{name}");
        } else {
            // Stopped on a rejected step: its Jacobian is the optimum's.
            assert_eq!(spared, 0, "{name}");
            assert_eq!(lean.gradient_norm, full.gradient_norm, "{name}");
            assert_eq!(lean.uncertainty.status, full.uncertainty.status, "{name}");
        }
        assert!(
            full.uncertainty
                .status
                .iter()
                .all(|&s| s != ParameterStatus::NotComputed),
            "{name}"
        );
    }
    assert!(
        skipped > 0,
        "no problem stopped right after an accepted step"
    );
}

#[test]
fn options_written_before_the_uncertainty_switch_still_read_with_it_on() {
    let mut text = ron::to_string(&needle_lsq::Options::default()).unwrap();
    let field = ",uncertainty:true";
    assert!(text.contains(field), "{text}");
    text = text.replace(field, "");
    let read: needle_lsq::Options = ron::from_str(&text).unwrap();
    assert_eq!(read, needle_lsq::Options::default());
}

/// $r_i = e^{-(a + b v_i) t_i} + c t_i^2 - y_i$: `b` acts only through
/// $a + b v_i$, so its column is $v \odot$ the column of `a`, which the
/// problem declares when `chain` says so (`a` from `b` as well when
/// `circular`).
struct Grouped {
    t: Vec<f64>,
    v: Vec<f64>,
    y: Vec<f64>,
    chain: bool,
    circular: bool,
}

impl Grouped {
    fn new(chain: bool, circular: bool) -> Self {
        let t: Vec<f64> = (0..30).map(|i| 0.1 * f64::from(i % 10)).collect();
        let v: Vec<f64> = (0..30).map(|i| [0.5, 1.0, 2.0][i / 10]).collect();
        let y = t
            .iter()
            .zip(&v)
            .map(|(t, v)| (-(0.7 + 0.4 * v) * t).exp() + 0.2 * t * t)
            .collect();
        Self {
            t,
            v,
            y,
            chain,
            circular,
        }
    }

    fn analytic(&self, p: &[f64]) -> DMatrix<f64> {
        DMatrix::from_fn(self.t.len(), 3, |i, j| {
            let (t, v) = (self.t[i], self.v[i]);
            let decay = -t * (-(p[0] + p[1] * v) * t).exp();
            [decay, decay * v, t * t][j]
        })
    }
}

impl Problem for Grouped {
    fn num_parameters(&self) -> usize {
        3
    }
    fn num_residuals(&self) -> usize {
        self.t.len()
    }
    fn residuals(&self, p: &[f64], out: &mut [f64]) -> Result<(), EvaluationError> {
        for (i, o) in out.iter_mut().enumerate() {
            let (t, v) = (self.t[i], self.v[i]);
            *o = (-(p[0] + p[1] * v) * t).exp() + p[2] * t * t - self.y[i];
        }
        Ok(())
    }
    fn chained_column(&self, _params: &[f64], j: usize) -> Option<(usize, Vec<f64>)> {
        match j {
            1 if self.chain => Some((0, self.v.clone())),
            0 if self.circular => Some((1, self.v.iter().map(|v| 1.0 / v).collect())),
            _ => None,
        }
    }
}

fn grouped_parameters() -> [Parameter; 3] {
    [
        Parameter::new("a", 1.0),
        Parameter::new("b", 0.0),
        Parameter::new("c", 0.0),
    ]
}

#[test]
fn a_chained_column_is_the_multiple_of_its_differenced_source() {
    let at = [0.9, 0.3, 0.1];
    let chained = Grouped::new(true, false);
    let plain = Grouped::new(false, false);
    let parameters = grouped_parameters();
    let with =
        finite_difference_jacobian(&chained, &parameters, &at, Differences::Forward).unwrap();
    let without =
        finite_difference_jacobian(&plain, &parameters, &at, Differences::Forward).unwrap();
    let exact = chained.analytic(&at);
    for i in 0..chained.t.len() {
        // Taken from column 0, not differenced: the product to the bit.
        assert_eq!(with[(i, 1)], chained.v[i] * with[(i, 0)]);
        assert_eq!(with[(i, 0)], without[(i, 0)]);
        assert_eq!(with[(i, 2)], without[(i, 2)]);
        for j in 0..3 {
            assert!((with[(i, j)] - exact[(i, j)]).abs() < 1e-6, "({i}, {j})");
        }
    }
}

#[test]
fn a_fit_with_a_chained_column_reaches_the_same_minimum_for_fewer_evaluations() {
    let engine = LevenbergMarquardt::default();
    let parameters = grouped_parameters();
    let plain = engine
        .minimize(&Grouped::new(false, false), &parameters)
        .unwrap();
    let chained = engine
        .minimize(&Grouped::new(true, false), &parameters)
        .unwrap();
    assert!(
        chained.termination.is_converged(),
        "{:?}",
        chained.termination
    );
    for (p, q) in chained.params.iter().zip(plain.params.iter()) {
        assert!((p - q).abs() < 1e-7, "{p} against {q}");
    }
    for (p, truth) in chained.params.iter().zip([0.7, 0.4, 0.2]) {
        assert!((p - truth).abs() < 1e-7, "{p} against {truth}");
    }
    // Two differenced columns per Jacobian instead of three.
    assert_eq!(
        chained.evaluations.finite_difference_residuals,
        2 * chained.evaluations.jacobians
    );
    assert_eq!(
        plain.evaluations.finite_difference_residuals,
        3 * plain.evaluations.jacobians
    );
}

#[test]
fn a_chain_whose_source_is_fixed_or_chained_itself_is_differenced() {
    let engine = LevenbergMarquardt::default();
    let mut parameters = grouped_parameters();
    parameters[0] = Parameter::new("a", 0.7).fix();
    let report = engine
        .minimize(&Grouped::new(true, false), &parameters)
        .unwrap();
    assert!(
        (report.params[1] - 0.4).abs() < 1e-7,
        "{}",
        report.params[1]
    );
    assert_eq!(
        report.evaluations.finite_difference_residuals,
        2 * report.evaluations.jacobians
    );
    // Each column declared a multiple of the other: both are differenced.
    let at = [0.9, 0.3, 0.1];
    let circular = Grouped::new(true, true);
    let parameters = grouped_parameters();
    let jacobian =
        finite_difference_jacobian(&circular, &parameters, &at, Differences::Forward).unwrap();
    let plain = finite_difference_jacobian(
        &Grouped::new(false, false),
        &parameters,
        &at,
        Differences::Forward,
    )
    .unwrap();
    assert_eq!(jacobian, plain);
}
