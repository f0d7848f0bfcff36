//! Finding a dot-grid calibration target in an image, and correcting the
//! perspective bias of dot centres.
//!
//! Detection: Otsu's threshold splits dark dots from the bright ground; the
//! 4-connected dark components of typical area are the candidate dots; each
//! centre is the darkness-weighted centroid over the dot's box widened by
//! the blur (darkness = local background, the median of the box's rim,
//! minus the grey level), which is the centroid of the dot's image area.
//! Ordering: the four extreme dots (least and greatest $u+v$ and $u-v$) are
//! the grid's corners; the homography they define predicts every node,
//! each node takes the nearest dot, and the homography is refitted on all
//! nodes and the matching repeated.
//!
//! The centroid of a disc's image is not the image of the disc's centre
//! (perspective makes the near half larger). [`circle_centre_bias`] computes
//! that offset for the current camera estimate, so that calibration can
//! subtract it and recalibrate ([`calibrate_dot_grid`]).

use nalgebra::{Vector2, Vector3};

use crate::{
    CalibrationFit, CalibrationView, Camera, FixedParameters, GreyFrame, Pose, VisionError,
    calibrate, homography, refine,
};

/// A planar dot-grid target: `columns` x `rows` dots of `dot_diameter` at
/// `pitch`, node `(i, j)` at `(i pitch, j pitch)` on the target plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DotGrid {
    /// Dots per row.
    pub columns: usize,
    /// Rows of dots.
    pub rows: usize,
    /// Centre-to-centre distance (m).
    pub pitch: f64,
    /// Dot diameter (m).
    pub dot_diameter: f64,
}

impl DotGrid {
    /// Target-plane coordinates of the nodes, row-major.
    pub fn nodes(&self) -> Vec<Vector2<f64>> {
        (0..self.rows)
            .flat_map(|j| {
                (0..self.columns)
                    .map(move |i| Vector2::new(i as f64 * self.pitch, j as f64 * self.pitch))
            })
            .collect()
    }
}

fn otsu_threshold(frame: &GreyFrame) -> f32 {
    let (lo, hi) = frame
        .pixels
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &p| {
            (a.min(p), b.max(p))
        });
    let bins = 256;
    let width = ((hi - lo) / bins as f32).max(f32::MIN_POSITIVE);
    let mut histogram = vec![0.0f64; bins];
    for &p in &frame.pixels {
        histogram[(((p - lo) / width) as usize).min(bins - 1)] += 1.0;
    }
    let total: f64 = histogram.iter().sum();
    let weighted: f64 = histogram
        .iter()
        .enumerate()
        .map(|(i, h)| i as f64 * h)
        .sum();
    let (mut below, mut below_weighted, mut best, mut threshold) = (0.0, 0.0, -1.0, 0);
    for (i, h) in histogram.iter().enumerate() {
        below += h;
        below_weighted += i as f64 * h;
        let above = total - below;
        if below == 0.0 || above == 0.0 {
            continue;
        }
        let difference = below_weighted / below - (weighted - below_weighted) / above;
        let between = below * above * difference * difference;
        if between > best {
            best = between;
            threshold = i;
        }
    }
    lo + (threshold as f32 + 1.0) * width
}

struct Blob {
    area: usize,
    min: (usize, usize),
    max: (usize, usize),
}

fn dark_blobs(frame: &GreyFrame, threshold: f32) -> Vec<Blob> {
    let (w, h) = (frame.width, frame.height);
    let mut seen = vec![false; w * h];
    let mut blobs = Vec::new();
    let mut stack = Vec::new();
    for start in 0..w * h {
        if seen[start] || frame.pixels[start] >= threshold {
            continue;
        }
        seen[start] = true;
        stack.push(start);
        let mut blob = Blob {
            area: 0,
            min: (usize::MAX, usize::MAX),
            max: (0, 0),
        };
        while let Some(i) = stack.pop() {
            let (x, y) = (i % w, i / w);
            blob.area += 1;
            blob.min = (blob.min.0.min(x), blob.min.1.min(y));
            blob.max = (blob.max.0.max(x), blob.max.1.max(y));
            let mut visit = |j: usize| {
                if !seen[j] && frame.pixels[j] < threshold {
                    seen[j] = true;
                    stack.push(j);
                }
            };
            if x > 0 {
                visit(i - 1);
            }
            if x + 1 < w {
                visit(i + 1);
            }
            if y > 0 {
                visit(i - w);
            }
            if y + 1 < h {
                visit(i + w);
            }
        }
        blobs.push(blob);
    }
    blobs
}

