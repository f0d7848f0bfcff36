//! Test problems of Moré, Garbow & Hillstrom (1981), "Testing unconstrained
//! optimization software", ACM TOMS 7(1), with their analytic Jacobians.

use nalgebra::DMatrix;
use needle_lsq::{EvaluationError, Problem};

/// One MGH problem; `analytic` switches the Jacobian off to exercise
/// finite differences on the same residuals.
#[derive(Clone, Copy)]
pub struct Mgh {
    pub name: &'static str,
    pub n: usize,
    pub m: usize,
    pub start: &'static [f64],
    pub residuals: fn(&[f64], &mut [f64]),
    pub jacobian: fn(&[f64], &mut DMatrix<f64>),
    pub analytic: bool,
}

impl Problem for Mgh {
    fn num_parameters(&self) -> usize {
        self.n
    }
    fn num_residuals(&self) -> usize {
        self.m
    }
    fn residuals(&self, p: &[f64], out: &mut [f64]) -> Result<(), EvaluationError> {
        (self.residuals)(p, out);
        Ok(())
    }
    fn jacobian(&self, p: &[f64], out: &mut DMatrix<f64>) -> Option<Result<(), EvaluationError>> {
        self.analytic.then(|| {
            (self.jacobian)(p, out);
            Ok(())
        })
    }
}

pub const ROSENBROCK: Mgh = Mgh {
    name: "rosenbrock",
    n: 2,
    m: 2,
    start: &[-1.2, 1.0],
    residuals: |x, f| {
        f[0] = 10.0 * (x[1] - x[0] * x[0]);
        f[1] = 1.0 - x[0];
    },
    jacobian: |x, j| {
        j[(0, 0)] = -20.0 * x[0];
        j[(0, 1)] = 10.0;
        j[(1, 0)] = -1.0;
    },
    analytic: true,
};

pub const FREUDENSTEIN_ROTH: Mgh = Mgh {
    name: "freudenstein-roth",
    n: 2,
    m: 2,
    start: &[0.5, -2.0],
    residuals: |x, f| {
        f[0] = -13.0 + x[0] + ((5.0 - x[1]) * x[1] - 2.0) * x[1];
        f[1] = -29.0 + x[0] + ((x[1] + 1.0) * x[1] - 14.0) * x[1];
    },
    jacobian: |x, j| {
        j[(0, 0)] = 1.0;
        j[(0, 1)] = 10.0 * x[1] - 3.0 * x[1] * x[1] - 2.0;
        j[(1, 0)] = 1.0;
        j[(1, 1)] = 3.0 * x[1] * x[1] + 2.0 * x[1] - 14.0;
    },
    analytic: true,
};

pub const BROWN_BADLY_SCALED: Mgh = Mgh {
    name: "brown-badly-scaled",
    n: 2,
    m: 3,
    start: &[1.0, 1.0],
    residuals: |x, f| {
        f[0] = x[0] - 1e6;
        f[1] = x[1] - 2e-6;
        f[2] = x[0] * x[1] - 2.0;
    },
    jacobian: |x, j| {
        j[(0, 0)] = 1.0;
        j[(1, 1)] = 1.0;
        j[(2, 0)] = x[1];
        j[(2, 1)] = x[0];
    },
    analytic: true,
};

const BEALE_Y: [f64; 3] = [1.5, 2.25, 2.625];

pub const BEALE: Mgh = Mgh {
    name: "beale",
    n: 2,
    m: 3,
    start: &[1.0, 1.0],
    residuals: |x, f| {
        for i in 0..3 {
            f[i] = BEALE_Y[i] - x[0] * (1.0 - x[1].powi(i as i32 + 1));
        }
    },
    jacobian: |x, j| {
        for i in 0..3 {
            let power = i as i32 + 1;
            j[(i, 0)] = -(1.0 - x[1].powi(power));
            j[(i, 1)] = x[0] * f64::from(power) * x[1].powi(power - 1);
        }
    },
    analytic: true,
};

fn helix_angle(x: &[f64]) -> f64 {
    let two_pi = 2.0 * std::f64::consts::PI;
    if x[0] > 0.0 {
        (x[1] / x[0]).atan() / two_pi
    } else if x[0] < 0.0 {
        (x[1] / x[0]).atan() / two_pi + 0.5
    } else {
        0.25_f64.copysign(x[1])
    }
}

pub const HELICAL_VALLEY: Mgh = Mgh {
    name: "helical-valley",
    n: 3,
    m: 3,
    start: &[-1.0, 0.0, 0.0],
    residuals: |x, f| {
        f[0] = 10.0 * (x[2] - 10.0 * helix_angle(x));
        f[1] = 10.0 * (x[0].hypot(x[1]) - 1.0);
        f[2] = x[2];
    },
    jacobian: |x, j| {
        let radius_squared = x[0] * x[0] + x[1] * x[1];
        let radius = radius_squared.sqrt();
        let factor = 100.0 / (2.0 * std::f64::consts::PI * radius_squared);
        j[(0, 0)] = factor * x[1];
        j[(0, 1)] = -factor * x[0];
        j[(0, 2)] = 10.0;
        j[(1, 0)] = 10.0 * x[0] / radius;
        j[(1, 1)] = 10.0 * x[1] / radius;
        j[(2, 2)] = 1.0;
    },
    analytic: true,
};

