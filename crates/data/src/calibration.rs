//! The calibration folder's target description, `calibration/target.ron`:
//! the dot-grid target the calibration images show, which image shows it
//! lying on the phantom top face, and where it lies there.
//!
//! On the target plane, dot `(i, j)` (column `i`, row `j`) has its centre at
//! `(i pitch, j pitch)`. In the face view the target lies flat on the top
//! face with its axes along the phantom's x and y, so dot `(i, j)` is at
//! `face_origin + (i pitch, j pitch)` in the phantom frame, and the pose of
//! the top face follows from that view's pose $(R, t)$ as
//! $(R,\ t - R\,(o_x, o_y, 0))$.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::BundleError;
use crate::grey_png::grey_png_problem;
use crate::layout::{CALIBRATION, CALIBRATION_TARGET};
use crate::report::{Collector, IssueKind, Severity};
use crate::ron_lines::field_lines;

/// The most dots on a side of a calibration target: a dot must span a few
/// pixels to be found, and a frame is a few thousand pixels wide (the
/// paper's camera 2056 x 1544), so more is a typing error, and would make a
/// calibration allocate for billions of dots.
const MOST_DOTS_PER_SIDE: usize = 1000;

/// `calibration/target.ron`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrationTarget {
    /// Dots per row (along the target's x).
    pub columns: usize,
    /// Rows of dots (along the target's y).
    pub rows: usize,
    /// Centre-to-centre distance of neighbouring dots (m).
    pub pitch: f64,
    /// Dot diameter (m).
    pub dot_diameter: f64,
    /// The calibration images, PNG files in the calibration folder, in
    /// view order.
    pub images: Vec<String>,
    /// Index in `images` of the view with the target lying on the top face.
    pub face_view: usize,
    /// Phantom-frame position (x, y) of dot `(0, 0)` in the face view (m).
    pub face_origin: (f64, f64),
}

impl CalibrationTarget {
    /// What is wrong with the description, as `(field, reason)`; empty when
    /// it is usable.
    pub fn problems(&self) -> Vec<(&'static str, String)> {
        let mut problems = Vec::new();
        if self.columns < 2 || self.rows < 2 {
            problems.push((
                "columns/rows",
                format!("a {} x {} grid has no extent", self.columns, self.rows),
            ));
        } else if self.columns > MOST_DOTS_PER_SIDE || self.rows > MOST_DOTS_PER_SIDE {
            problems.push((
                "columns/rows",
                format!(
                    "a {} x {} grid has more than {MOST_DOTS_PER_SIDE} dots a side; no camera \
                     frame resolves that many",
                    self.columns, self.rows
                ),
            ));
        }
        if !(self.pitch.is_finite() && self.pitch > 0.0) {
            problems.push(("pitch", format!("{} must be positive", self.pitch)));
        }
        if !(self.dot_diameter.is_finite()
            && self.dot_diameter > 0.0
            && self.dot_diameter < self.pitch)
        {
            problems.push((
                "dot_diameter",
                format!(
                    "{} must be positive and less than the pitch",
                    self.dot_diameter
                ),
            ));
        }
        if self.face_view >= self.images.len() {
            problems.push((
                "face_view",
                format!(
                    "{} is not an index of the {} images",
                    self.face_view,
                    self.images.len()
                ),
            ));
        }
        if !(self.face_origin.0.is_finite() && self.face_origin.1.is_finite()) {
            problems.push(("face_origin", "must be finite".into()));
        }
        for image in &self.images {
            if !image.ends_with(".png") || image.contains(['/', '\\']) || image.starts_with('.') {
                problems.push((
                    "images",
                    format!("{image:?} is not a PNG file name in the calibration folder"),
                ));
            }
        }
        problems
    }
}

/// Reads and checks `calibration/target.ron` of the bundle at `root`, if the
/// bundle has one; every problem goes to `issues`, with the line and field
/// it is at.
pub(crate) fn check_calibration_target(
    root: &Path,
    issues: &mut Collector,
) -> Option<CalibrationTarget> {
    let relative = Path::new(CALIBRATION).join(CALIBRATION_TARGET);
    let path = root.join(&relative);
    if !path.is_file() {
        return None;
    }
    let mut error = |line: Option<u64>, field: Option<&str>, message: String| {
        issues.add(
            Severity::Error,
            IssueKind::BadCalibration,
            &relative,
            line,
            field,
            message,
        )
    };
    let text = match std::fs::read_to_string(&path) {
        Ok(text) => text,
        Err(e) => {
            error(None, None, e.to_string());
            return None;
        }
    };
    let target: CalibrationTarget = match ron::from_str(&text) {
        Ok(target) => target,
        Err(e) => {
            error(
                Some(e.span.start.line as u64),
                field_named_by(&e.code),
                format!(
                    "not a valid calibration target: {} (column {})",
                    e.code, e.span.start.col
                ),
            );
            return None;
        }
    };
    let lines = field_lines(&text);
    let mut fine = true;
    for (field, reason) in target.problems() {
        // "columns/rows" is reported at the line of `columns`.
        let key = field.split('/').next().unwrap_or(field);
        error(lines.get(key).copied(), Some(field), reason);
        fine = false;
    }
    for image in &target.images {
        if !root.join(CALIBRATION).join(image).is_file() {
            let line = line_of_string(&text, image).or_else(|| lines.get("images").copied());
            error(
                line,
                Some("images"),
                format!("{image} is not in the calibration folder"),
            );
            fine = false;
        } else if let Some(problem) = grey_png_problem(&root.join(CALIBRATION).join(image)) {
            let line = line_of_string(&text, image).or_else(|| lines.get("images").copied());
            error(line, Some("images"), format!("{image} {problem}"));
            fine = false;
        }
    }
    fine.then_some(target)
}

/// The field a RON error is about, when serde names one.
fn field_named_by(code: &ron::Error) -> Option<&str> {
    match code {
        ron::Error::NoSuchStructField { found, .. } => Some(found),
        ron::Error::MissingStructField { field, .. }
        | ron::Error::DuplicateStructField { field, .. } => Some(field),
        _ => None,
    }
}

/// The one-based line of the first string literal `"value"` in `text`.
fn line_of_string(text: &str, value: &str) -> Option<u64> {
    let at = text.find(&format!("\"{value}\""))?;
    Some(1 + text[..at].matches('\n').count() as u64)
}

/// Reads `calibration/target.ron` of the bundle at `root`: `None` when the
/// bundle has none, [`BundleError::Invalid`] when it is malformed, names a
/// missing image or has an unusable value.
pub fn read_calibration_target(
    root: impl AsRef<Path>,
) -> Result<Option<CalibrationTarget>, BundleError> {
    let root = root.as_ref();
    let mut issues = Collector::default();
    let target = check_calibration_target(root, &mut issues);
    if issues.has_errors() {
        return Err(BundleError::Invalid {
            report: issues.finish(root),
        });
    }
    Ok(target)
}