/// Darkness-weighted centroid over the blob's box widened by `margin`.
fn centroid(frame: &GreyFrame, blob: &Blob, margin: usize) -> Option<Vector2<f64>> {
    let (x0, y0) = (
        blob.min.0.checked_sub(margin)?,
        blob.min.1.checked_sub(margin)?,
    );
    let (x1, y1) = (blob.max.0 + margin, blob.max.1 + margin);
    if x1 >= frame.width || y1 >= frame.height {
        return None;
    }
    let mut rim: Vec<f32> = Vec::new();
    for x in x0..=x1 {
        rim.push(frame.at(x, y0));
        rim.push(frame.at(x, y1));
    }
    for y in y0..=y1 {
        rim.push(frame.at(x0, y));
        rim.push(frame.at(x1, y));
    }
    rim.sort_by(f32::total_cmp);
    let background = rim[rim.len() / 2] as f64;
    let (mut sum, mut sx, mut sy) = (0.0, 0.0, 0.0);
    for y in y0..=y1 {
        for x in x0..=x1 {
            let darkness = (background - frame.at(x, y) as f64).max(0.0);
            sum += darkness;
            sx += darkness * x as f64;
            sy += darkness * y as f64;
        }
    }
    (sum > 0.0).then(|| Vector2::new(sx / sum, sy / sum))
}

/// Find the dots of `grid` in a frame; the result is one image point per
/// node, row-major, ready to pair with [`DotGrid::nodes`].
pub fn detect_dot_grid(
    frame: &GreyFrame,
    grid: &DotGrid,
    blur_margin: usize,
) -> Result<Vec<Vector2<f64>>, VisionError> {
    let needed = grid.columns * grid.rows;
    if grid.columns < 2 || grid.rows < 2 {
        return Err(VisionError::DotGrid(format!(
            "a {} x {} grid has no extent",
            grid.columns, grid.rows
        )));
    }
    let blobs = dark_blobs(frame, otsu_threshold(frame));
    let mut areas: Vec<usize> = blobs.iter().map(|b| b.area).filter(|&a| a >= 4).collect();
    if areas.len() < needed {
        return Err(VisionError::DotGrid(format!(
            "{} dark blobs found, the grid has {needed} dots",
            areas.len()
        )));
    }
    areas.sort_unstable();
    // The grid's dots are the bulk of the blobs: their median area is typical.
    let typical = areas[areas.len() - needed / 2 - 1] as f64;
    let centres: Vec<Vector2<f64>> = blobs
        .iter()
        .filter(|b| (b.area as f64) > 0.3 * typical && (b.area as f64) < 3.0 * typical)
        .filter_map(|b| centroid(frame, b, blur_margin))
        .collect();
    if centres.len() < needed {
        return Err(VisionError::DotGrid(format!(
            "{} dots of typical size found inside the frame, the grid has {needed}",
            centres.len()
        )));
    }
    let extreme = |key: &dyn Fn(&Vector2<f64>) -> f64| {
        *centres
            .iter()
            .min_by(|a, b| key(a).total_cmp(&key(b)))
            .unwrap_or(&centres[0])
    };
    let corners_image = [
        extreme(&|p| p.x + p.y),
        extreme(&|p| -(p.x - p.y)),
        extreme(&|p| p.x - p.y),
        extreme(&|p| -(p.x + p.y)),
    ];
    let (c, r) = ((grid.columns - 1) as f64, (grid.rows - 1) as f64);
    let corners_grid = [
        Vector2::new(0.0, 0.0),
        Vector2::new(c, 0.0),
        Vector2::new(0.0, r),
        Vector2::new(c, r),
    ];
    let nodes: Vec<Vector2<f64>> = (0..grid.rows)
        .flat_map(|j| (0..grid.columns).map(move |i| Vector2::new(i as f64, j as f64)))
        .collect();
    let mut h = homography(&corners_grid, &corners_image)?;
    let mut matched = Vec::new();
    for _ in 0..3 {
        matched.clear();
        for node in &nodes {
            let q = h * Vector3::new(node.x, node.y, 1.0);
            let predicted = Vector2::new(q.x / q.z, q.y / q.z);
            // Half the local pitch: the distance to the next node's prediction.
            let q1 = h * Vector3::new(node.x + 1.0, node.y, 1.0);
            let pitch = (Vector2::new(q1.x / q1.z, q1.y / q1.z) - predicted).norm();
            let nearest = centres
                .iter()
                .min_by(|a, b| (*a - predicted).norm().total_cmp(&(*b - predicted).norm()));
            match nearest {
                Some(p) if (p - predicted).norm() < 0.4 * pitch => matched.push(*p),
                _ => {
                    return Err(VisionError::DotGrid(format!(
                        "no dot near grid node ({}, {}) predicted at ({:.1}, {:.1}) px",
                        node.x, node.y, predicted.x, predicted.y
                    )));
                }
            }
        }
        h = homography(&nodes, &matched)?;
    }
    Ok(matched)
}

