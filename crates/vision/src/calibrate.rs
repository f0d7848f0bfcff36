//! Camera calibration from a planar target seen in one or more views:
//! Zhang's closed-form initialisation, then Levenberg-Marquardt refinement
//! (needle-lsq) of the intrinsics, the distortion and every view's pose.
//!
//! 1. Each view's homography $H$ (target plane $z = 0$ to pixels, distortion
//!    ignored) by the normalised direct linear transform: both point sets are
//!    moved to zero mean and mean distance $\sqrt 2$, $A h = 0$ is solved for
//!    the unit $h$ of least $|A h|$, and the normalisation is undone.
//! 2. The image of the absolute conic $B = K^{-\mathsf T} K^{-1}$ from
//!    $h_1^{\mathsf T} B h_2 = 0$ and $h_1^{\mathsf T} B h_1 = h_2^{\mathsf T} B h_2$
//!    per view (three views or more: all five intrinsics; fewer: principal
//!    point at the frame centre and zero skew, solving for $1/f_x^2, 1/f_y^2$),
//!    then $K$ from $B$ in closed form.
//! 3. Each pose from $[r_1\ r_2\ t] = \lambda K^{-1} H$, $r_3 = r_1 \times r_2$,
//!    the rotation projected onto SO(3) by SVD.
//! 4. Levenberg-Marquardt on the reprojection residuals (pixels) with the
//!    analytic Jacobian of [`Camera::project_with_jacobians`]; any parameter
//!    can be held fixed.

use nalgebra::{DMatrix, Matrix3, Rotation3, SMatrix, SVector, Vector2, Vector3};
use needle_lsq::{EvaluationError, LevenbergMarquardt, Options, Parameter, Problem};
use serde::{Deserialize, Serialize};

use crate::camera::{DISTORTION_COUNT, INTRINSIC_COUNT, POSE_COUNT};
use crate::{Camera, Distortion, Intrinsics, Pose, VisionError};

/// The points of one view of a planar target: positions on the target plane
/// (m, the plane is $z = 0$) and where they were seen (px).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CalibrationView {
    /// Target-plane coordinates (m).
    pub target: Vec<Vector2<f64>>,
    /// Measured pixels, one per target point.
    pub image: Vec<Vector2<f64>>,
}

/// Which parameters calibration holds at their initial values.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FixedParameters {
    /// fx, fy, cx, cy, skew.
    pub intrinsics: [bool; INTRINSIC_COUNT],
    /// k1, k2, k3, p1, p2.
    pub distortion: [bool; DISTORTION_COUNT],
}

impl Default for FixedParameters {
    /// Everything free except the skew (zero for every modern sensor).
    fn default() -> FixedParameters {
        FixedParameters {
            intrinsics: [false, false, false, false, true],
            distortion: [false; DISTORTION_COUNT],
        }
    }
}

/// The result of a calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationFit {
    /// The refined camera.
    pub camera: Camera,
    /// Each view's target pose.
    pub poses: Vec<Pose>,
    /// Root-mean-square reprojection distance (px):
    /// $\sqrt{\sum_i |e_i|^2 / N}$ over all $N$ points.
    pub reprojection_rms: f64,
    /// Levenberg-Marquardt iterations.
    pub iterations: usize,
}

/// Points per view below which a homography is not determined with
/// redundancy (four give an exact fit and no check).
const MIN_POINTS_PER_VIEW: usize = 6;

fn calibration_error(message: String) -> VisionError {
    VisionError::Calibration(message)
}

/// Similarity moving points to zero mean and mean distance $\sqrt 2$.
fn normalisation(points: &[Vector2<f64>]) -> Matrix3<f64> {
    let n = points.len() as f64;
    let mean = points.iter().sum::<Vector2<f64>>() / n;
    let spread = points.iter().map(|p| (p - mean).norm()).sum::<f64>() / n;
    let s = if spread > 0.0 {
        std::f64::consts::SQRT_2 / spread
    } else {
        1.0
    };
    Matrix3::new(s, 0.0, -s * mean.x, 0.0, s, -s * mean.y, 0.0, 0.0, 1.0)
}

