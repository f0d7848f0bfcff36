//! Closed-form reference solutions of linear elasticity, used to verify the
//! finite elements (see `tests/convergence.rs`). Plane-strain solutions take
//! the plane-strain material; [`plane_strain_equivalent`] converts for the
//! plane-stress formulas.

use std::f64::consts::PI;

use crate::material::Material;

/// Plane-strain equivalent constants of a plane-stress formula:
/// $E' = E/(1-\nu^2)$, $\nu' = \nu/(1-\nu)$. A plane-stress solution with
/// $(E', \nu')$ is the plane-strain solution with $(E, \nu)$.
pub fn plane_strain_equivalent(youngs_modulus: f64, poisson_ratio: f64) -> (f64, f64) {
    (
        youngs_modulus / (1.0 - poisson_ratio * poisson_ratio),
        poisson_ratio / (1.0 - poisson_ratio),
    )
}

/// Lamé's thick-walled cylinder (inner radius $a$, outer $b$) under internal
/// pressure $p$, plane strain:
/// $u_r = \frac{(1+\nu)\,p\,a^2}{E\,(b^2-a^2)}\left[(1-2\nu)\,r + \frac{b^2}{r}\right]$,
/// $\sigma_{rr} = \frac{p a^2}{b^2-a^2}\left(1 - \frac{b^2}{r^2}\right)$,
/// $\sigma_{\theta\theta} = \frac{p a^2}{b^2-a^2}\left(1 + \frac{b^2}{r^2}\right)$.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LameCylinder {
    /// Inner radius $a$ (m).
    pub inner_radius: f64,
    /// Outer radius $b$ (m).
    pub outer_radius: f64,
    /// Internal pressure $p$ (Pa).
    pub pressure: f64,
    /// Material.
    pub material: Material,
}

impl LameCylinder {
    /// Radial displacement $u_r(r)$.
    pub fn radial_displacement(&self, r: f64) -> f64 {
        let (a, b, p) = (self.inner_radius, self.outer_radius, self.pressure);
        let (e, nu) = (
            self.material.youngs_modulus(),
            self.material.poisson_ratio(),
        );
        (1.0 + nu) * p * a * a / (e * (b * b - a * a)) * ((1.0 - 2.0 * nu) * r + b * b / r)
    }

    /// Displacement $(u_x, u_y)$ at $(x, y)$.
    pub fn displacement(&self, x: [f64; 2]) -> [f64; 2] {
        let r = x[0].hypot(x[1]);
        let ur = self.radial_displacement(r);
        [ur * x[0] / r, ur * x[1] / r]
    }

    /// Stresses $(\sigma_{rr}, \sigma_{\theta\theta})$ at radius $r$.
    pub fn polar_stress(&self, r: f64) -> (f64, f64) {
        let (a, b, p) = (self.inner_radius, self.outer_radius, self.pressure);
        let c = p * a * a / (b * b - a * a);
        (c * (1.0 - b * b / (r * r)), c * (1.0 + b * b / (r * r)))
    }
}

/// Flamant's solution: a normal line force $P$ (N per unit thickness) pressing
/// on the boundary $y = 0$ of the half-plane $y > 0$ at $x = x_0$. In polar
/// coordinates about the load with $\theta$ measured from $+y$, the only
/// stress is radial: $\sigma_{rr} = -\frac{2P\cos\theta}{\pi r}$.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Flamant {
    /// Force per unit thickness (N/m), positive pressing into the body (+y).
    pub force: f64,
    /// Load position $x_0$ on the boundary.
    pub position: f64,
}

impl Flamant {
    /// Cartesian stress $(\sigma_{xx}, \sigma_{yy}, \tau_{xy})$ at $(x, y)$, $y > 0$:
    /// $\sigma_{ij} = -\frac{2P}{\pi}\frac{y\, d_i d_j}{r^4}$ with $d = (x - x_0, y)$.
    pub fn stress(&self, x: [f64; 2]) -> [f64; 3] {
        let (dx, dy) = (x[0] - self.position, x[1]);
        let r2 = dx * dx + dy * dy;
        let c = -2.0 * self.force * dy / (PI * r2 * r2);
        [c * dx * dx, c * dy * dy, c * dx * dy]
    }
}

