//! Where the shaft load acts: on the material line whose deformed image is
//! the needle.
//!
//! The tool reports the needle in space: its line crosses $y = 0$ at $p_0$
//! and runs along the unit axis $\hat d$ to the tip at arc length $R$. The
//! tissue it holds has been dragged along, so the needle point at spatial
//! arc length $\sigma$, $p(\sigma) = p_0 + \sigma\hat d$, loads the
//! material point $X$ with
//! $$X + u(X) = p(\sigma),$$
//! and the inserted shaft starts where the deformed front face crosses the
//! needle: at the material point $X_e = (x_e, 0)$ whose image lies on the
//! needle's line, $\hat n\cdot(X_e + u(X_e) - p_0) = 0$ ($\hat n \perp \hat
//! d$). That entry lies $\delta = \hat d\cdot(X_e + u(X_e) - p_0)$ inside,
//! so the inserted length is $L = R - \delta$, and the density $q(s)$ is per
//! length of needle, $s = \sigma - \delta$ from the deformed entry: the
//! base force is $\int_0^L q\,ds$.
//!
//! $u$ is the displacement the load itself causes, so the estimator places
//! the load in a field, fits the density, and places it again in the
//! field of that fit ([`crate::estimate`]). A placement in a given field
//! solves the entry by Newton's method on $x_e$ and every material point by
//! Newton's method on $X + u(X) = p$, with the Jacobian $I + \nabla u$ by
//! central differences and steps halved until the misfit drops (plain
//! substitution contracts slowly, or not at all, where the displacement
//! gradient is large, near the tip).
//!
//! The shaft is cut into pieces, [`PIECES_PER_ELEMENT`] per element of the
//! density's basis, so that each hat function is linear on every piece; the
//! load of a piece runs along the straight material segment between the
//! images of its ends and is integrated by three-point Gauss quadrature in
//! $s$.

use crate::error::ForceError;
use crate::shaft::ShaftBasis;

/// A displacement field in the plane of the needle: $u(X)$ at a material
/// point.
pub(crate) type Field<'a> = dyn Fn([f64; 2]) -> Result<[f64; 2], ForceError> + 'a;

/// Pieces of the shaft per element of the density basis.
const PIECES_PER_ELEMENT: usize = 3;

/// Newton steps per material point (and for the entry).
const NEWTON_STEPS: usize = 4;

/// Halvings of a Newton step before giving up on it.
const BACKTRACKS: usize = 6;

/// Step of the central differences of $\nabla u$ (m).
const DIFFERENCE_STEP: f64 = 1e-6;

/// Three-point Gauss-Legendre rule on $[0, 1]$: (abscissa, weight).
const GAUSS: [(f64, f64); 3] = [
    (0.112_701_665_379_258_3, 5.0 / 18.0),
    (0.5, 8.0 / 18.0),
    (0.887_298_334_620_741_7, 5.0 / 18.0),
];

/// The needle in space at one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Needle {
    /// Where its line crosses $y = 0$, $p_0$ (m).
    pub origin: [f64; 2],
    /// Unit axis, into the phantom.
    pub axis: [f64; 2],
    /// Arc length from `origin` to the tip, $R$ (m).
    pub reach: f64,
}

impl Needle {
    /// The needle through the spatial `tip` along `axis`.
    pub fn through(tip: [f64; 2], axis: [f64; 2]) -> Self {
        let reach = tip[1] / axis[1];
        Self {
            origin: [tip[0] - reach * axis[0], 0.0],
            axis,
            reach,
        }
    }

    /// The spatial point at arc length `sigma` from `origin`.
    fn point(&self, sigma: f64) -> [f64; 2] {
        [
            self.origin[0] + sigma * self.axis[0],
            self.origin[1] + sigma * self.axis[1],
        ]
    }
}

/// Where the load of one frame acts, in one displacement field.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Placement {
    /// How far the deformed entry lies inside along the needle, $\delta$ (m).
    pub entry_offset: f64,
    /// The density's basis on the inserted shaft $[0, L]$, $L = R - \delta$.
    pub basis: ShaftBasis,
    /// Material points of the piece ends, entry ($X_e$) first, tip last.
    pub material: Vec<[f64; 2]>,
}

/// A quadrature point of the shaft load.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct LoadPoint {
    /// Where it acts (material point, m).
    pub at: [f64; 2],
    /// Arc length from the deformed entry (m).
    pub s: f64,
    /// Quadrature weight (m): the point carries $w\,q(s)$.
    pub weight: f64,
}