fn apply(h: &Matrix3<f64>, p: &Vector2<f64>) -> Vector2<f64> {
    let q = h * Vector3::new(p.x, p.y, 1.0);
    Vector2::new(q.x / q.z, q.y / q.z)
}

/// The homography from target-plane points to pixels by the normalised DLT.
pub fn homography(
    target: &[Vector2<f64>],
    image: &[Vector2<f64>],
) -> Result<Matrix3<f64>, VisionError> {
    if target.len() != image.len() || target.len() < 4 {
        return Err(calibration_error(format!(
            "a homography needs at least 4 point pairs, got {} target and {} image points",
            target.len(),
            image.len()
        )));
    }
    let (t_target, t_image) = (normalisation(target), normalisation(image));
    let mut normal = SMatrix::<f64, 9, 9>::zeros();
    for (x, u) in target.iter().zip(image) {
        let (x, u) = (apply(&t_target, x), apply(&t_image, u));
        let rows = [
            SVector::<f64, 9>::from_column_slice(&[
                -x.x,
                -x.y,
                -1.0,
                0.0,
                0.0,
                0.0,
                u.x * x.x,
                u.x * x.y,
                u.x,
            ]),
            SVector::<f64, 9>::from_column_slice(&[
                0.0,
                0.0,
                0.0,
                -x.x,
                -x.y,
                -1.0,
                u.y * x.x,
                u.y * x.y,
                u.y,
            ]),
        ];
        for row in &rows {
            normal += row * row.transpose();
        }
    }
    let eigen = normal.symmetric_eigen();
    let (smallest, _) =
        eigen
            .eigenvalues
            .iter()
            .enumerate()
            .fold(
                (0, f64::INFINITY),
                |best, (i, &v)| if v < best.1 { (i, v) } else { best },
            );
    // The second-smallest eigenvalue must stand clear of zero, or the points
    // are collinear and the homography is not determined.
    let mut sorted: Vec<f64> = eigen.eigenvalues.iter().copied().collect();
    sorted.sort_by(f64::total_cmp);
    if sorted[1] < 1e-10 * sorted[8] {
        return Err(calibration_error(
            "the target points are degenerate (collinear): no homography".into(),
        ));
    }
    let h = eigen.eigenvectors.column(smallest);
    let normalised = Matrix3::new(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8]);
    let inverse = t_image
        .try_inverse()
        .ok_or_else(|| calibration_error("image points coincide".into()))?;
    let full = inverse * normalised * t_target;
    Ok(full / full[(2, 2)])
}

/// Zhang's $v_{ij}$ row: $h_i^{\mathsf T} B h_j = v_{ij} \cdot b$.
fn conic_row(h: &Matrix3<f64>, i: usize, j: usize) -> SVector<f64, 6> {
    let (a, b) = (h.column(i), h.column(j));
    SVector::<f64, 6>::from_column_slice(&[
        a[0] * b[0],
        a[0] * b[1] + a[1] * b[0],
        a[1] * b[1],
        a[2] * b[0] + a[0] * b[2],
        a[2] * b[1] + a[1] * b[2],
        a[2] * b[2],
    ])
}

