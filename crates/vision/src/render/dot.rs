//! One dot's blurred coverage on the rectangle of pixels around it.
//!
//! A pixel's coverage needs the plane point $q(t)$ seen at its centre $t$,
//! found by Newton's method on the forward projection, but only where the
//! rim can pass through the pixel; everywhere else the coverage is exactly
//! 0 or 1. Let $f(t) = |q(t) - c| - R$ be the plane distance (m) of that
//! point from the rim. The coverage formula measures the signed pixel
//! distance $f / |J^{-T} \nabla_q f|$ with $|\nabla_q f| = 1$, which is at
//! least $f / L$ in size for $L \ge \|J^{-1}\|_2$; once
//! $|f| \ge L \sqrt2/2$ the rim's tangent misses the pixel square and the
//! coverage is exactly 0 (outside) or 1 (inside).
//!
//! To know $|f|$ is that large without solving, the projection is replaced
//! by its affine model about the dot's centre, $q_a(t) = c + J_c^{-1}(t - p_c)$,
//! whose error is second order: $|q(t) - q_a(t)| \le \kappa |t - p_c|^2$.
//! Then $|f(t)| \ge |f_a(t)| - e(t)$ with $f_a = |q_a - c| - R$ and
//! $e(t) = 2 \kappa |t - p_c|^2 + \epsilon$, and a pixel with
//! $|f_a(t)| - e(t) \ge L (\sqrt2/2 + 10^{-3})$ is filled with 0 or 1
//! without solving: only a band about two pixels wide round the rim is
//! solved. $\kappa$ is the largest $|q - q_a| / |t - p_c|^2$ on a ring of 64
//! exact points just outside the rim (the factor 2 covers third-order
//! terms and the directions between samples); $\epsilon$, a thousandth of
//! a pixel in the plane, covers round-off and Newton's tolerance. $L$ is the
//! largest $\|J^{-1}\|_2$ at the centre and on the ring times
//! [`BOUND_HEADROOM`]; $J$ changes by well under 1% across a dot for any
//! real camera. Every solved pixel checks both bounds: should its model
//! error exceed $e(t) / 1.5$ or its $\|J^{-1}\|_2$ come within
//! [`CHECKED_HEADROOM`] of $L$, the dot is solved again at every pixel.
//!
//! Each solve starts from the affine model corrected by the last solved
//! pixel's model error (or, next to it, moved from it by its inverse
//! Jacobian), so Newton's method starts well within a pixel of the answer.

use nalgebra::{Matrix2, Rotation3, Vector2, Vector3};

use super::RenderOptions;
use super::blur::blur;
use super::coverage::{HALF_DIAGONAL, pixel_coverage};
use crate::{Camera, Pose, VisionError};

/// Factor by which the skipping bound $L$ exceeds the largest
/// $\|J^{-1}\|_2$ seen at the centre and on the ring.
const BOUND_HEADROOM: f64 = 1.25;

/// A solved pixel whose $\|J^{-1}\|_2$ times this exceeds $L$ means the
/// bound is not safe for this dot.
const CHECKED_HEADROOM: f64 = 1.1;

/// Pixels of clearance (half the pixel diagonal plus a margin for
/// round-off) a filled pixel's centre keeps from the rim.
const CLEARANCE: f64 = HALF_DIAGONAL + 1e-3;

/// Factor on the largest model error seen on the ring, for third-order
/// terms and directions between the samples.
const MODEL_HEADROOM: f64 = 2.0;

/// A solved pixel whose model error times this exceeds the bound $e(t)$
/// means the bound is not safe for this dot.
const CHECKED_MODEL_HEADROOM: f64 = 1.5;

/// Model error allowed whatever the distance, in pixels.
const MODEL_FLOOR: f64 = 1e-3;

/// Rendered darkness (blurred dot coverage) of one dot, on a rectangle of
/// pixels.
pub(super) struct Patch {
    pub column: usize,
    pub row: usize,
    pub width: usize,
    pub height: usize,
    pub values: Vec<f32>,
}

/// Pixel and $\partial p / \partial q$ of the in-plane point $q$ at height
/// `z` in the face frame.
fn project_in_plane(
    camera: &Camera,
    rotation: &Rotation3<f64>,
    translation: &Vector3<f64>,
    q: Vector2<f64>,
    z: f64,
) -> Option<(Vector2<f64>, Matrix2<f64>)> {
    let xc = rotation * Vector3::new(q.x, q.y, z) + translation;
    if xc.z <= 0.0 {
        return None;
    }
    let inv_z = 1.0 / xc.z;
    let n = Vector2::new(xc.x * inv_z, xc.y * inv_z);
    let (d, dd_dn) = camera.distortion.distort_with_jacobian(n);
    let r = rotation.matrix();
    // dn/dq = (1/z) [r_0j - n_x r_2j ; r_1j - n_y r_2j], j = 0, 1.
    let dn_dq = Matrix2::new(
        (r[(0, 0)] - n.x * r[(2, 0)]) * inv_z,
        (r[(0, 1)] - n.x * r[(2, 1)]) * inv_z,
        (r[(1, 0)] - n.y * r[(2, 0)]) * inv_z,
        (r[(1, 1)] - n.y * r[(2, 1)]) * inv_z,
    );
    Some((
        camera.intrinsics.to_pixel(d),
        camera.intrinsics.jacobian() * dd_dn * dn_dq,
    ))
}