impl Placement {
    /// Places the shaft of `needle` in the field `u`, with density stations
    /// at most `spacing` apart; points are kept inside the phantom's
    /// outline `[0, extent[0]] x [0, extent[1]]`.
    pub fn in_field(
        needle: &Needle,
        spacing: f64,
        u: &Field<'_>,
        extent: [f64; 2],
    ) -> Result<Self, ForceError> {
        let (entry, entry_offset) = entry_in(needle, u, extent)?;
        let length = needle.reach - entry_offset;
        if length.is_nan() || length <= 0.0 {
            return Err(ForceError::BadShaft {
                length,
                reason: "the deformed entry lies beyond the tip",
            });
        }
        let basis = ShaftBasis::new(length, spacing)?;
        let pieces = (basis.len() - 1) * PIECES_PER_ELEMENT;
        let mut material = Vec::with_capacity(pieces + 1);
        material.push(entry);
        for k in 1..=pieces {
            let p = needle.point(entry_offset + length * k as f64 / pieces as f64);
            material.push(material_point(p, u, extent)?);
        }
        Ok(Self {
            entry_offset,
            basis,
            material,
        })
    }

    /// The material point of the tip.
    pub fn tip(&self) -> [f64; 2] {
        *self.material.last().expect("a placement has pieces")
    }

    /// The quadrature points of the load, entry first.
    pub fn load_points(&self) -> Vec<LoadPoint> {
        let pieces = self.material.len() - 1;
        let h = self.basis.length() / pieces as f64;
        let mut points = Vec::with_capacity(pieces * GAUSS.len());
        for (k, ends) in self.material.windows(2).enumerate() {
            for (xi, w) in GAUSS {
                points.push(LoadPoint {
                    at: [
                        ends[0][0] + xi * (ends[1][0] - ends[0][0]),
                        ends[0][1] + xi * (ends[1][1] - ends[0][1]),
                    ],
                    s: (k as f64 + xi) * h,
                    weight: w * h,
                });
            }
        }
        points
    }

    /// How far this placement moved from `other`: the larger move of the
    /// deformed entry and of the tip's material point (m).
    pub fn moved_from(&self, other: &Placement) -> f64 {
        let (a, b) = (self.tip(), other.tip());
        (a[0] - b[0])
            .hypot(a[1] - b[1])
            .max((self.entry_offset - other.entry_offset).abs())
    }
}

/// The entry's material point $X_e = (x_e, 0)$ and the offset $\delta$:
/// Newton's method on $\hat n\cdot(X_e + u(X_e) - p_0) = 0$.
fn entry_in(
    needle: &Needle,
    u: &Field<'_>,
    extent: [f64; 2],
) -> Result<([f64; 2], f64), ForceError> {
    let (d, p0) = (needle.axis, needle.origin);
    let normal = [d[1], -d[0]];
    let image = |x: f64| -> Result<[f64; 2], ForceError> {
        let v = u([x, 0.0])?;
        Ok([x + v[0] - p0[0], v[1] - p0[1]])
    };
    let miss = |x: f64| -> Result<f64, ForceError> {
        let r = image(x)?;
        Ok(normal[0] * r[0] + normal[1] * r[1])
    };
    let inside = |x: f64| x.clamp(DIFFERENCE_STEP, extent[0] - DIFFERENCE_STEP);
    let mut x = inside(p0[0]);
    for _ in 0..NEWTON_STEPS {
        let slope = (miss(inside(x + DIFFERENCE_STEP))? - miss(inside(x - DIFFERENCE_STEP))?)
            / (2.0 * DIFFERENCE_STEP);
        if slope.is_nan() || slope.abs() <= 1e-6 {
            break;
        }
        x = inside(x - miss(x)? / slope);
    }
    let r = image(x)?;
    Ok(([x, 0.0], d[0] * r[0] + d[1] * r[1]))
}

