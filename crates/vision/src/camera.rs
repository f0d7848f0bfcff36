//! The camera model: pinhole intrinsics, the radial-decentering distortion of
//! the paper's equation (1), the pose of the phantom top face, and projection
//! with analytic Jacobians.
//!
//! A point $X$ given in the face frame (the phantom top face is the plane
//! $z = 0$, $x$ and $y$ as in the measurement bundle) is mapped to a pixel by
//!
//! 1. the pose: $X_c = R X + t$ (camera frame, $z$ along the optical axis);
//! 2. the pinhole: $n = (X_{c,x}/X_{c,z},\ X_{c,y}/X_{c,z})$;
//! 3. the distortion (Brown-Conrady), with $r^2 = n_x^2 + n_y^2$:
//!    $d = (1 + k_1 r^2 + k_2 r^4 + k_3 r^6)\, n
//!       + \begin{bmatrix} 2 p_1 n_x n_y + p_2 (r^2 + 2 n_x^2) \\ p_1 (r^2 + 2 n_y^2) + 2 p_2 n_x n_y \end{bmatrix}$;
//! 4. the intrinsics: $u = f_x d_x + s\, d_y + c_x$, $v = f_y d_y + c_y$.
//!
//! In the paper's symbols, $n = (x_n, y_n)$ and $d = (x_p, y_p)$.

use nalgebra::{Matrix2, Matrix2x3, Matrix3, Rotation3, SMatrix, Vector2, Vector3};
use serde::{Deserialize, Serialize};

use crate::VisionError;

/// Pinhole intrinsics in pixels.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    /// Focal length along the pixel rows (px).
    pub fx: f64,
    /// Focal length along the pixel columns (px).
    pub fy: f64,
    /// Principal point column (px).
    pub cx: f64,
    /// Principal point row (px).
    pub cy: f64,
    /// Skew (px); zero for square-grid sensors.
    pub skew: f64,
}

/// The radial-decentering distortion coefficients of equation (1).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Distortion {
    /// Radial, $r^2$.
    pub k1: f64,
    /// Radial, $r^4$.
    pub k2: f64,
    /// Radial, $r^6$.
    pub k3: f64,
    /// Decentering (tangential).
    pub p1: f64,
    /// Decentering (tangential).
    pub p2: f64,
}

/// A camera: intrinsics and distortion.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    /// Pinhole intrinsics.
    pub intrinsics: Intrinsics,
    /// Lens distortion.
    pub distortion: Distortion,
}

/// A rigid pose mapping face-frame points to the camera frame,
/// $X_c = R(\omega) X + t$, with $R(\omega)$ the rotation by the rotation
/// vector $\omega$ (axis times angle).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Rotation vector $\omega$ (rad).
    pub rotation: [f64; 3],
    /// Translation $t$ (m).
    pub translation: [f64; 3],
}

/// Order of the intrinsic parameters in Jacobians: fx, fy, cx, cy, skew.
pub const INTRINSIC_COUNT: usize = 5;
/// Order of the distortion parameters in Jacobians: k1, k2, k3, p1, p2.
pub const DISTORTION_COUNT: usize = 5;
/// Order of the pose parameters in Jacobians: rotation vector, translation.
pub const POSE_COUNT: usize = 6;

/// A projected pixel with its derivatives.
#[derive(Debug, Clone, Copy)]
pub struct ProjectionJacobians {
    /// The pixel $(u, v)$.
    pub pixel: Vector2<f64>,
    /// $\partial (u,v) / \partial$ (fx, fy, cx, cy, skew).
    pub intrinsics: SMatrix<f64, 2, INTRINSIC_COUNT>,
    /// $\partial (u,v) / \partial$ (k1, k2, k3, p1, p2).
    pub distortion: SMatrix<f64, 2, DISTORTION_COUNT>,
    /// $\partial (u,v) / \partial (\omega, t)$.
    pub pose: SMatrix<f64, 2, POSE_COUNT>,
    /// $\partial (u,v) / \partial X$ (face-frame point).
    pub point: Matrix2x3<f64>,
}

impl Intrinsics {
    /// Pixel from distorted normalised coordinates.
    pub fn to_pixel(&self, d: Vector2<f64>) -> Vector2<f64> {
        Vector2::new(
            self.fx * d.x + self.skew * d.y + self.cx,
            self.fy * d.y + self.cy,
        )
    }

    /// Distorted normalised coordinates from a pixel (the inverse of
    /// [`Intrinsics::to_pixel`]).
    pub fn to_normalised(&self, pixel: Vector2<f64>) -> Vector2<f64> {
        let y = (pixel.y - self.cy) / self.fy;
        let x = (pixel.x - self.cx - self.skew * y) / self.fx;
        Vector2::new(x, y)
    }

    /// $\partial (u, v) / \partial d$.
    pub fn jacobian(&self) -> Matrix2<f64> {
        Matrix2::new(self.fx, self.skew, 0.0, self.fy)
    }