/// Timoshenko & Goodier's cantilever: length $L$ along x, height $h$
/// ($-h/2 \le y \le h/2$), unit thickness, plane stress, clamped at $x = 0$
/// (in the sense of this exact solution), parabolic shear resultant $P$
/// (+y) at $x = L$. With $I = h^3/12$:
/// $u_x = -\frac{P y}{6EI}\left[(6L - 3x)x + (2+\nu)(y^2 - h^2/4)\right]$,
/// $u_y = \frac{P}{6EI}\left[3\nu y^2 (L - x) + (4 + 5\nu)\frac{h^2 x}{4} + (3L - x)x^2\right]$,
/// $\sigma_{xx} = -\frac{P (L - x) y}{I}$, $\sigma_{yy} = 0$,
/// $\tau_{xy} = \frac{P}{2I}\left(\frac{h^2}{4} - y^2\right)$.
/// For plane strain use [`plane_strain_equivalent`] constants.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cantilever {
    /// Length $L$ (m).
    pub length: f64,
    /// Height $h$ (m).
    pub height: f64,
    /// Shear resultant $P$ per unit thickness (N/m).
    pub force: f64,
    /// Young's modulus (plane stress).
    pub youngs_modulus: f64,
    /// Poisson's ratio (plane stress).
    pub poisson_ratio: f64,
}

impl Cantilever {
    fn inertia(&self) -> f64 {
        self.height.powi(3) / 12.0
    }

    /// Displacement at $(x, y)$.
    pub fn displacement(&self, p: [f64; 2]) -> [f64; 2] {
        let (x, y) = (p[0], p[1]);
        let (l, h, f, e, nu) = (
            self.length,
            self.height,
            self.force,
            self.youngs_modulus,
            self.poisson_ratio,
        );
        let c = f / (6.0 * e * self.inertia());
        [
            -c * y * ((6.0 * l - 3.0 * x) * x + (2.0 + nu) * (y * y - h * h / 4.0)),
            c * (3.0 * nu * y * y * (l - x)
                + (4.0 + 5.0 * nu) * h * h * x / 4.0
                + (3.0 * l - x) * x * x),
        ]
    }

    /// Shear traction $\tau_{xy}(y)$ on the loaded end.
    pub fn end_shear(&self, y: f64) -> f64 {
        self.force / (2.0 * self.inertia()) * (self.height * self.height / 4.0 - y * y)
    }

    /// Stress $(\sigma_{xx}, \sigma_{yy}, \tau_{xy})$ at $(x, y)$.
    pub fn stress(&self, p: [f64; 2]) -> [f64; 3] {
        [
            -self.force * (self.length - p[0]) * p[1] / self.inertia(),
            0.0,
            self.end_shear(p[1]),
        ]
    }
}

/// A manufactured solution on the unit square, zero on its boundary:
/// $u_x = u_y = \varphi = \sin\pi x \sin\pi y$. The body force that makes it
/// exact is $b = -\nabla\cdot\sigma = -(\lambda+\mu)\nabla(\nabla\cdot u) - \mu\Delta u$,
/// i.e. $b_x = b_y = (\lambda+\mu)\pi^2(\varphi - \cos\pi x\cos\pi y) + 2\mu\pi^2\varphi$
/// with the plane-strain $\lambda, \mu$.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ManufacturedSquare {
    /// Material (plane strain).
    pub material: Material,
}

impl ManufacturedSquare {
    /// Exact displacement.
    pub fn displacement(&self, p: [f64; 2]) -> [f64; 2] {
        let phi = (PI * p[0]).sin() * (PI * p[1]).sin();
        [phi, phi]
    }

    /// Exact displacement gradient $\partial u_i/\partial x_j$ (row `i`).
    pub fn gradient(&self, p: [f64; 2]) -> [[f64; 2]; 2] {
        let dx = PI * (PI * p[0]).cos() * (PI * p[1]).sin();
        let dy = PI * (PI * p[0]).sin() * (PI * p[1]).cos();
        [[dx, dy], [dx, dy]]
    }

    /// Body force per unit volume.
    pub fn body_force(&self, p: [f64; 2]) -> [f64; 2] {
        let (lambda, mu) = (self.material.lame_lambda(), self.material.shear_modulus());
        let phi = (PI * p[0]).sin() * (PI * p[1]).sin();
        let cc = (PI * p[0]).cos() * (PI * p[1]).cos();
        let b = (lambda + mu) * PI * PI * (phi - cc) + 2.0 * mu * PI * PI * phi;
        [b, b]
    }
}