const BARD_Y: [f64; 15] = [
    0.14, 0.18, 0.22, 0.25, 0.29, 0.32, 0.35, 0.39, 0.37, 0.58, 0.73, 0.96, 1.34, 2.10, 4.39,
];

fn bard_uvw(i: usize) -> (f64, f64, f64) {
    let u = (i + 1) as f64;
    let v = (15 - i) as f64;
    (u, v, u.min(v))
}

pub const BARD: Mgh = Mgh {
    name: "bard",
    n: 3,
    m: 15,
    start: &[1.0, 1.0, 1.0],
    residuals: |x, f| {
        for i in 0..15 {
            let (u, v, w) = bard_uvw(i);
            f[i] = BARD_Y[i] - (x[0] + u / (v * x[1] + w * x[2]));
        }
    },
    jacobian: |x, j| {
        for i in 0..15 {
            let (u, v, w) = bard_uvw(i);
            let denominator = v * x[1] + w * x[2];
            let d2 = denominator * denominator;
            j[(i, 0)] = -1.0;
            j[(i, 1)] = u * v / d2;
            j[(i, 2)] = u * w / d2;
        }
    },
    analytic: true,
};

pub const BOX_3D: Mgh = Mgh {
    name: "box-3d",
    n: 3,
    m: 10,
    start: &[0.0, 10.0, 20.0],
    residuals: |x, f| {
        for i in 0..10 {
            let t = 0.1 * (i + 1) as f64;
            f[i] = (-t * x[0]).exp() - (-t * x[1]).exp() - x[2] * ((-t).exp() - (-10.0 * t).exp());
        }
    },
    jacobian: |x, j| {
        for i in 0..10 {
            let t = 0.1 * (i + 1) as f64;
            j[(i, 0)] = -t * (-t * x[0]).exp();
            j[(i, 1)] = t * (-t * x[1]).exp();
            j[(i, 2)] = -((-t).exp() - (-10.0 * t).exp());
        }
    },
    analytic: true,
};

pub const POWELL_SINGULAR: Mgh = Mgh {
    name: "powell-singular",
    n: 4,
    m: 4,
    start: &[3.0, -1.0, 0.0, 1.0],
    residuals: |x, f| {
        f[0] = x[0] + 10.0 * x[1];
        f[1] = 5f64.sqrt() * (x[2] - x[3]);
        f[2] = (x[1] - 2.0 * x[2]).powi(2);
        f[3] = 10f64.sqrt() * (x[0] - x[3]).powi(2);
    },
    jacobian: |x, j| {
        j[(0, 0)] = 1.0;
        j[(0, 1)] = 10.0;
        j[(1, 2)] = 5f64.sqrt();
        j[(1, 3)] = -(5f64.sqrt());
        j[(2, 1)] = 2.0 * (x[1] - 2.0 * x[2]);
        j[(2, 2)] = -4.0 * (x[1] - 2.0 * x[2]);
        j[(3, 0)] = 2.0 * 10f64.sqrt() * (x[0] - x[3]);
        j[(3, 3)] = -2.0 * 10f64.sqrt() * (x[0] - x[3]);
    },
    analytic: true,
};

const MEYER_Y: [f64; 16] = [
    34780.0, 28610.0, 23650.0, 19630.0, 16370.0, 13720.0, 11540.0, 9744.0, 8261.0, 7030.0, 6005.0,
    5147.0, 4427.0, 3820.0, 3307.0, 2872.0,
];

pub const MEYER: Mgh = Mgh {
    name: "meyer",
    n: 3,
    m: 16,
    start: &[0.02, 4000.0, 250.0],
    residuals: |x, f| {
        for i in 0..16 {
            let t = 45.0 + 5.0 * (i + 1) as f64;
            f[i] = x[0] * (x[1] / (t + x[2])).exp() - MEYER_Y[i];
        }
    },
    jacobian: |x, j| {
        for i in 0..16 {
            let t = 45.0 + 5.0 * (i + 1) as f64;
            let e = (x[1] / (t + x[2])).exp();
            j[(i, 0)] = e;
            j[(i, 1)] = x[0] * e / (t + x[2]);
            j[(i, 2)] = -x[0] * e * x[1] / ((t + x[2]) * (t + x[2]));
        }
    },
    analytic: true,
};

pub const ALL: [Mgh; 9] = [
    ROSENBROCK,
    FREUDENSTEIN_ROTH,
    BROWN_BADLY_SCALED,
    BEALE,
    HELICAL_VALLEY,
    BARD,
    BOX_3D,
    POWELL_SINGULAR,
    MEYER,
];

impl Mgh {
    /// The same problem with finite differences instead of the Jacobian.
    pub fn numerical(self) -> Self {
        Self {
            analytic: false,
            ..self
        }
    }

    /// Unbounded, free parameters at the standard start.
    pub fn parameters(&self) -> Vec<needle_lsq::Parameter> {
        self.start
            .iter()
            .enumerate()
            .map(|(j, &x)| needle_lsq::Parameter::new(format!("x{}", j + 1), x))
            .collect()
    }
}