    /// Check that the focal lengths are positive and every value finite.
    pub fn validate(&self) -> Result<(), VisionError> {
        let all = [self.fx, self.fy, self.cx, self.cy, self.skew];
        if all.iter().any(|v| !v.is_finite()) {
            return Err(VisionError::InvalidParameter {
                field: "intrinsics",
                reason: format!("non-finite value in {self:?}"),
            });
        }
        if self.fx <= 0.0 || self.fy <= 0.0 {
            return Err(VisionError::InvalidParameter {
                field: "intrinsics",
                reason: format!(
                    "focal lengths must be positive, got fx {} fy {}",
                    self.fx, self.fy
                ),
            });
        }
        Ok(())
    }
}

impl Distortion {
    /// No distortion.
    pub const NONE: Distortion = Distortion {
        k1: 0.0,
        k2: 0.0,
        k3: 0.0,
        p1: 0.0,
        p2: 0.0,
    };

    /// Radial factor $L(r^2) = 1 + k_1 r^2 + k_2 r^4 + k_3 r^6$ and its
    /// derivative with respect to $r^2$.
    fn radial(&self, r2: f64) -> (f64, f64) {
        let l = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        let dl = self.k1 + r2 * (2.0 * self.k2 + 3.0 * r2 * self.k3);
        (l, dl)
    }

    /// Distorted normalised point $d(n)$ of equation (1).
    pub fn distort(&self, n: Vector2<f64>) -> Vector2<f64> {
        let (x, y) = (n.x, n.y);
        let r2 = x * x + y * y;
        let (l, _) = self.radial(r2);
        Vector2::new(
            l * x + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x),
            l * y + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y,
        )
    }

    /// $d(n)$ and $\partial d / \partial n$.
    pub fn distort_with_jacobian(&self, n: Vector2<f64>) -> (Vector2<f64>, Matrix2<f64>) {
        let (x, y) = (n.x, n.y);
        let r2 = x * x + y * y;
        let (l, dl) = self.radial(r2);
        let d = self.distort(n);
        let cross = 2.0 * x * y * dl + 2.0 * self.p1 * x + 2.0 * self.p2 * y;
        let j = Matrix2::new(
            l + 2.0 * x * x * dl + 2.0 * self.p1 * y + 6.0 * self.p2 * x,
            cross,
            cross,
            l + 2.0 * y * y * dl + 6.0 * self.p1 * y + 2.0 * self.p2 * x,
        );
        (d, j)
    }

    /// $\partial d / \partial (k_1, k_2, k_3, p_1, p_2)$ at $n$.
    pub fn parameter_jacobian(&self, n: Vector2<f64>) -> SMatrix<f64, 2, DISTORTION_COUNT> {
        let (x, y) = (n.x, n.y);
        let r2 = x * x + y * y;
        let r4 = r2 * r2;
        let r6 = r4 * r2;
        SMatrix::<f64, 2, DISTORTION_COUNT>::from_row_slice(&[
            x * r2,
            x * r4,
            x * r6,
            2.0 * x * y,
            r2 + 2.0 * x * x,
            y * r2,
            y * r4,
            y * r6,
            r2 + 2.0 * y * y,
            2.0 * x * y,
        ])
    }

    /// The radius $r_{\max}$ of the disc in normalised coordinates on which
    /// the radial part of the map is monotone, i.e. the first root of
    /// $\frac{d}{dr}\left(r L(r^2)\right) = 1 + 3 k_1 r^2 + 5 k_2 r^4 + 7 k_3 r^6$
    /// (infinity if there is none). Undistortion only returns points inside it.
    pub fn monotone_radius(&self) -> f64 {
        let slope = |r: f64| {
            let r2 = r * r;
            1.0 + r2 * (3.0 * self.k1 + r2 * (5.0 * self.k2 + r2 * 7.0 * self.k3))
        };
        // Far beyond any lens' field of view (r = 10 is 84 degrees off axis).
        const SEARCH_LIMIT: f64 = 10.0;
        // Steps of 0.005: a lens polynomial does not dip below zero and
        // recover within one.
        let steps = 2_000;
        let h = SEARCH_LIMIT / steps as f64;
        for i in 0..steps {
            let (a, b) = (i as f64 * h, (i + 1) as f64 * h);
            if slope(b) <= 0.0 {
                // Bisect the sign change in [a, b].
                let (mut lo, mut hi) = (a, b);
                for _ in 0..60 {
                    let mid = 0.5 * (lo + hi);
                    if slope(mid) > 0.0 { lo = mid } else { hi = mid }
                }
                return lo;
            }
        }
        f64::INFINITY
    }

    /// Check that every coefficient is finite.
    pub fn validate(&self) -> Result<(), VisionError> {
        if [self.k1, self.k2, self.k3, self.p1, self.p2]
            .iter()
            .any(|v| !v.is_finite())
        {
            return Err(VisionError::InvalidParameter {
                field: "distortion",
                reason: format!("non-finite coefficient in {self:?}"),
            });
        }
        Ok(())
    }
}