/// $\|M\|_2$ of a 2 x 2 matrix, from its Frobenius norm and determinant.
fn spectral_norm(m: &Matrix2<f64>) -> f64 {
    let frobenius = m.norm_squared();
    let det = m.determinant();
    (0.5 * (frobenius + (frobenius * frobenius - 4.0 * det * det).max(0.0).sqrt())).sqrt()
}

/// The plane point seen at a pixel, and $\partial q / \partial p$ there.
#[derive(Clone, Copy)]
struct PlanePoint {
    point: Vector2<f64>,
    inverse_jacobian: Matrix2<f64>,
}

/// The plane point seen at pixel `target` by Newton's method from `start`;
/// `None` if it does not converge.
fn solve_plane_point(
    project: &impl Fn(Vector2<f64>) -> Result<(Vector2<f64>, Matrix2<f64>), VisionError>,
    target: Vector2<f64>,
    start: Vector2<f64>,
) -> Result<Option<PlanePoint>, VisionError> {
    let mut q = start;
    for _ in 0..30 {
        let (p, j) = project(q)?;
        let Some(inverse) = j.try_inverse() else {
            return Ok(None);
        };
        let error = target - p;
        q += inverse * error;
        if error.norm() < 1e-9 {
            return Ok(Some(PlanePoint {
                point: q,
                inverse_jacobian: inverse,
            }));
        }
    }
    Ok(None)
}

/// Where a dot's patch lies and how its pixels map onto its plane.
struct DotView<'a, P> {
    project: &'a P,
    centre: Vector3<f64>,
    radius: f64,
    column: usize,
    row: usize,
    width: usize,
    height: usize,
    /// Pixel of the dot's centre and inverse Jacobian there: the affine
    /// model.
    centre_pixel: Vector2<f64>,
    centre_inverse: Matrix2<f64>,
}

/// What filling pixels without solving may rely on.
#[derive(Clone, Copy)]
struct Bounds {
    /// $L$ (m per px).
    lipschitz: f64,
    /// $\kappa$ times [`MODEL_HEADROOM`] (m per px$^2$).
    model: f64,
    /// $\epsilon$ (m).
    floor: f64,
}

impl<P> DotView<'_, P>
where
    P: Fn(Vector2<f64>) -> Result<(Vector2<f64>, Matrix2<f64>), VisionError>,
{
    /// Coverage of every pixel of the patch, row-major, filling pixels
    /// proved wholly inside or outside when `bounds` are given; `None` if a
    /// solved pixel shows the bounds unsafe.
    fn coverage(&self, bounds: Option<Bounds>) -> Result<Option<Vec<f64>>, VisionError> {
        let centre = Vector2::new(self.centre.x, self.centre.y);
        let model = |t: Vector2<f64>| centre + self.centre_inverse * (t - self.centre_pixel);
        let mut coverage = vec![0.0; self.width * self.height];
        // The last solved pixel and what it sees.
        let mut last: Option<(Vector2<f64>, PlanePoint)> = None;
        for r in 0..self.height {
            for c in 0..self.width {
                let target = Vector2::new((self.column + c) as f64, (self.row + r) as f64);
                let modelled = model(target);
                let model_error =
                    bounds.map(|b| b.model * (target - self.centre_pixel).norm_squared() + b.floor);
                if let (Some(b), Some(e)) = (bounds, model_error) {
                    let rim_distance = (modelled - centre).norm() - self.radius;
                    if rim_distance.abs() - e >= b.lipschitz * CLEARANCE {
                        coverage[r * self.width + c] = if rim_distance > 0.0 { 0.0 } else { 1.0 };
                        continue;
                    }
                }
                let start = match last {
                    Some((t, seen)) if (t - target).norm_squared() <= 1.0 => {
                        seen.point + seen.inverse_jacobian * (target - t)
                    }
                    Some((t, seen)) => modelled + (seen.point - model(t)),
                    None => modelled,
                };
                let Some(seen) = solve_plane_point(self.project, target, start)? else {
                    return Err(VisionError::InvalidParameter {
                        field: "markers",
                        reason: format!(
                            "pixel ({}, {}) near the dot at {:?} does not map back onto its plane",
                            target.x, target.y, self.centre
                        ),
                    });
                };
                last = Some((target, seen));
                coverage[r * self.width + c] =
                    pixel_coverage(seen.point - centre, &seen.inverse_jacobian, self.radius);
                if let (Some(b), Some(e)) = (bounds, model_error)
                    && (CHECKED_HEADROOM * spectral_norm(&seen.inverse_jacobian) > b.lipschitz
                        || CHECKED_MODEL_HEADROOM * (seen.point - modelled).norm() > e)
                {
                    return Ok(None);
                }
            }
        }
        Ok(Some(coverage))
    }
}

