//! Where each file of a bundle lives, so that no other module spells a path.

use std::path::{Path, PathBuf};

/// The manifest.
pub const MANIFEST: &str = "bundle.ron";
/// Undeformed marker positions.
pub const MARKERS_REST: &str = "markers_rest.csv";
/// The folder holding one sub-folder per trial.
pub const TRIALS: &str = "trials";
/// A trial's tool trajectory and force samples.
pub const TOOL: &str = "tool.csv";
/// A trial's tracked marker positions.
pub const MARKERS: &str = "markers.csv";
/// A trial's raw camera frames.
pub const FRAMES: &str = "frames";
/// The optional calibration folder.
pub const CALIBRATION: &str = "calibration";
/// The calibration target description inside the calibration folder.
pub const CALIBRATION_TARGET: &str = "target.ron";
/// The optional unconfined compression curve.
pub const COMPRESSION: &str = "compression.csv";

/// Header of `markers_rest.csv`.
pub(crate) const MARKERS_REST_HEADER: &[&str] = &["id", "x", "y"];
/// Header of `tool.csv`.
pub(crate) const TOOL_HEADER: &[&str] = &["t", "tip_x", "tip_y", "theta", "fx", "fy", "mz"];
/// Header of `markers.csv` without tracking deviations.
pub(crate) const MARKERS_HEADER: &[&str] = &["frame", "t", "id", "x", "y"];
/// The optional trailing columns of `markers.csv`.
pub(crate) const MARKERS_SIGMA_COLUMNS: &[&str] = &["sx", "sy"];
/// Header of `compression.csv`.
pub(crate) const COMPRESSION_HEADER: &[&str] = &["strain", "stress"];

/// `BUNDLE/trials/ID`.
pub fn trial_dir(bundle: &Path, trial_id: &str) -> PathBuf {
    bundle.join(TRIALS).join(trial_id)
}

/// `BUNDLE/trials/ID/frames`, where a trial's camera frames go.
pub fn frames_dir(bundle: &Path, trial_id: &str) -> PathBuf {
    trial_dir(bundle, trial_id).join(FRAMES)
}

/// The file name of frame `number`: six digits, zero padded, `.png`.
/// `None` when the number needs more than six digits.
pub fn frame_file_name(number: u64) -> Option<String> {
    (number <= 999_999).then(|| format!("{number:06}.png"))
}

/// The frame number of a file name `NNNNNN.png` (exactly six digits), if it
/// is one.
pub(crate) fn parse_frame_file_name(name: &str) -> Option<u64> {
    let digits = name.strip_suffix(".png")?;
    if digits.len() == 6 && digits.bytes().all(|b| b.is_ascii_digit()) {
        digits.parse().ok()
    } else {
        None
    }
}

/// The longest file name, in bytes, of the common file systems (ext4,
/// APFS, NTFS in UTF-16 units, which is no shorter).
const LONGEST_FOLDER_NAME: usize = 255;

/// Why a trial id cannot name a folder, if it cannot.
pub(crate) fn trial_id_problem(id: &str) -> Option<&'static str> {
    if id.is_empty() {
        Some("is empty")
    } else if id.contains(['/', '\\', '\0']) {
        Some("contains a path separator or NUL")
    } else if id.starts_with('.') {
        Some("starts with a dot (a hidden or relative folder)")
    } else if id.trim() != id {
        Some("starts or ends with white space")
    } else if id.len() > LONGEST_FOLDER_NAME {
        Some("is longer than the 255 bytes a folder name can have")
    } else {
        None
    }
}
