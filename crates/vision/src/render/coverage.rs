//! Exact area coverage of one pixel by a dot, from the plane point seen at
//! the pixel's centre.

use nalgebra::{Matrix2, Vector2};

/// Half the diagonal of the unit pixel: a rim tangent farther than this from
/// the pixel centre misses the pixel square.
pub(super) const HALF_DIAGONAL: f64 = std::f64::consts::FRAC_1_SQRT_2;

/// Covered fraction of the pixel whose centre sees the plane point at
/// `offset` from the dot's centre (m), where `inverse_jacobian` is
/// $\partial q / \partial p$ (m per px) and `radius` the dot's radius (m).
///
/// The signed distance to the rim in pixels is
/// $s = (|q - c| - R) / |J^{-T} \hat n_q|$, the rim's pixel normal
/// $J^{-T} \hat n_q$ normalised; the pixel's covered fraction is the area of
/// the unit square on the inner side of the tangent line at distance $s$,
/// less the sliver between tangent and curved rim.
pub(super) fn pixel_coverage(
    offset: Vector2<f64>,
    inverse_jacobian: &Matrix2<f64>,
    radius: f64,
) -> f64 {
    let distance = offset.norm();
    if distance == 0.0 {
        return 1.0;
    }
    let gradient = inverse_jacobian.transpose() * (offset / distance);
    let scale = gradient.norm();
    if scale == 0.0 {
        return 0.0;
    }
    let signed = (distance - radius) / scale;
    let normal = gradient / scale;
    // Rim curvature (1/px) of the level set |J^-1 (p - p_m)| = r.
    let tangent = Vector2::new(-normal.y, normal.x);
    let curvature = (inverse_jacobian * tangent).norm_squared() / (distance * scale);
    (half_plane_coverage(normal, -signed) - curvature_correction(normal, -signed, curvature))
        .clamp(0.0, 1.0)
}

/// Area of the part of the unit pixel square $[-1/2, 1/2]^2$ where
/// $\nu \cdot x < s$, for a unit normal $\nu$: the distribution function of
/// $\nu \cdot x$ for $x$ uniform on the square, a trapezoid's integral.
fn half_plane_coverage(normal: Vector2<f64>, s: f64) -> f64 {
    let (a, b) = {
        let (x, y) = (normal.x.abs(), normal.y.abs());
        if x >= y { (x, y) } else { (y, x) }
    };
    let outer = 0.5 * (a + b);
    let inner = 0.5 * (a - b);
    if s <= -outer {
        0.0
    } else if s >= outer {
        1.0
    } else if b < 1e-12 {
        (s / a + 0.5).clamp(0.0, 1.0)
    } else if s <= -inner {
        (s + outer).powi(2) / (2.0 * a * b)
    } else if s <= inner {
        b / (2.0 * a) + (s + inner) / a
    } else {
        1.0 - (outer - s).powi(2) / (2.0 * a * b)
    }
}

/// The area between the tangent line $\nu \cdot x = s$ and the rim it
/// touches, inside the unit pixel: the rim lies $\kappa \sigma^2 / 2$ inside
/// the tangent at tangential offset $\sigma$, so the disc covers
/// $\int_{\text{chord}} \kappa \sigma^2 / 2\, d\sigma = \kappa (\sigma_b^3 - \sigma_a^3)/6$
/// less than the half-plane. Summed round a disc of radius $R$ this is
/// $\pi/12$ px$^2$ whatever $R$, which the half-plane alone would add to
/// every dot.
fn curvature_correction(normal: Vector2<f64>, s: f64, curvature: f64) -> f64 {
    // The chord: x = s normal + sigma tangent within [-1/2, 1/2]^2.
    let tangent = Vector2::new(-normal.y, normal.x);
    let (mut low, mut high) = (f64::NEG_INFINITY, f64::INFINITY);
    for k in 0..2 {
        let (foot, direction) = (s * normal[k], tangent[k]);
        if direction.abs() < 1e-15 {
            if foot.abs() > 0.5 {
                return 0.0;
            }
            continue;
        }
        let (a, b) = ((-0.5 - foot) / direction, (0.5 - foot) / direction);
        low = low.max(a.min(b));
        high = high.min(a.max(b));
    }
    if high <= low {
        return 0.0;
    }
    curvature * (high.powi(3) - low.powi(3)) / 6.0
}
