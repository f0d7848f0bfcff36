//! Rendering synthetic camera frames of the painted marker pattern.
//!
//! Each marker is a dark disc of diameter `dot_diameter` lying in the plane
//! parallel to the top face through the marker's 3-D position. Its image is
//! the exact projection of that disc through the camera model (perspective
//! and distortion), so the image of a disc is not an ellipse centred on the
//! projected centre; this is the perspective bias that calibration corrects.
//!
//! Anti-aliasing is by analytic area coverage: at every pixel centre the
//! plane point seen there is found by Newton's method on the forward
//! projection, giving the signed distance to the disc's rim and its gradient;
//! the pixel's covered fraction is the exact area of the unit square on the
//! inner side of the rim's tangent line there, less the sliver between the
//! tangent and the curved rim (second order in the rim's curvature), so a
//! disc's rendered area is exact to a few thousandths of a pixel.
//!
//! The frame is then
//! $I(u,v) = g(u,v)\,\big(b - c\,(G_\sigma * D)(u,v)\big) + \text{noise}$,
//! with $D$ the coverage, $G_\sigma$ the defocus blur, $b$ the background,
//! $c$ the contrast and $g$ a linear illumination gradient; shot noise is
//! Poisson in photo-electrons, read noise Gaussian in grey levels, and the
//! result is rounded to the bit depth. Only patches around the dots are
//! rendered, in parallel; noise is drawn per row from a ChaCha stream keyed
//! by `(seed, row)`, so a frame is reproducible whatever the thread count.

use nalgebra::{Matrix2, Vector2, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal, Poisson};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::{BitDepth, Camera, GreyFrame, Intrinsics, Pose, VisionError};

/// How to render a frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RenderOptions {
    /// Frame width (px).
    pub width: usize,
    /// Frame height (px).
    pub height: usize,
    /// Diameter of a painted dot (m).
    pub dot_diameter: f64,
    /// Grey level of the bright background.
    pub background: f64,
    /// Background minus dot grey level.
    pub contrast: f64,
    /// Defocus blur, Gaussian standard deviation (px); zero for none.
    pub blur_sigma: f64,
    /// Relative brightness change from the frame centre to the right edge
    /// (first) and to the bottom edge (second).
    pub illumination_gradient: [f64; 2],
    /// Gaussian read noise, standard deviation in grey levels.
    pub read_noise_sigma: f64,
    /// Photo-electrons per grey level for Poisson shot noise; `None` for no
    /// shot noise.
    pub electrons_per_grey: Option<f64>,
    /// Bit depth of the output.
    pub bit_depth: BitDepth,
}

impl RenderOptions {
    /// The paper's camera (2056 x 1544, 8 bit) and 2 mm dots at contrast 180,
    /// blur 1 px, read noise 2 grey levels, no shot noise, no gradient.
    pub fn paper() -> RenderOptions {
        RenderOptions {
            width: 2056,
            height: 1544,
            dot_diameter: 0.002,
            background: 220.0,
            contrast: 180.0,
            blur_sigma: 1.0,
            illumination_gradient: [0.0, 0.0],
            read_noise_sigma: 2.0,
            electrons_per_grey: None,
            bit_depth: BitDepth::Eight,
        }
    }

    fn validate(&self) -> Result<(), VisionError> {
        let bad = |field: &'static str, reason: String| {
            Err(VisionError::InvalidParameter { field, reason })
        };
        if self.width == 0 || self.height == 0 {
            return bad(
                "width/height",
                format!("{} x {} is empty", self.width, self.height),
            );
        }
        if !(self.dot_diameter > 0.0 && self.dot_diameter.is_finite()) {
            return bad(
                "dot_diameter",
                format!("{} must be positive", self.dot_diameter),
            );
        }
        if !(self.blur_sigma >= 0.0 && self.blur_sigma.is_finite()) {
            return bad(
                "blur_sigma",
                format!("{} must be non-negative", self.blur_sigma),
            );
        }
        if !(self.read_noise_sigma >= 0.0 && self.read_noise_sigma.is_finite()) {
            return bad(
                "read_noise_sigma",
                format!("{} must be non-negative", self.read_noise_sigma),
            );
        }
        if let Some(e) = self.electrons_per_grey
            && !(e > 0.0 && e.is_finite())
        {
            return bad("electrons_per_grey", format!("{e} must be positive"));
        }
        if !(self.background.is_finite() && self.contrast.is_finite())
            || self.illumination_gradient.iter().any(|g| !g.is_finite())
        {
            return bad(
                "background/contrast/illumination_gradient",
                "must be finite".into(),
            );
        }
        Ok(())
    }
}

