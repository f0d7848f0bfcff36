//! The neo-Hookean displacement as a series in the load, for
//! `material_nonlinearity`.
//!
//! Expand the neo-Hookean internal force about the rest state,
//! $f_\text{int}(u) = K u + Q(u) + C(u) + O(u^4)$ with $Q$ quadratic and
//! $C$ cubic (and $B$ the symmetric bilinear form of $Q$, $Q(u) = B(u, u)$).
//! The equilibrium $f_\text{int}(u) = f$ then has the solution
//! $u = u_1 + u_2 + u_3 + O(f^4)$ with
//! $$K u_1 = f, \qquad K u_2 = -Q(u_1), \qquad K u_3 = -2B(u_1, u_2) - C(u_1),$$
//! each on the factorisation of $K$ the linear model already has: two
//! back-substitutions more per load case.
//!
//! $Q$ and $C$ are the even and odd parts of $f_\text{int}$ on small
//! multiples of $u$: with $e(a) = \tfrac12(f(au) + f(-au))$ and
//! $o(a) = \tfrac12(f(au) - f(-au))$,
//! $$Q(u) = \frac{e(\epsilon)}{\epsilon^2} + O(\epsilon^2), \qquad
//!   C(u) = \frac{o(2\epsilon) - 2\,o(\epsilon)}{6\epsilon^3} + O(\epsilon^2),$$
//! and $B(u, v) = \big(Q(u + tv) - Q(u - tv)\big)/4t$ with $t$ making both
//! fields the same size. $\epsilon$ is chosen so that $\epsilon u$ moves
//! no node by more than [`PROBING_STRAIN`] of the smallest element: the
//! linear parts cancel exactly, the remainders are $10^{-6}$ of the
//! terms, rounding far below; no element can invert whatever $u$ is (the
//! linear solution of a soft trial may invert one, where $f_\text{int}(u)$
//! does not exist); the linear springs of the supports drop out; and the
//! terms are polynomials in $u$, smooth in the parameters for the
//! finite-difference Jacobians.
//!
//! **Scaling.** A factorisation is of $K_c = K / c$ (moduli divided by
//! $c$) and returns $v = c\,u_1$. $f_\text{int}$ is linear in the moduli,
//! so the terms computed from $v$ with the normalised materials are
//! $c^2 u_2$ and $c^3 u_3$.

use needle_fem::{HyperelasticAssembler, LinearProblem, Materials};

use crate::error::DiagnoseError;

/// Largest nodal displacement of the probing fields $\pm\epsilon u$,
/// $\pm 2\epsilon u$, relative to the smallest element.
const PROBING_STRAIN: f64 = 1.0e-3;

/// What the series needs of one factorisation.
pub(crate) struct Series<'a, const D: usize> {
    pub assembler: &'a HyperelasticAssembler<D>,
    /// The normalised materials of the factorisation.
    pub materials: &'a Materials,
    pub problem: &'a LinearProblem<D>,
    /// Smallest element extent (m).
    pub element_size: f64,
}

/// Largest absolute entry.
fn largest(v: &[f64]) -> f64 {
    v.iter().fold(0.0f64, |m, x| m.max(x.abs()))
}

