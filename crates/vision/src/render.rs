//! Rendering synthetic camera frames of the painted marker pattern.
//!
//! Each marker is a dark disc of diameter `dot_diameter` lying in the plane
//! parallel to the top face through the marker's 3-D position. Its image is
//! the exact projection of that disc through the camera model (perspective
//! and distortion), so the image of a disc is not an ellipse centred on the
//! projected centre; this is the perspective bias that calibration corrects.
//!
//! Anti-aliasing is by analytic area coverage ([`coverage`]): at a pixel
//! centre the plane point seen there is found by Newton's method on the
//! forward projection, giving the signed distance to the disc's rim and its
//! gradient; the pixel's covered fraction is the exact area of the unit
//! square on the inner side of the rim's tangent line there, less the sliver
//! between the tangent and the curved rim (second order in the rim's
//! curvature), so a disc's rendered area is exact to a few thousandths of a
//! pixel. Only pixels the rim can cross are solved; the others are wholly
//! inside or outside, which a Lipschitz bound on the distance to the rim
//! proves ([`dot`]).
//!
//! The frame is then
//! $I(u,v) = g(u,v)\,\big(b - c\,(G_\sigma * D)(u,v)\big) + \text{noise}$,
//! with $D$ the coverage, $G_\sigma$ the defocus blur, $b$ the background,
//! $c$ the contrast and $g$ a linear illumination gradient; shot noise is
//! Poisson in photo-electrons, read noise Gaussian in grey levels, and the
//! result is rounded to the bit depth. Only patches around the dots are
//! rendered, in parallel; noise is drawn per row from a ChaCha stream keyed
//! by `(seed, row)`, so a frame is reproducible whatever the thread count.

mod blur;
mod coverage;
mod dot;

use nalgebra::Vector3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal, Poisson};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::frame::quantise;
use crate::{BitDepth, Camera, GreyFrame, Intrinsics, Pose, VisionError};
use dot::{Patch, render_dot};

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

/// Blurred dot coverage of the whole frame, in $[0, 1]$.
fn render_darkness(
    camera: &Camera,
    pose: &Pose,
    markers: &[Vector3<f64>],
    options: &RenderOptions,
    solve_every_pixel: bool,
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
    let kernel = blur::gaussian_kernel(options.blur_sigma);
    let patches: Vec<Option<Patch>> = markers
        .par_iter()
        .map(|m| render_dot(camera, pose, m, options, &kernel, solve_every_pixel))
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
    let darkness = render_darkness(camera, pose, markers, options, false)?;
    let (w, h) = (options.width, options.height);
    let mut frame = GreyFrame::filled(w, h, options.bit_depth, 0.0);
    // The gain is 1 + (column term) + (row term); the column terms are the
    // same on every row.
    let (hw, hh) = (0.5 * w as f64, 0.5 * h as f64);
    let column_terms: Vec<f64> = (0..w)
        .map(|column| options.illumination_gradient[0] * (column as f64 - hw) / hw)
        .collect();
    frame
        .pixels
        .par_chunks_mut(w)
        .zip(darkness.par_chunks(w))
        .enumerate()
        .for_each(|(row, (pixels, dark))| {
            let row_term = options.illumination_gradient[1] * (row as f64 - hh) / hh;
            for ((value, &d), column_term) in pixels.iter_mut().zip(dark).zip(&column_terms) {
                let gain = 1.0 + column_term + row_term;
                *value = (gain * (options.background - options.contrast * d as f64)) as f32;
            }
        });
    Ok(frame)
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
                *value = quantise(level as f32, max);
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

#[cfg(test)]
mod tests;
