//! Quadrature rules on the reference simplices and on $\[0,1\]$.
//!
//! Stiffness matrices use the lowest rule that is exact for straight-sided
//! elements (degree $2(p-1)$); loads, supports and error norms use
//! collapsed (Duffy) Gauss–Legendre product rules of any order.

use nalgebra::SVector;

/// Gauss–Legendre points and weights on $[0, 1]$ with `n` points
/// (exact for polynomials of degree $2n-1$). Computed by Newton's method on
/// the Legendre polynomial $P_n$.
pub fn gauss_legendre_unit(n: usize) -> Vec<(f64, f64)> {
    let n = n.max(1);
    let mut rule = Vec::with_capacity(n);
    for i in 0..n {
        // Chebyshev-like initial guess for the i-th root of P_n on [-1, 1].
        let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut derivative = 1.0;
        for _ in 0..100 {
            let (mut p0, mut p1) = (1.0, x);
            for k in 2..=n {
                let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                p0 = p1;
                p1 = p2;
            }
            let pn = if n == 1 { x } else { p1 };
            let pn_minus_1 = if n == 1 { 1.0 } else { p0 };
            derivative = n as f64 * (x * pn - pn_minus_1) / (x * x - 1.0);
            let step = pn / derivative;
            x -= step;
            if step.abs() < 1e-16 {
                break;
            }
        }
        let weight = 2.0 / ((1.0 - x * x) * derivative * derivative);
        rule.push(((1.0 - x) / 2.0, weight / 2.0));
    }
    rule.sort_by(|a, b| a.0.total_cmp(&b.0));
    rule
}

/// A quadrature rule on the reference `D`-simplex: points and weights
/// (weights sum to the reference volume $1/D!$).
pub type SimplexRule<const D: usize> = Vec<(SVector<f64, D>, f64)>;

/// The lowest-order rule exact for polynomials of degree `degree` (up to 2)
/// on the reference `D`-simplex, or a collapsed Gauss rule above that.
pub fn simplex_rule<const D: usize>(degree: usize) -> SimplexRule<D> {
    match (D, degree) {
        (_, 0 | 1) => {
            let c = 1.0 / (D as f64 + 1.0);
            let volume = if D == 2 { 0.5 } else { 1.0 / 6.0 };
            vec![(SVector::from_element(c), volume)]
        }
        (2, 2) => {
            let (a, b) = (1.0 / 6.0, 2.0 / 3.0);
            [[a, a], [b, a], [a, b]]
                .iter()
                .map(|p| (SVector::from_fn(|j, _| p[j]), 1.0 / 6.0))
                .collect()
        }
        (3, 2) => {
            let (a, b) = (0.585_410_196_624_968_5, 0.138_196_601_125_010_5);
            [[b, b, b], [a, b, b], [b, a, b], [b, b, a]]
                .iter()
                .map(|p| (SVector::from_fn(|j, _| p[j]), 1.0 / 24.0))
                .collect()
        }
        _ => collapsed_rule::<D>((degree + D).div_ceil(2)),
    }
}

/// Collapsed (Duffy) Gauss–Legendre product rule with `n` points per
/// direction on the reference `D`-simplex (`D` = 1, 2 or 3). The collapse
/// Jacobian has degree $D-1$, so the rule is exact for polynomials of degree
/// $2n - D$.
pub fn collapsed_rule<const D: usize>(n: usize) -> SimplexRule<D> {
    let line = gauss_legendre_unit(n);
    let mut rule = Vec::new();
    match D {
        1 => {
            for &(u, wu) in &line {
                rule.push((SVector::from_element(u), wu));
            }
        }
        2 => {
            for &(u, wu) in &line {
                for &(v, wv) in &line {
                    let p = [u, v * (1.0 - u)];
                    rule.push((SVector::from_fn(|j, _| p[j]), wu * wv * (1.0 - u)));
                }
            }
        }
        _ => {
            for &(u, wu) in &line {
                for &(v, wv) in &line {
                    for &(w, ww) in &line {
                        let p = [u, v * (1.0 - u), w * (1.0 - u) * (1.0 - v)];
                        let jacobian = (1.0 - u) * (1.0 - u) * (1.0 - v);
                        rule.push((SVector::from_fn(|j, _| p[j]), wu * wv * ww * jacobian));
                    }
                }
            }
        }
    }
    rule
}