impl<const D: usize> Series<'_, D> {
    /// $(c^2 u_2, c^3 u_3)$ of every solution $v = c\,u_1$ of the
    /// factorisation.
    pub fn terms(&self, solutions: &[&[f64]]) -> Result<Vec<[Vec<f64>; 2]>, DiagnoseError> {
        let mut quadratics = Vec::with_capacity(solutions.len());
        let mut cubics = Vec::with_capacity(solutions.len());
        for v in solutions {
            let (q, c) = self.quadratic_and_cubic(v)?;
            quadratics.push(negated(q));
            cubics.push(c);
        }
        let second = self.solve(&quadratics)?;
        let third_loads = solutions
            .iter()
            .zip(&second)
            .zip(cubics)
            .map(|((v, u2), c)| {
                let b = self.bilinear(v, u2)?;
                Ok(b.iter().zip(c).map(|(b, c)| -(2.0 * b + c)).collect())
            })
            .collect::<Result<Vec<Vec<f64>>, DiagnoseError>>()?;
        let third = self.solve(&third_loads)?;
        Ok(second
            .into_iter()
            .zip(third)
            .map(|(u2, u3)| [u2, u3])
            .collect())
    }

    fn solve(&self, loads: &[Vec<f64>]) -> Result<Vec<Vec<f64>>, DiagnoseError> {
        let refs: Vec<&[f64]> = loads.iter().map(|l| l.as_slice()).collect();
        Ok(self.problem.displacements_many(&refs)?)
    }

    /// $\epsilon$ for `v` (see the module doc); `None` for a zero field.
    fn step(&self, v: &[f64]) -> Option<f64> {
        let size = largest(v);
        (size > 0.0).then(|| PROBING_STRAIN * self.element_size / size)
    }

    /// $\tfrac12(f(a v) + s f(-a v))$, the even ($s = 1$) or odd
    /// ($s = -1$) part.
    fn part(&self, v: &[f64], a: f64, sign: f64) -> Result<Vec<f64>, DiagnoseError> {
        let scaled = |factor: f64| -> Vec<f64> { v.iter().map(|x| factor * x).collect() };
        let plus = self.assembler.internal_force(self.materials, &scaled(a))?;
        let minus = self.assembler.internal_force(self.materials, &scaled(-a))?;
        Ok(plus
            .iter()
            .zip(minus)
            .map(|(p, m)| 0.5 * (p + sign * m))
            .collect())
    }

    /// $Q(v)$.
    fn quadratic(&self, v: &[f64]) -> Result<Vec<f64>, DiagnoseError> {
        let Some(epsilon) = self.step(v) else {
            return Ok(vec![0.0; v.len()]);
        };
        let even = self.part(v, epsilon, 1.0)?;
        Ok(even.iter().map(|e| e / (epsilon * epsilon)).collect())
    }

    /// $Q(v)$ and $C(v)$.
    fn quadratic_and_cubic(&self, v: &[f64]) -> Result<(Vec<f64>, Vec<f64>), DiagnoseError> {
        let Some(epsilon) = self.step(v) else {
            return Ok((vec![0.0; v.len()], vec![0.0; v.len()]));
        };
        let even = self.part(v, epsilon, 1.0)?;
        let odd = self.part(v, epsilon, -1.0)?;
        let odd_double = self.part(v, 2.0 * epsilon, -1.0)?;
        let quadratic = even.iter().map(|e| e / (epsilon * epsilon)).collect();
        let cubic = odd_double
            .iter()
            .zip(&odd)
            .map(|(d, o)| (d - 2.0 * o) / (6.0 * epsilon.powi(3)))
            .collect();
        Ok((quadratic, cubic))
    }

    /// $B(u, v)$ by polarisation.
    fn bilinear(&self, u: &[f64], v: &[f64]) -> Result<Vec<f64>, DiagnoseError> {
        let (size_u, size_v) = (largest(u), largest(v));
        if size_u == 0.0 || size_v == 0.0 {
            return Ok(vec![0.0; u.len()]);
        }
        let t = size_u / size_v;
        let sum: Vec<f64> = u.iter().zip(v).map(|(a, b)| a + t * b).collect();
        let difference: Vec<f64> = u.iter().zip(v).map(|(a, b)| a - t * b).collect();
        let (plus, minus) = (self.quadratic(&sum)?, self.quadratic(&difference)?);
        Ok(plus
            .iter()
            .zip(minus)
            .map(|(p, m)| (p - m) / (4.0 * t))
            .collect())
    }
}

fn negated(v: Vec<f64>) -> Vec<f64> {
    v.into_iter().map(|x| -x).collect()
}

