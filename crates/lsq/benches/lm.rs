//! Criterion benches of the Levenberg-Marquardt engine on mid-size problems.
//!
//! Run: `cargo bench -p needle-lsq --bench lm -- --warm-up-time 1 --measurement-time 5`

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use needle_lsq::{EvaluationError, LevenbergMarquardt, Parameter, Problem};

/// A sum of `k` Gaussian peaks (amplitude, centre, width each) sampled at
/// `m` points, fitted from perturbed starts with finite differences: `3k`
/// parallel Jacobian columns per iteration.
struct Peaks {
    t: Vec<f64>,
    y: Vec<f64>,
    k: usize,
}

fn peak_parameters(k: usize, perturbation: f64) -> Vec<f64> {
    (0..k)
        .flat_map(|j| {
            let centre = (j as f64 + 0.5) / k as f64;
            [
                1.0 + 0.1 * j as f64,
                centre + perturbation * 0.2 / k as f64,
                0.3 / k as f64,
            ]
        })
        .collect()
}

impl Peaks {
    fn new(k: usize, m: usize) -> Self {
        let t: Vec<f64> = (0..m).map(|i| i as f64 / (m - 1) as f64).collect();
        let truth = peak_parameters(k, 0.0);
        let mut y = vec![0.0; m];
        let problem = Self {
            t,
            y: vec![0.0; m],
            k,
        };
        problem.model(&truth, &mut y);
        Self { y, ..problem }
    }

    fn model(&self, p: &[f64], out: &mut [f64]) {
        for (o, &t) in out.iter_mut().zip(&self.t) {
            *o = (0..self.k)
                .map(|j| {
                    let d = (t - p[3 * j + 1]) / p[3 * j + 2];
                    p[3 * j] * (-0.5 * d * d).exp()
                })
                .sum();
        }
    }
}

impl Problem for Peaks {
    fn num_parameters(&self) -> usize {
        3 * self.k
    }
    fn num_residuals(&self) -> usize {
        self.t.len()
    }
    fn residuals(&self, p: &[f64], out: &mut [f64]) -> Result<(), EvaluationError> {
        self.model(p, out);
        for (o, y) in out.iter_mut().zip(&self.y) {
            *o -= y;
        }
        Ok(())
    }
}

/// `y = 2 exp(-1.3 t)` on `m` points, 2 parameters.
struct Exponential {
    t: Vec<f64>,
    y: Vec<f64>,
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

fn benches(c: &mut Criterion) {
    let peaks = Peaks::new(10, 3000);
    let start: Vec<Parameter> = peak_parameters(10, 1.0)
        .into_iter()
        .enumerate()
        .map(|(j, x)| Parameter::new(format!("p{j}"), x).with_lower(0.0))
        .collect();
    let lm = LevenbergMarquardt::default();
    let check = lm.minimize(&peaks, &start).unwrap();
    assert!(
        check.termination.is_converged() && check.cost < 1e-12,
        "{check:?}"
    );
    c.bench_function("peaks_30p_3000r_fd", |b| {
        b.iter(|| lm.minimize(black_box(&peaks), black_box(&start)).unwrap())
    });

    let m = 100_000;
    let t: Vec<f64> = (0..m).map(|i| 5.0 * i as f64 / (m - 1) as f64).collect();
    let y = t.iter().map(|t| 2.0 * (-1.3 * t).exp()).collect();
    let exponential = Exponential { t, y };
    let start = [Parameter::new("a", 1.0), Parameter::new("k", 1.0)];
    c.bench_function("exponential_2p_1e5r_fd", |b| {
        b.iter(|| {
            lm.minimize(black_box(&exponential), black_box(&start))
                .unwrap()
        })
    });
}

criterion_group!(lm, benches);
criterion_main!(lm);
