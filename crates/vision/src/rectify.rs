//! Rectification: the map between pixels and positions on the phantom top
//! face, and the [`Calibration`] that holds what it needs.
//!
//! The top face is the plane $z = 0$ of the face frame. A pixel is
//! undistorted to a ray $(n_x, n_y, 1)$ in the camera frame; in the face
//! frame the ray is $X(s) = R^{\mathsf T}(s\,\tilde n - t)$ and it meets the
//! face where $X_z(s) = 0$, $s = (R^{\mathsf T} t)_z / (R^{\mathsf T}\tilde n)_z$.

use std::path::Path;

use nalgebra::{Matrix2, Vector2, Vector3};
use serde::{Deserialize, Serialize};

use crate::{Camera, Pose, VisionError};

/// Everything needed to turn pixels of the tracking camera into top-face
/// positions: frame size, camera model and the top face's pose. Stored as RON.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Calibration {
    /// Frame width (px).
    pub width: u32,
    /// Frame height (px).
    pub height: u32,
    /// Intrinsics and distortion.
    pub camera: Camera,
    /// Pose of the phantom top face (face frame to camera frame).
    pub face_pose: Pose,
    /// Reprojection RMS of the calibration that produced it (px).
    pub reprojection_rms: f64,
}

impl Calibration {
    /// The paper's set-up, nominally: a 2056 x 1544 camera 0.2 m above the
    /// 75 mm phantom, about 0.079 mm per pixel on the top face, the face
    /// centred and slightly tilted, a mild barrel distortion. For synthetic
    /// experiments and benchmarks, not a measured calibration.
    pub fn paper() -> Calibration {
        Calibration {
            width: 2056,
            height: 1544,
            camera: Camera {
                intrinsics: crate::Intrinsics {
                    fx: 2532.0,
                    fy: 2532.0,
                    cx: 1027.5,
                    cy: 771.5,
                    skew: 0.0,
                },
                distortion: crate::Distortion {
                    k1: -0.08,
                    k2: 0.02,
                    k3: 0.0,
                    p1: 2e-4,
                    p2: -1e-4,
                },
            },
            face_pose: Pose {
                rotation: [0.02, -0.015, 0.005],
                translation: [-0.0375, -0.0375, 0.2],
            },
            reprojection_rms: 0.0,
        }
    }

    /// Check every value.
    pub fn validate(&self) -> Result<(), VisionError> {
        if self.width == 0 || self.height == 0 {
            return Err(VisionError::InvalidParameter {
                field: "calibration width/height",
                reason: format!("{} x {}", self.width, self.height),
            });
        }
        self.camera.validate()?;
        self.face_pose.validate()
    }

    /// Pixel of a top-face point (m).
    pub fn face_to_pixel(&self, point: Vector2<f64>) -> Result<Vector2<f64>, VisionError> {
        self.camera
            .project(&self.face_pose, &Vector3::new(point.x, point.y, 0.0))
    }

    /// Top-face point (m) seen at a pixel.
    pub fn pixel_to_face(&self, pixel: Vector2<f64>) -> Result<Vector2<f64>, VisionError> {
        let n = self.camera.undistort_pixel(pixel)?;
        let rotation = self.face_pose.rotation_matrix();
        let ray = rotation.inverse() * Vector3::new(n.x, n.y, 1.0);
        let origin = -(rotation.inverse() * self.face_pose.translation_vector());
        // X(s) = origin + s ray; X_z = 0.
        if ray.z.abs() < 1e-12 {
            return Err(VisionError::RayMissesPlane {
                u: pixel.x,
                v: pixel.y,
            });
        }
        let s = -origin.z / ray.z;
        if s <= 0.0 {
            return Err(VisionError::RayMissesPlane {
                u: pixel.x,
                v: pixel.y,
            });
        }
        let point = origin + s * ray;
        Ok(Vector2::new(point.x, point.y))
    }

    /// $\partial (x, y) / \partial (u, v)$ at a top-face point: metres per
    /// pixel, to carry tracking uncertainty onto the face.
    pub fn face_per_pixel(&self, point: Vector2<f64>) -> Result<Matrix2<f64>, VisionError> {
        let j = self
            .camera
            .project_with_jacobians(&self.face_pose, &Vector3::new(point.x, point.y, 0.0))?;
        let in_plane = j.point.fixed_columns::<2>(0).into_owned();
        in_plane.try_inverse().ok_or(VisionError::RayMissesPlane {
            u: j.pixel.x,
            v: j.pixel.y,
        })
    }

    /// Read from a RON file.
    pub fn load(path: &Path) -> Result<Calibration, VisionError> {
        let text = std::fs::read_to_string(path).map_err(|source| VisionError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let calibration: Calibration = ron::from_str(&text).map_err(|e| VisionError::Ron {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })?;
        calibration.validate()?;
        Ok(calibration)
    }

    /// Write as RON; the file gets its final name only once complete.
    pub fn save(&self, path: &Path) -> Result<(), VisionError> {
        let text =
            ron::ser::to_string_pretty(self, ron::ser::PrettyConfig::default()).map_err(|e| {
                VisionError::Ron {
                    path: path.to_path_buf(),
                    reason: e.to_string(),
                }
            })?;
        let partial = path.with_extension("ron.partial");
        std::fs::write(&partial, text).map_err(|source| VisionError::Io {
            path: partial.clone(),
            source,
        })?;
        std::fs::rename(&partial, path).map_err(|source| VisionError::Io {
            path: path.to_path_buf(),
            source,
        })
    }
}