/// Marker values of the nonlinear terms of a probe on one contact patch as
/// forms in the probe force $F$: with the unit responses $g_x, g_y$ and
/// $u_1 = F_x g_x + F_y g_y$, $u_2$ is a quadratic and $u_3$ a cubic form,
/// $$u_2 = F_x^2 D_{xx} + 2F_xF_y D_{xy} + F_y^2 D_{yy},\qquad
///   u_3 = F_x^3 C_{xxx} + 3F_x^2F_y C_{xxy} + 3F_xF_y^2 C_{xyy} + F_y^3 C_{yyy},$$
/// so a frame costs no solve and the derivatives in $F$ (for the force
/// noise) are exact.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ProbeSeries {
    /// $[D_{xx}, D_{xy}, D_{yy}]$ per marker.
    pub quadratic: [Vec<[f64; 2]>; 3],
    /// $[C_{xxx}, C_{xxy}, C_{xyy}, C_{yyy}]$ per marker.
    pub cubic: [Vec<[f64; 2]>; 4],
}

/// $\sum_k c_k a_k$ over marker vectors.
fn combine(terms: &[(f64, &[[f64; 2]])]) -> Vec<[f64; 2]> {
    let n = terms.first().map_or(0, |t| t.1.len());
    (0..n)
        .map(|m| {
            let mut s = [0.0; 2];
            for (c, a) in terms {
                s[0] += c * a[m][0];
                s[1] += c * a[m][1];
            }
            s
        })
        .collect()
}

impl ProbeSeries {
    /// The coefficients from the terms (`[u_2, u_3]` at the markers) under
    /// the unit forces along $x$, $y$, $x + y$ and $x - y$.
    pub fn from_directions(terms: [[Vec<[f64; 2]>; 2]; 4]) -> Self {
        let [x, y, sum, difference] = terms;
        // u_2(1, 1) - u_2(1, -1) = 4 D_xy.
        let xy = combine(&[(0.25, &sum[0]), (-0.25, &difference[0])]);
        // (u_3(1, 1) + u_3(1, -1)) / 2 = C_xxx + 3 C_xyy and
        // (u_3(1, 1) - u_3(1, -1)) / 2 = 3 C_xxy + C_yyy.
        let xyy = combine(&[
            (1.0 / 6.0, &sum[1]),
            (1.0 / 6.0, &difference[1]),
            (-1.0 / 3.0, &x[1]),
        ]);
        let xxy = combine(&[
            (1.0 / 6.0, &sum[1]),
            (-1.0 / 6.0, &difference[1]),
            (-1.0 / 3.0, &y[1]),
        ]);
        let [x2, x3] = x;
        let [y2, y3] = y;
        Self {
            quadratic: [x2, xy, y2],
            cubic: [x3, xxy, xyy, y3],
        }
    }

    /// The coefficients for a factorisation scale `c`: the quadratic ones
    /// divided by $c^2$, the cubic ones by $c^3$ (see the module doc).
    pub fn scaled(&self, c: f64) -> Self {
        let divide = |v: &Vec<[f64; 2]>, d: f64| v.iter().map(|u| [u[0] / d, u[1] / d]).collect();
        Self {
            quadratic: self.quadratic.each_ref().map(|v| divide(v, c * c)),
            cubic: self.cubic.each_ref().map(|v| divide(v, c * c * c)),
        }
    }

    /// $u_2 + u_3$ at the markers under `force`, and its derivatives in
    /// $F_x$ and $F_y$.
    pub fn at(&self, force: [f64; 2]) -> [Vec<[f64; 2]>; 3] {
        let [x, y] = force;
        let [dxx, dxy, dyy] = &self.quadratic;
        let [cxxx, cxxy, cxyy, cyyy] = &self.cubic;
        let value = combine(&[
            (x * x, dxx),
            (2.0 * x * y, dxy),
            (y * y, dyy),
            (x * x * x, cxxx),
            (3.0 * x * x * y, cxxy),
            (3.0 * x * y * y, cxyy),
            (y * y * y, cyyy),
        ]);
        let along_x = combine(&[
            (2.0 * x, dxx),
            (2.0 * y, dxy),
            (3.0 * x * x, cxxx),
            (6.0 * x * y, cxxy),
            (3.0 * y * y, cxyy),
        ]);
        let along_y = combine(&[
            (2.0 * x, dxy),
            (2.0 * y, dyy),
            (3.0 * x * x, cxxy),
            (6.0 * x * y, cxyy),
            (3.0 * y * y, cyyy),
        ]);
        [value, along_x, along_y]
    }
}
