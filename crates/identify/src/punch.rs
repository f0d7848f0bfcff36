//! The contact patch of a rigid, frictionless flat punch of width $a$
//! pressed on a face: the classical half-plane solution puts the pressure
//!
//! $$p(s) = \frac{F}{\pi\sqrt{(a/2)^2 - s^2}}, \qquad |s| < a/2,$$
//!
//! along the face ($s$ from the patch centre), which integrates to $F$ and
//! is singular at the punch edges. With $s = \tfrac a2\cos\varphi$ the
//! weight turns into $d\varphi/\pi$ on $[0, \pi]$, so the consistent nodal
//! load of a unit force is $\frac1\pi\int_0^\pi N(\tfrac a2\cos\varphi)\,
//! d\varphi$ for every shape function $N$. The equal-weight Gauss-Chebyshev
//! rule samples exactly this (the midpoint rule in $\varphi$), but the
//! shape functions kink at the mesh lines crossing the patch, and a sample
//! crossing a line as $a$ changes would make the load, and the fit of $a$,
//! jump in slope. Here the $\varphi$ interval is split where the patch
//! crosses mesh lines and each piece integrated by Gauss-Legendre: on each
//! piece the integrand is smooth, the load is exact to rounding for any
//! $a$, and it is continuously differentiable in $a$.

use std::f64::consts::PI;

use needle_fem::element::quadrature::gauss_legendre_unit;

/// Gauss-Legendre points per piece of the patch between mesh lines: on
/// each piece the integrand is a polynomial in $\cos\varphi$ (quadratic
/// for T6 and Tet10), analytic in $\varphi$, and twelve points on a piece
/// as long as $\pi$ integrate $\cos 2\varphi$ to about $10^{-18}$.
const POINTS_PER_PIECE: usize = 12;

/// Positions along the face and weights (summing to 1) of a unit punch
/// force of `width` centred at `centre`, split at the mesh `lines` that
/// cross the patch. Positions past the face's ends `extent` are clamped
/// onto them (a patch reaching past a corner keeps its whole force). A
/// width of zero is the point force at `centre`; the rule is even in the
/// width, so a difference quotient about zero is well defined.
pub(crate) fn patch_rule(
    centre: f64,
    width: f64,
    lines: &[f64],
    extent: (f64, f64),
) -> Vec<(f64, f64)> {
    let half = 0.5 * width.abs();
    let clamp = |s: f64| s.clamp(extent.0, extent.1);
    if half == 0.0 {
        return vec![(clamp(centre), 1.0)];
    }
    let mut angles = vec![0.0, PI];
    angles.extend(
        lines
            .iter()
            .map(|&line| (line - centre) / half)
            .filter(|c| c.abs() < 1.0)
            .map(f64::acos),
    );
    angles.sort_by(f64::total_cmp);
    angles.dedup();
    let rule = gauss_legendre_unit(POINTS_PER_PIECE);
    let mut out = Vec::with_capacity(rule.len() * (angles.len() - 1));
    for piece in angles.windows(2) {
        let (a, b) = (piece[0], piece[1]);
        for &(t, w) in &rule {
            let phi = a + t * (b - a);
            out.push((clamp(centre + half * phi.cos()), w * (b - a) / PI));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::patch_rule;

    /// The rule integrates the punch pressure against polynomials exactly:
    /// the moments of $1/(\pi\sqrt{r^2 - s^2})$ are $1, 0, r^2/2, 0,
    /// 3r^4/8$; and against $|s - c|$, which kinks at a mesh line $c$,
    /// to rounding when the rule is split there.
    #[test]
    fn integrates_the_punch_pressure_exactly() {
        let (centre, width) = (0.03, 0.004);
        let r = 0.5 * width;
        let lines = [0.0291, 0.03, 0.0315, 0.05];
        let rule = patch_rule(centre, width, &lines, (0.0, 0.075));
        let moment = |k: i32| -> f64 { rule.iter().map(|&(s, w)| w * (s - centre).powi(k)).sum() };
        assert!((moment(0) - 1.0).abs() < 1e-14);
        assert!(moment(1).abs() < 1e-18);
        assert!((moment(2) / (r * r / 2.0) - 1.0).abs() < 1e-12);
        assert!((moment(4) / (3.0 * r.powi(4) / 8.0) - 1.0).abs() < 1e-12);
        // \int |s - c| p(s) ds for c = 0.0291 (s - c has c' = c - centre):
        // (2/pi) (sqrt(r^2 - c'^2) + c' asin(c'/r)), by hand.
        let c = 0.0291 - centre;
        let exact = 2.0 / std::f64::consts::PI * ((r * r - c * c).sqrt() + c * (c / r).asin());
        let numeric: f64 = rule.iter().map(|&(s, w)| w * (s - 0.0291).abs()).sum();
        assert!(
            (numeric / exact - 1.0).abs() < 1e-12,
            "{numeric} vs {exact}"
        );
    }

    #[test]
    fn zero_width_is_the_point_force_and_corners_clamp() {
        assert_eq!(
            patch_rule(0.02, 0.0, &[0.02], (0.0, 0.075)),
            vec![(0.02, 1.0)]
        );
        let rule = patch_rule(0.001, 0.004, &[], (0.0, 0.075));
        assert!(rule.iter().all(|&(s, _)| s >= 0.0));
        assert!((rule.iter().map(|p| p.1).sum::<f64>() - 1.0).abs() < 1e-14);
        assert_eq!(
            patch_rule(0.03, -0.004, &[0.031], (0.0, 0.075)),
            patch_rule(0.03, 0.004, &[0.031], (0.0, 0.075))
        );
    }
}
