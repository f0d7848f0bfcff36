//! Inverting the distortion of equation (1) by damped Newton iteration.
//!
//! Given a distorted normalised point $d^\ast$, find $n$ with $d(n) = d^\ast$
//! inside the disc $|n| < r_{\max}$ on which the radial part of the map is
//! monotone ([`Distortion::monotone_radius`]). Outside that disc the map folds
//! over and a preimage is not unique; a point whose only preimages lie there
//! (or where the Jacobian is singular) is reported as
//! [`VisionError::NotInvertible`], never returned as a wrong point.

use nalgebra::Vector2;

use crate::{Camera, Distortion, VisionError};

/// Residual below which the iteration has converged, in normalised units
/// (about 1e-10 px for focal lengths of a few thousand pixels).
const TOLERANCE: f64 = 1e-13;
const MAX_ITERATIONS: usize = 100;

impl Distortion {
    /// The undistorted normalised point $n$ with $d(n) = $ `distorted`.
    pub fn undistort(&self, distorted: Vector2<f64>) -> Result<Vector2<f64>, VisionError> {
        self.undistort_within(distorted, self.monotone_radius())
    }

    /// [`Distortion::undistort`] with the monotone radius computed beforehand
    /// (it costs a scan; hot loops compute it once).
    pub fn undistort_within(
        &self,
        distorted: Vector2<f64>,
        radius_limit: f64,
    ) -> Result<Vector2<f64>, VisionError> {
        let fail = |reason: &str| VisionError::NotInvertible {
            x: distorted.x,
            y: distorted.y,
            reason: reason.to_string(),
        };
        if !distorted.x.is_finite() || !distorted.y.is_finite() {
            return Err(fail("non-finite input"));
        }
        let mut n = distorted;
        if n.norm() >= radius_limit {
            n *= 0.5 * radius_limit / n.norm();
        }
        let mut residual = self.distort(n) - distorted;
        for _ in 0..MAX_ITERATIONS {
            let (_, jacobian) = self.distort_with_jacobian(n);
            if residual.norm() < TOLERANCE {
                if jacobian.determinant() <= 0.0 {
                    return Err(fail("the distortion map folds over at the solution"));
                }
                return Ok(n);
            }
            let Some(inverse) = jacobian.try_inverse() else {
                return Err(fail("singular Jacobian"));
            };
            let step = inverse * residual;
            let mut scale = 1.0;
            loop {
                let candidate = n - scale * step;
                if candidate.norm() < radius_limit {
                    let candidate_residual = self.distort(candidate) - distorted;
                    if candidate_residual.norm() < residual.norm() {
                        n = candidate;
                        residual = candidate_residual;
                        break;
                    }
                }
                scale *= 0.5;
                if scale < 1e-12 {
                    return Err(fail("no preimage inside the monotone radius"));
                }
            }
        }
        Err(fail("Newton iteration did not converge"))
    }
}

impl Camera {
    /// The undistorted normalised coordinates (a ray direction $(n_x, n_y, 1)$)
    /// of a pixel.
    pub fn undistort_pixel(&self, pixel: Vector2<f64>) -> Result<Vector2<f64>, VisionError> {
        self.distortion
            .undistort(self.intrinsics.to_normalised(pixel))
    }
}