/// Intrinsics from three or more homographies (all five parameters).
fn intrinsics_general(homographies: &[Matrix3<f64>]) -> Option<Intrinsics> {
    let mut normal = SMatrix::<f64, 6, 6>::zeros();
    for h in homographies {
        for row in [conic_row(h, 0, 1), conic_row(h, 0, 0) - conic_row(h, 1, 1)] {
            normal += row * row.transpose();
        }
    }
    let eigen = normal.symmetric_eigen();
    let smallest = eigen.eigenvalues.imin();
    let mut b = eigen.eigenvectors.column(smallest).into_owned();
    if b[0] < 0.0 {
        b = -b;
    }
    let (b11, b12, b22, b13, b23, b33) = (b[0], b[1], b[2], b[3], b[4], b[5]);
    let denominator = b11 * b22 - b12 * b12;
    let v0 = (b12 * b13 - b11 * b23) / denominator;
    let lambda = b33 - (b13 * b13 + v0 * (b12 * b13 - b11 * b23)) / b11;
    let alpha2 = lambda / b11;
    let beta2 = lambda * b11 / denominator;
    if !(alpha2 > 0.0 && beta2 > 0.0 && denominator > 0.0) {
        return None;
    }
    let (alpha, beta) = (alpha2.sqrt(), beta2.sqrt());
    let gamma = -b12 * alpha2 * beta / lambda;
    let u0 = gamma * v0 / beta - b13 * alpha2 / lambda;
    let k = Intrinsics {
        fx: alpha,
        fy: beta,
        cx: u0,
        cy: v0,
        skew: gamma,
    };
    k.validate().ok().map(|_| k)
}

/// Focal lengths with the principal point at `centre` and zero skew.
fn intrinsics_centred(homographies: &[Matrix3<f64>], centre: Vector2<f64>) -> Option<Intrinsics> {
    let shift = Matrix3::new(1.0, 0.0, -centre.x, 0.0, 1.0, -centre.y, 0.0, 0.0, 1.0);
    let mut normal = nalgebra::Matrix2::<f64>::zeros();
    let mut rhs = Vector2::<f64>::zeros();
    for h in homographies {
        let h = shift * h;
        let rows = [
            (
                Vector2::new(h[(0, 0)] * h[(0, 1)], h[(1, 0)] * h[(1, 1)]),
                -h[(2, 0)] * h[(2, 1)],
            ),
            (
                Vector2::new(
                    h[(0, 0)].powi(2) - h[(0, 1)].powi(2),
                    h[(1, 0)].powi(2) - h[(1, 1)].powi(2),
                ),
                -(h[(2, 0)].powi(2) - h[(2, 1)].powi(2)),
            ),
        ];
        for (a, c) in rows {
            normal += a * a.transpose();
            rhs += a * c;
        }
    }
    let w = normal.try_inverse()? * rhs;
    (w.x > 0.0 && w.y > 0.0).then(|| Intrinsics {
        fx: 1.0 / w.x.sqrt(),
        fy: 1.0 / w.y.sqrt(),
        cx: centre.x,
        cy: centre.y,
        skew: 0.0,
    })
}

/// The target pose of a view from its homography and the intrinsics.
fn pose_from_homography(h: &Matrix3<f64>, k: &Intrinsics) -> Option<Pose> {
    let k_matrix = Matrix3::new(k.fx, k.skew, k.cx, 0.0, k.fy, k.cy, 0.0, 0.0, 1.0);
    let m = k_matrix.try_inverse()? * h;
    let mut lambda = 1.0 / m.column(0).norm();
    // The target is in front of the camera: t_z > 0.
    if m[(2, 2)] * lambda < 0.0 {
        lambda = -lambda;
    }
    let r1 = m.column(0) * lambda;
    let r2 = m.column(1) * lambda;
    let r3 = r1.cross(&r2);
    let t = m.column(2) * lambda;
    let approximate = Matrix3::from_columns(&[r1, r2, r3]);
    let svd = approximate.svd(true, true);
    let mut rotation = svd.u? * svd.v_t?;
    if rotation.determinant() < 0.0 {
        rotation = -rotation;
    }
    Some(Pose::from_rotation_translation(
        &Rotation3::from_matrix_unchecked(rotation),
        t.into_owned(),
    ))
}