/// Rendered darkness (blurred dot coverage) of one dot, on a rectangle of
/// pixels.
struct Patch {
    column: usize,
    row: usize,
    width: usize,
    height: usize,
    values: Vec<f32>,
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

/// Pixel and $\partial p / \partial q$ of the in-plane point $q$ at height
/// `z` in the face frame.
fn project_in_plane(
    camera: &Camera,
    rotation: &nalgebra::Rotation3<f64>,
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

/// Normalised, truncated (at 5 sigma) sampled Gaussian kernel.
fn gaussian_kernel(sigma: f64) -> Vec<f64> {
    if sigma <= 0.0 {
        return vec![1.0];
    }
    let half = (5.0 * sigma).ceil() as i64;
    let weights: Vec<f64> = (-half..=half)
        .map(|i| (-0.5 * (i as f64 / sigma).powi(2)).exp())
        .collect();
    let total: f64 = weights.iter().sum();
    weights.into_iter().map(|w| w / total).collect()
}

/// Separable convolution of a row-major rectangle with zero outside it.
fn blur(values: &[f64], width: usize, height: usize, kernel: &[f64]) -> Vec<f64> {
    let half = (kernel.len() / 2) as i64;
    let mut rows = vec![0.0; values.len()];
    for r in 0..height {
        for c in 0..width {
            let mut sum = 0.0;
            for (k, w) in kernel.iter().enumerate() {
                let cc = c as i64 + k as i64 - half;
                if cc >= 0 && (cc as usize) < width {
                    sum += w * values[r * width + cc as usize];
                }
            }
            rows[r * width + c] = sum;
        }
    }
    let mut out = vec![0.0; values.len()];
    for r in 0..height {
        for c in 0..width {
            let mut sum = 0.0;
            for (k, w) in kernel.iter().enumerate() {
                let rr = r as i64 + k as i64 - half;
                if rr >= 0 && (rr as usize) < height {
                    sum += w * rows[rr as usize * width + c];
                }
            }
            out[r * width + c] = sum;
        }
    }
    out
}

/// Render one dot's blurred coverage; `None` if it is entirely outside the
/// frame.
fn render_dot(
    camera: &Camera,
    pose: &Pose,
    centre: &Vector3<f64>,
    options: &RenderOptions,
    kernel: &[f64],
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
    // Bounding box of the rim, from points on a slightly larger circle.
    let (mut lo, mut hi) = (
        Vector2::repeat(f64::INFINITY),
        Vector2::repeat(f64::NEG_INFINITY),
    );
    for i in 0..64 {
        let angle = i as f64 * std::f64::consts::TAU / 64.0;
        let q = Vector2::new(centre.x, centre.y)
            + 1.1 * radius * Vector2::new(angle.cos(), angle.sin());
        let (p, _) = project(q)?;
        lo = lo.inf(&p);
        hi = hi.sup(&p);
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
    let (width, height) = (c1 - c0 + 1, r1 - r0 + 1);
    let centre_q = Vector2::new(centre.x, centre.y);
    let mut coverage = vec![0.0; width * height];
    for r in 0..height {
        let mut q = centre_q;
        let mut seeded = false;
        for c in 0..width {
            let target = Vector2::new((c0 + c) as f64, (r0 + r) as f64);
            if !seeded {
                // Start the row from the affine map about the centre.
                let (p, j) = project(centre_q)?;
                q = centre_q
                    + j.try_inverse().ok_or(VisionError::InvalidParameter {
                        field: "pose",
                        reason: "the face plane is seen edge-on".into(),
                    })? * (target - p);
                seeded = true;
            }
            let mut jacobian = Matrix2::identity();
            let mut converged = false;
            for _ in 0..30 {
                let (p, j) = project(q)?;
                jacobian = j;
                let error = target - p;
                let Some(inverse) = j.try_inverse() else {
                    break;
                };
                q += inverse * error;
                if error.norm() < 1e-9 {
                    converged = true;
                    break;
                }
            }
            if !converged {
                return Err(VisionError::InvalidParameter {
                    field: "markers",
                    reason: format!(
                        "pixel ({}, {}) near the dot at {centre:?} does not map back onto its plane",
                        c0 + c,
                        r0 + r
                    ),
                });
            }
            let offset = q - centre_q;
            let distance = offset.norm();
            if distance == 0.0 {
                coverage[r * width + c] = 1.0;
                continue;
            }
            // Signed distance to the rim in pixels and the rim's normal.
            let inverse_jacobian = jacobian.try_inverse().unwrap_or_else(Matrix2::zeros);
            let gradient = inverse_jacobian.transpose() * (offset / distance);
            let scale = gradient.norm();
            if scale == 0.0 {
                continue;
            }
            let signed = (distance - radius) / scale;
            let normal = gradient / scale;
            // Rim curvature (1/px) of the level set |J^-1 (p - p_m)| = r.
            let tangent = Vector2::new(-normal.y, normal.x);
            let curvature = (inverse_jacobian * tangent).norm_squared() / (distance * scale);
            coverage[r * width + c] = (half_plane_coverage(normal, -signed)
                - curvature_correction(normal, -signed, curvature))
            .clamp(0.0, 1.0);
        }
    }
    let blurred = if kernel.len() > 1 {
        blur(&coverage, width, height, kernel)
    } else {
        coverage
    };
    Ok(Some(Patch {
        column: c0,
        row: r0,
        width,
        height,
        values: blurred.into_iter().map(|v| v as f32).collect(),
    }))
}

/// Blurred dot coverage of the whole frame, in $[0, 1]$.
fn render_darkness(
    camera: &Camera,
    pose: &Pose,
    markers: &[Vector3<f64>],
    options: &RenderOptions,
) -> Result<Vec<f32>, VisionError> {
    camera.validate()?;
    pose.validate()?;
    options.validate()?;
    if let Some((i, m)) = markers
        .iter()
        .enumerate()
        .find(|(_, m)| !(m.x.is_finite() && m.y.is_finite() && m.z.is_finite()))
    {
        return Err(VisionError::InvalidParameter {
            field: "markers",
            reason: format!("marker {i} at {m:?} is not finite"),
        });
    }
    let kernel = gaussian_kernel(options.blur_sigma);
    let patches: Vec<Option<Patch>> = markers
        .par_iter()
        .map(|m| render_dot(camera, pose, m, options, &kernel))
        .collect::<Result<_, _>>()?;
    let mut darkness = vec![0.0f32; options.width * options.height];
    for patch in patches.into_iter().flatten() {
        for r in 0..patch.height {
            let row = (patch.row + r) * options.width + patch.column;
            for c in 0..patch.width {
                let v = &mut darkness[row + c];
                *v = (*v + patch.values[r * patch.width + c]).min(1.0);
            }
        }
    }
    Ok(darkness)
}

/// The noise-free frame, in unrounded grey levels.
pub fn render_ideal(
    camera: &Camera,
    pose: &Pose,
    markers: &[Vector3<f64>],
    options: &RenderOptions,
) -> Result<GreyFrame, VisionError> {
    let darkness = render_darkness(camera, pose, markers, options)?;
    let (w, h) = (options.width, options.height);
    let mut frame = GreyFrame::filled(w, h, options.bit_depth, 0.0);
    frame
        .pixels
        .par_chunks_mut(w)
        .enumerate()
        .for_each(|(row, pixels)| {
            for (column, value) in pixels.iter_mut().enumerate() {
                let gain = illumination(options, column, row);
                *value = (gain
                    * (options.background - options.contrast * darkness[row * w + column] as f64))
                    as f32;
            }
        });
    Ok(frame)
}

fn illumination(options: &RenderOptions, column: usize, row: usize) -> f64 {
    let (hw, hh) = (0.5 * options.width as f64, 0.5 * options.height as f64);
    1.0 + options.illumination_gradient[0] * (column as f64 - hw) / hw
        + options.illumination_gradient[1] * (row as f64 - hh) / hh
}

/// Add shot and read noise to a noise-free frame and round to its bit depth,
/// deterministically for a given `seed`.
pub fn add_noise(
    frame: &mut GreyFrame,
    options: &RenderOptions,
    seed: u64,
) -> Result<(), VisionError> {
    options.validate()?;
    let read =
        Normal::new(0.0, options.read_noise_sigma).map_err(|e| VisionError::InvalidParameter {
            field: "read_noise_sigma",
            reason: e.to_string(),
        })?;
    let max = frame.bit_depth.max_level();
    let width = frame.width;
    frame
        .pixels
        .par_chunks_mut(width)
        .enumerate()
        .for_each(|(row, pixels)| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            rng.set_stream(row as u64);
            for value in pixels.iter_mut() {
                let mut level = *value as f64;
                if let Some(gain) = options.electrons_per_grey {
                    let electrons = (level * gain).max(0.0);
                    if electrons > 0.0 {
                        // Poisson::new only fails for a non-positive or non-finite rate.
                        if let Ok(poisson) = Poisson::new(electrons) {
                            level = poisson.sample(&mut rng) / gain;
                        }
                    }
                }
                if options.read_noise_sigma > 0.0 {
                    level += read.sample(&mut rng);
                }
                *value = (level as f32).round().clamp(0.0, max);
            }
        });
    Ok(())
}

/// Render a frame: [`render_ideal`] then [`add_noise`].
pub fn render_frame(
    camera: &Camera,
    pose: &Pose,
    markers: &[Vector3<f64>],
    options: &RenderOptions,
    seed: u64,
) -> Result<GreyFrame, VisionError> {
    let mut frame = render_ideal(camera, pose, markers, options)?;
    add_noise(&mut frame, options, seed)?;
    Ok(frame)
}

/// A fronto-parallel unit camera: face-frame metres are pixels, so a dot of
/// diameter `d` "metres" at `(x, y, 0)` renders as a `d`-pixel disc centred on
/// pixel `(x, y)`. Used for synthetic templates.
pub fn pixel_space_view() -> (Camera, Pose) {
    (
        Camera {
            intrinsics: Intrinsics {
                fx: 1.0,
                fy: 1.0,
                cx: 0.0,
                cy: 0.0,
                skew: 0.0,
            },
            distortion: crate::Distortion::NONE,
        },
        Pose {
            rotation: [0.0; 3],
            translation: [0.0, 0.0, 1.0],
        },
    )
}
