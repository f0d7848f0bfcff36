//! Our side of the peer comparison with SciPy (`bench/peers/lsq_peer.py`):
//! the same problems from the same starts, printing final cost (½ Σ r²),
//! evaluations and wall time.
//!
//! Run: `cargo run --release -p needle-lsq --example peer_problems`

use std::time::Instant;

use needle_lsq::{Differences, EvaluationError, LevenbergMarquardt, Options, Parameter, Problem};

/// Meyer's thermistor problem (MGH no. 10), start (0.02, 4000, 250).
struct Meyer;

const MEYER_Y: [f64; 16] = [
    34780.0, 28610.0, 23650.0, 19630.0, 16370.0, 13720.0, 11540.0, 9744.0, 8261.0, 7030.0, 6005.0,
    5147.0, 4427.0, 3820.0, 3307.0, 2872.0,
];

impl Problem for Meyer {
    fn num_parameters(&self) -> usize {
        3
    }
    fn num_residuals(&self) -> usize {
        16
    }
    fn residuals(&self, x: &[f64], out: &mut [f64]) -> Result<(), EvaluationError> {
        for (i, o) in out.iter_mut().enumerate() {
            let t = 45.0 + 5.0 * (i + 1) as f64;
            *o = x[0] * (x[1] / (t + x[2])).exp() - MEYER_Y[i];
        }
        Ok(())
    }
}

/// `y = 2 exp(-1.3 t) + e_i` on 1e5 points of [0, 5], with the
/// deterministic perturbation `e_i = 0.01 (((7919 i) mod 1000) / 1000 - 0.5)`
/// the Python peer reproduces exactly; start (1, 1).
struct Exponential {
    t: Vec<f64>,
    y: Vec<f64>,
}

impl Exponential {
    fn new(m: usize) -> Self {
        let t: Vec<f64> = (0..m).map(|i| 5.0 * i as f64 / (m - 1) as f64).collect();
        let y = t
            .iter()
            .enumerate()
            .map(|(i, t)| {
                2.0 * (-1.3 * t).exp() + 0.01 * (((7919 * i) % 1000) as f64 / 1000.0 - 0.5)
            })
            .collect();
        Self { t, y }
    }
}

impl Problem for Exponential {
    fn num_parameters(&self) -> usize {
        2
    }
    fn num_residuals(&self) -> usize {
        self.t.len()
    }
    fn residuals(&self, p: &[f64], out: &mut [f64]) -> Result<(), EvaluationError> {
        for ((o, t), y) in out.iter_mut().zip(&self.t).zip(&self.y) {
            *o = p[0] * (-p[1] * t).exp() - y;
        }
        Ok(())
    }
}

fn run<P: Problem>(name: &str, problem: &P, start: &[f64]) {
    let parameters: Vec<Parameter> = start
        .iter()
        .enumerate()
        .map(|(j, &x)| Parameter::new(format!("x{j}"), x))
        .collect();
    // Same tolerances as the peer script; forward differences like SciPy's '2-point'.
    let lm = LevenbergMarquardt::new(Options {
        function_tolerance: 1e-10,
        step_tolerance: 1e-10,
        gradient_tolerance: 1e-10,
        differences: Differences::Forward,
        ..Options::default()
    });
    let repeats = 5;
    let begin = Instant::now();
    let mut report = None;
    for _ in 0..repeats {
        report = Some(lm.minimize(problem, &parameters).expect("fit"));
    }
    let seconds = begin.elapsed().as_secs_f64() / f64::from(repeats);
    let report = report.expect("at least one repeat");
    println!(
        "{name:<14} needle-lsq  cost {:.10e}  nfev {:>4} + fd {:>4} = all calls {:>4}  njev {:>4}  time {:.3e} s  {:?}  x = {:?}",
        report.cost,
        report.evaluations.residuals,
        report.evaluations.finite_difference_residuals,
        report.evaluations.residuals + report.evaluations.finite_difference_residuals,
        report.evaluations.jacobians,
        seconds,
        report.termination,
        report.params.as_slice()
    );
}

fn main() {
    run("meyer", &Meyer, &[0.02, 4000.0, 250.0]);
    run("exp-1e5", &Exponential::new(100_000), &[1.0, 1.0]);
}