/// Offset from the image of a disc's centre to the centroid of the disc's
/// image (px), for a disc of `diameter` at `centre` on the target plane.
/// The area centroid of the projected rim polygon (256 vertices) is
/// $\bar p = \frac{1}{6A}\sum_k (p_k + p_{k+1})(p_k \times p_{k+1})$.
pub fn circle_centre_bias(
    camera: &Camera,
    pose: &Pose,
    centre: Vector2<f64>,
    diameter: f64,
) -> Result<Vector2<f64>, VisionError> {
    let vertices = 256;
    let radius = 0.5 * diameter;
    let rim: Vec<Vector2<f64>> = (0..vertices)
        .map(|k| {
            let angle = k as f64 * std::f64::consts::TAU / vertices as f64;
            camera.project(
                pose,
                &Vector3::new(
                    centre.x + radius * angle.cos(),
                    centre.y + radius * angle.sin(),
                    0.0,
                ),
            )
        })
        .collect::<Result<_, _>>()?;
    let image_centre = camera.project(pose, &Vector3::new(centre.x, centre.y, 0.0))?;
    let (mut area, mut weighted) = (0.0, Vector2::zeros());
    for k in 0..vertices {
        let (a, b) = (
            rim[k] - image_centre,
            rim[(k + 1) % vertices] - image_centre,
        );
        let cross = a.x * b.y - a.y * b.x;
        area += 0.5 * cross;
        weighted += (a + b) * cross;
    }
    Ok(weighted / (6.0 * area))
}

/// Calibrate from images of a dot grid: detect, calibrate, then
/// `bias_iterations` times subtract each dot's perspective bias under the
/// current estimate and refine again.
pub fn calibrate_dot_grid(
    frames: &[GreyFrame],
    grid: &DotGrid,
    blur_margin: usize,
    fixed: &FixedParameters,
    bias_iterations: usize,
) -> Result<CalibrationFit, VisionError> {
    let (width, height) = frames
        .first()
        .map(|f| (f.width as u32, f.height as u32))
        .ok_or_else(|| VisionError::Calibration("no calibration image".into()))?;
    let measured: Vec<CalibrationView> = frames
        .iter()
        .enumerate()
        .map(|(i, f)| {
            let image = detect_dot_grid(f, grid, blur_margin)
                .map_err(|e| VisionError::DotGrid(format!("image {i}: {e}")))?;
            Ok(CalibrationView {
                target: grid.nodes(),
                image,
            })
        })
        .collect::<Result<_, VisionError>>()?;
    let mut fit = calibrate(&measured, width, height, fixed)?;
    for _ in 0..bias_iterations {
        let corrected: Vec<CalibrationView> = measured
            .iter()
            .zip(&fit.poses)
            .map(|(view, pose)| {
                let image = view
                    .target
                    .iter()
                    .zip(&view.image)
                    .map(|(t, p)| {
                        Ok(p - circle_centre_bias(&fit.camera, pose, *t, grid.dot_diameter)?)
                    })
                    .collect::<Result<_, VisionError>>()?;
                Ok(CalibrationView {
                    target: view.target.clone(),
                    image,
                })
            })
            .collect::<Result<_, VisionError>>()?;
        fit = refine(&corrected, &fit.camera, &fit.poses, fixed)?;
    }
    Ok(fit)
}