fn validate_views(views: &[CalibrationView]) -> Result<usize, VisionError> {
    if views.is_empty() {
        return Err(calibration_error("no view given".into()));
    }
    let mut total = 0;
    for (i, view) in views.iter().enumerate() {
        if view.target.len() != view.image.len() {
            return Err(calibration_error(format!(
                "view {i}: {} target points but {} image points",
                view.target.len(),
                view.image.len()
            )));
        }
        if view.target.len() < MIN_POINTS_PER_VIEW {
            return Err(calibration_error(format!(
                "view {i}: {} points, at least {MIN_POINTS_PER_VIEW} are needed",
                view.target.len()
            )));
        }
        if let Some(j) = view
            .target
            .iter()
            .chain(&view.image)
            .position(|p| !(p.x.is_finite() && p.y.is_finite()))
        {
            return Err(calibration_error(format!(
                "view {i}: point {j} is not finite"
            )));
        }
        total += view.target.len();
    }
    Ok(total)
}

/// Zhang's closed-form initialisation: intrinsics (distortion zero) and the
/// pose of every view.
pub fn initialise(
    views: &[CalibrationView],
    width: u32,
    height: u32,
) -> Result<(Camera, Vec<Pose>), VisionError> {
    validate_views(views)?;
    let homographies = views
        .iter()
        .map(|v| homography(&v.target, &v.image))
        .collect::<Result<Vec<_>, _>>()?;
    let centre = Vector2::new((width as f64 - 1.0) / 2.0, (height as f64 - 1.0) / 2.0);
    let general = if homographies.len() >= 3 {
        intrinsics_general(&homographies)
    } else {
        None
    };
    let intrinsics = general
        .filter(|k| k.skew.abs() < 0.1 * k.fx)
        .or_else(|| intrinsics_centred(&homographies, centre))
        .ok_or_else(|| {
            calibration_error("the focal length is not observable: the views are (nearly) fronto-parallel; tilt the target".into())
        })?;
    let poses = homographies
        .iter()
        .enumerate()
        .map(|(i, h)| {
            pose_from_homography(h, &intrinsics)
                .ok_or_else(|| calibration_error(format!("view {i}: no pose from its homography")))
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok((
        Camera {
            intrinsics,
            distortion: Distortion::NONE,
        },
        poses,
    ))
}

struct Reprojection<'a> {
    views: &'a [CalibrationView],
    points: usize,
}

const CAMERA_COUNT: usize = INTRINSIC_COUNT + DISTORTION_COUNT;

fn unpack(params: &[f64], view: usize) -> (Camera, Pose) {
    let camera = Camera {
        intrinsics: Intrinsics {
            fx: params[0],
            fy: params[1],
            cx: params[2],
            cy: params[3],
            skew: params[4],
        },
        distortion: Distortion {
            k1: params[5],
            k2: params[6],
            k3: params[7],
            p1: params[8],
            p2: params[9],
        },
    };
    let p = &params[CAMERA_COUNT + POSE_COUNT * view..][..POSE_COUNT];
    (
        camera,
        Pose {
            rotation: [p[0], p[1], p[2]],
            translation: [p[3], p[4], p[5]],
        },
    )
}

impl Problem for Reprojection<'_> {
    fn num_parameters(&self) -> usize {
        CAMERA_COUNT + POSE_COUNT * self.views.len()
    }

    fn num_residuals(&self) -> usize {
        2 * self.points
    }

    fn residuals(&self, params: &[f64], out: &mut [f64]) -> Result<(), EvaluationError> {
        let mut row = 0;
        for (v, view) in self.views.iter().enumerate() {
            let (camera, pose) = unpack(params, v);
            for (x, u) in view.target.iter().zip(&view.image) {
                let p = camera.project(&pose, &Vector3::new(x.x, x.y, 0.0))?;
                out[row] = p.x - u.x;
                out[row + 1] = p.y - u.y;
                row += 2;
            }
        }
        Ok(())
    }

    fn jacobian(
        &self,
        params: &[f64],
        out: &mut DMatrix<f64>,
    ) -> Option<Result<(), EvaluationError>> {
        let mut row = 0;
        for (v, view) in self.views.iter().enumerate() {
            let (camera, pose) = unpack(params, v);
            for x in &view.target {
                let j = match camera.project_with_jacobians(&pose, &Vector3::new(x.x, x.y, 0.0)) {
                    Ok(j) => j,
                    Err(e) => return Some(Err(e.into())),
                };
                out.view_mut((row, 0), (2, INTRINSIC_COUNT))
                    .copy_from(&j.intrinsics);
                out.view_mut((row, INTRINSIC_COUNT), (2, DISTORTION_COUNT))
                    .copy_from(&j.distortion);
                out.view_mut((row, CAMERA_COUNT + POSE_COUNT * v), (2, POSE_COUNT))
                    .copy_from(&j.pose);
                row += 2;
            }
        }
        Some(Ok(()))
    }
}