/// Render one dot's blurred coverage; `None` if it is entirely outside the
/// frame. With `solve_every_pixel` no pixel is filled without solving (the
/// reference the tests compare against).
pub(super) fn render_dot(
    camera: &Camera,
    pose: &Pose,
    centre: &Vector3<f64>,
    options: &RenderOptions,
    kernel: &[f64],
    solve_every_pixel: bool,
) -> Result<Option<Patch>, VisionError> {
    let rotation = pose.rotation_matrix();
    let translation = pose.translation_vector();
    let radius = 0.5 * options.dot_diameter;
    let project = |q: Vector2<f64>| {
        project_in_plane(camera, &rotation, &translation, q, centre.z).ok_or(
            VisionError::BehindCamera {
                x: q.x,
                y: q.y,
                z: centre.z,
            },
        )
    };
    let centre_q = Vector2::new(centre.x, centre.y);
    let (centre_p, centre_j) = project(centre_q)?;
    let centre_inverse = centre_j.try_inverse();
    // Bounding box of the rim, from points on a slightly larger circle,
    // and the largest inverse Jacobian and model error there.
    let (mut lo, mut hi) = (
        Vector2::repeat(f64::INFINITY),
        Vector2::repeat(f64::NEG_INFINITY),
    );
    let mut largest_inverse = centre_inverse.map_or(f64::INFINITY, |i| spectral_norm(&i));
    // kappa (m per px^2): the affine model's error over the squared pixel
    // distance from the centre.
    let mut model_curvature: f64 = 0.0;
    for i in 0..64 {
        let angle = i as f64 * std::f64::consts::TAU / 64.0;
        let q = centre_q + 1.1 * radius * Vector2::new(angle.cos(), angle.sin());
        let (p, j) = project(q)?;
        lo = lo.inf(&p);
        hi = hi.sup(&p);
        largest_inverse = largest_inverse.max(
            j.try_inverse()
                .map_or(f64::INFINITY, |inverse| spectral_norm(&inverse)),
        );
        let offset = p - centre_p;
        let modelled = centre_q + centre_inverse.unwrap_or_else(Matrix2::zeros) * offset;
        model_curvature = model_curvature.max((q - modelled).norm() / offset.norm_squared());
    }
    let margin = (kernel.len() / 2) as f64 + 2.0;
    let c0 = (lo.x - margin).floor().max(0.0);
    let r0 = (lo.y - margin).floor().max(0.0);
    let c1 = (hi.x + margin).ceil().min(options.width as f64 - 1.0);
    let r1 = (hi.y + margin).ceil().min(options.height as f64 - 1.0);
    if !(c0 <= c1 && r0 <= r1) {
        return Ok(None);
    }
    let (c0, r0, c1, r1) = (c0 as usize, r0 as usize, c1 as usize, r1 as usize);
    let centre_inverse = centre_inverse.ok_or(VisionError::InvalidParameter {
        field: "pose",
        reason: "the face plane is seen edge-on".into(),
    })?;
    let view = DotView {
        project: &project,
        centre: *centre,
        radius,
        column: c0,
        row: r0,
        width: c1 - c0 + 1,
        height: r1 - r0 + 1,
        centre_pixel: centre_p,
        centre_inverse,
    };
    let lipschitz = BOUND_HEADROOM * largest_inverse;
    let bounds = (!solve_every_pixel && lipschitz.is_finite() && model_curvature.is_finite())
        .then_some(Bounds {
            lipschitz,
            model: MODEL_HEADROOM * model_curvature,
            floor: MODEL_FLOOR * lipschitz,
        });
    let coverage = match view.coverage(bounds)? {
        Some(coverage) => coverage,
        None => view
            .coverage(None)?
            .expect("solving every pixel never gives up on the bound"),
    };
    let blurred = if kernel.len() > 1 {
        blur(&coverage, view.width, view.height, kernel)
    } else {
        coverage
    };
    Ok(Some(Patch {
        column: c0,
        row: r0,
        width: view.width,
        height: view.height,
        values: blurred.into_iter().map(|v| v as f32).collect(),
    }))
}