/// The right Jacobian of SO(3): $R(\omega + \delta) \approx R(\omega)\exp([J_r(\omega)\delta]_\times)$.
fn right_jacobian(w: &Vector3<f64>) -> Matrix3<f64> {
    let theta2 = w.norm_squared();
    let wx = w.cross_matrix();
    if theta2 < 1e-16 {
        return Matrix3::identity() - 0.5 * wx;
    }
    let theta = theta2.sqrt();
    let a = (1.0 - theta.cos()) / theta2;
    let b = (theta - theta.sin()) / (theta2 * theta);
    Matrix3::identity() - a * wx + b * wx * wx
}

impl Pose {
    /// A pose from a rotation matrix and a translation.
    pub fn from_rotation_translation(rotation: &Rotation3<f64>, translation: Vector3<f64>) -> Pose {
        let w = rotation.scaled_axis();
        Pose {
            rotation: [w.x, w.y, w.z],
            translation: [translation.x, translation.y, translation.z],
        }
    }

    /// The rotation vector $\omega$.
    pub fn rotation_vector(&self) -> Vector3<f64> {
        Vector3::from(self.rotation)
    }

    /// The rotation $R(\omega)$.
    pub fn rotation_matrix(&self) -> Rotation3<f64> {
        Rotation3::new(self.rotation_vector())
    }

    /// The translation $t$.
    pub fn translation_vector(&self) -> Vector3<f64> {
        Vector3::from(self.translation)
    }

    /// $X_c = R X + t$.
    pub fn transform(&self, point: &Vector3<f64>) -> Vector3<f64> {
        self.rotation_matrix() * point + self.translation_vector()
    }

    /// Check that every value is finite.
    pub fn validate(&self) -> Result<(), VisionError> {
        if self
            .rotation
            .iter()
            .chain(self.translation.iter())
            .any(|v| !v.is_finite())
        {
            return Err(VisionError::InvalidParameter {
                field: "pose",
                reason: format!("non-finite value in {self:?}"),
            });
        }
        Ok(())
    }
}

impl Camera {
    /// Check the intrinsics and distortion.
    pub fn validate(&self) -> Result<(), VisionError> {
        self.intrinsics.validate()?;
        self.distortion.validate()
    }

    /// Pixel of a camera-frame point.
    pub fn project_camera_point(&self, xc: &Vector3<f64>) -> Result<Vector2<f64>, VisionError> {
        if xc.z <= 0.0 || !xc.z.is_finite() {
            return Err(VisionError::BehindCamera {
                x: xc.x,
                y: xc.y,
                z: xc.z,
            });
        }
        let n = Vector2::new(xc.x / xc.z, xc.y / xc.z);
        Ok(self.intrinsics.to_pixel(self.distortion.distort(n)))
    }

    /// Pixel of a face-frame point seen from `pose`.
    pub fn project(&self, pose: &Pose, point: &Vector3<f64>) -> Result<Vector2<f64>, VisionError> {
        self.project_camera_point(&pose.transform(point))
    }

    /// Pixel of a face-frame point and its derivatives with respect to the
    /// intrinsics, the distortion, the pose and the point.
    pub fn project_with_jacobians(
        &self,
        pose: &Pose,
        point: &Vector3<f64>,
    ) -> Result<ProjectionJacobians, VisionError> {
        let rotation = pose.rotation_matrix();
        let rotated = rotation * point;
        let xc = rotated + pose.translation_vector();
        if xc.z <= 0.0 || !xc.z.is_finite() {
            return Err(VisionError::BehindCamera {
                x: xc.x,
                y: xc.y,
                z: xc.z,
            });
        }
        let inv_z = 1.0 / xc.z;
        let n = Vector2::new(xc.x * inv_z, xc.y * inv_z);
        let (d, dd_dn) = self.distortion.distort_with_jacobian(n);
        let k = self.intrinsics.jacobian();
        let pixel = self.intrinsics.to_pixel(d);
        let dn_dxc = Matrix2x3::new(inv_z, 0.0, -n.x * inv_z, 0.0, inv_z, -n.y * inv_z);
        let dp_dxc = k * dd_dn * dn_dxc;
        let intrinsics = SMatrix::<f64, 2, INTRINSIC_COUNT>::from_row_slice(&[
            d.x, 0.0, 1.0, 0.0, d.y, //
            0.0, d.y, 0.0, 1.0, 0.0,
        ]);
        let distortion = k * self.distortion.parameter_jacobian(n);
        // d(R X)/d omega = -R [X]x J_r(omega).
        let dxc_dw =
            -(rotation.matrix() * point.cross_matrix() * right_jacobian(&pose.rotation_vector()));
        let mut pose_jac = SMatrix::<f64, 2, POSE_COUNT>::zeros();
        pose_jac
            .fixed_view_mut::<2, 3>(0, 0)
            .copy_from(&(dp_dxc * dxc_dw));
        pose_jac.fixed_view_mut::<2, 3>(0, 3).copy_from(&dp_dxc);
        Ok(ProjectionJacobians {
            pixel,
            intrinsics,
            distortion,
            pose: pose_jac,
            point: dp_dxc * rotation.matrix(),
        })
    }
}