/// Calibrate from the views of a planar target: [`initialise`], then
/// Levenberg-Marquardt on the reprojection error with `fixed` parameters
/// held at their initial values (zero for the distortion and the skew).
pub fn calibrate(
    views: &[CalibrationView],
    width: u32,
    height: u32,
    fixed: &FixedParameters,
) -> Result<CalibrationFit, VisionError> {
    let (mut camera, poses) = initialise(views, width, height)?;
    if fixed.intrinsics[4] {
        // A held skew is held at zero, not at the closed form's estimate.
        camera.intrinsics.skew = 0.0;
    }
    refine(views, &camera, &poses, fixed)
}

/// Levenberg-Marquardt refinement of a camera and view poses.
pub fn refine(
    views: &[CalibrationView],
    camera: &Camera,
    poses: &[Pose],
    fixed: &FixedParameters,
) -> Result<CalibrationFit, VisionError> {
    let points = validate_views(views)?;
    if poses.len() != views.len() {
        return Err(calibration_error(format!(
            "{} poses for {} views",
            poses.len(),
            views.len()
        )));
    }
    let free_count = fixed
        .intrinsics
        .iter()
        .chain(&fixed.distortion)
        .filter(|f| !**f)
        .count()
        + POSE_COUNT * views.len();
    if 2 * points <= free_count {
        return Err(calibration_error(format!(
            "{points} points give {} residuals for {free_count} free parameters",
            2 * points
        )));
    }
    let k = &camera.intrinsics;
    let d = &camera.distortion;
    let names = ["fx", "fy", "cx", "cy", "skew", "k1", "k2", "k3", "p1", "p2"];
    let values = [k.fx, k.fy, k.cx, k.cy, k.skew, d.k1, d.k2, d.k3, d.p1, d.p2];
    let fixed_flags: Vec<bool> = fixed
        .intrinsics
        .iter()
        .chain(&fixed.distortion)
        .copied()
        .collect();
    let mut parameters: Vec<Parameter> = names
        .iter()
        .zip(values)
        .zip(&fixed_flags)
        .map(|((name, value), &is_fixed)| {
            let p = Parameter::new(*name, value).with_scale(
                if name.starts_with('f') || name.starts_with('c') {
                    k.fx.max(1.0)
                } else {
                    1.0
                },
            );
            if is_fixed { p.fix() } else { p }
        })
        .collect();
    for (v, pose) in poses.iter().enumerate() {
        for (i, value) in pose.rotation.iter().chain(&pose.translation).enumerate() {
            parameters.push(Parameter::new(
                format!("view{v}.{}", ["wx", "wy", "wz", "tx", "ty", "tz"][i]),
                *value,
            ));
        }
    }
    let problem = Reprojection { views, points };
    let report = LevenbergMarquardt::new(Options::default())
        .minimize(&problem, &parameters)
        .map_err(|e| calibration_error(format!("refinement failed: {e}")))?;
    if !report.termination.is_converged() {
        return Err(calibration_error(format!(
            "refinement did not converge: {:?}",
            report.termination
        )));
    }
    let params: Vec<f64> = report.params.iter().copied().collect();
    let (camera, _) = unpack(&params, 0);
    let poses = (0..views.len()).map(|v| unpack(&params, v).1).collect();
    Ok(CalibrationFit {
        camera,
        poses,
        reprojection_rms: (2.0 * report.cost / points as f64).sqrt(),
        iterations: report.iterations,
    })
}