/// The material point $X$ with $X + u(X) = p$, by Newton's method from
/// $X = p - u(p)$.
fn material_point(p: [f64; 2], u: &Field<'_>, extent: [f64; 2]) -> Result<[f64; 2], ForceError> {
    let clamp = |x: [f64; 2]| {
        [
            x[0].clamp(DIFFERENCE_STEP, extent[0] - DIFFERENCE_STEP),
            x[1].clamp(0.0, extent[1] - DIFFERENCE_STEP),
        ]
    };
    let first = u(clamp(p))?;
    let mut x = clamp([p[0] - first[0], p[1] - first[1]]);
    for _ in 0..NEWTON_STEPS {
        let v = u(x)?;
        let r = [x[0] + v[0] - p[0], x[1] + v[1] - p[1]];
        // J = I + grad u, column c by central differences along c.
        let mut j = [[1.0, 0.0], [0.0, 1.0]];
        for c in 0..2 {
            let mut plus = x;
            let mut minus = x;
            plus[c] += DIFFERENCE_STEP;
            minus[c] -= DIFFERENCE_STEP;
            let (plus, minus) = (clamp(plus), clamp(minus));
            let (a, b) = (u(plus)?, u(minus)?);
            let step = plus[c] - minus[c];
            for row in 0..2 {
                j[row][c] += (a[row] - b[row]) / step;
            }
        }
        let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
        if det.is_nan() || det.abs() <= 1e-6 {
            break;
        }
        let dx = [
            (j[1][1] * r[0] - j[0][1] * r[1]) / det,
            (j[0][0] * r[1] - j[1][0] * r[0]) / det,
        ];
        // Backtracking: a full step can overshoot where the gradient
        // changes fast (ahead of the tip); halve it until the misfit drops.
        let misfit = r[0].hypot(r[1]);
        let mut scale = 1.0;
        let mut accepted = None;
        for _ in 0..BACKTRACKS {
            let trial = clamp([x[0] - scale * dx[0], x[1] - scale * dx[1]]);
            if let Ok(v) = u(trial)
                && (trial[0] + v[0] - p[0]).hypot(trial[1] + v[1] - p[1]) < misfit
            {
                accepted = Some(trial);
                break;
            }
            scale *= 0.5;
        }
        match accepted {
            Some(next) => x = next,
            None => break,
        }
    }
    Ok(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn needle() -> Needle {
        Needle::through([0.03, 0.04], [0.0, 1.0])
    }

    #[test]
    fn a_uniform_shift_is_undone_exactly() {
        // u = (0.5 mm, 2 mm): the entry moves in by 2 mm, and each material
        // point is its spatial point minus u.
        let u = |_: [f64; 2]| Ok([0.0005, 0.002]);
        let placement = Placement::in_field(&needle(), 1.5e-3, &u, [0.075, 0.075]).unwrap();
        assert!((placement.entry_offset - 0.002).abs() < 1e-12);
        assert!((placement.basis.length() - 0.038).abs() < 1e-12);
        assert!((placement.material[0][0] - 0.0295).abs() < 1e-12);
        let tip = placement.tip();
        assert!((tip[0] - 0.0295).abs() < 1e-12 && (tip[1] - 0.038).abs() < 1e-12);
        let total: f64 = placement.load_points().iter().map(|p| p.weight).sum();
        assert!((total - 0.038).abs() < 1e-12);
    }

    #[test]
    fn a_linear_field_is_inverted_exactly() {
        // u = G X + c with shear and stretch: the material points solve
        // (I + G) X = p - c, the entry (I + G) X_e has x = 0.03.
        let g = [[0.02, 0.15], [0.05, 0.1]];
        let c = [0.0002, 0.001];
        let field = |x: [f64; 2]| {
            [
                g[0][0] * x[0] + g[0][1] * x[1] + c[0],
                g[1][0] * x[0] + g[1][1] * x[1] + c[1],
            ]
        };
        let u = |x: [f64; 2]| Ok(field(x));
        let needle = needle();
        let placement = Placement::in_field(&needle, 1.5e-3, &u, [0.075, 0.075]).unwrap();
        let xe = (0.03 - c[0]) / (1.0 + g[0][0]);
        assert!((placement.material[0][0] - xe).abs() < 1e-12);
        assert!((placement.entry_offset - (g[1][0] * xe + c[1])).abs() < 1e-12);
        let pieces = placement.material.len() - 1;
        for (k, x) in placement.material.iter().enumerate() {
            let v = field(*x);
            let sigma =
                placement.entry_offset + placement.basis.length() * k as f64 / pieces as f64;
            let p = needle.point(sigma);
            assert!((x[0] + v[0] - p[0]).abs() < 1e-12, "{k}");
            assert!((x[1] + v[1] - p[1]).abs() < 1e-12, "{k}");
        }
    }
}
