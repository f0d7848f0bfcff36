//! The crate's error type.

use std::io;
use std::path::PathBuf;

use crate::report::ValidationReport;

/// Why a bundle could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum BundleError {
    /// Validation found errors; the report lists every one of them (and the
    /// warnings).
    #[error("invalid measurement bundle {report}")]
    Invalid {
        /// Every issue found.
        report: ValidationReport,
    },
    /// The destination exists and the write options do not allow replacing it.
    #[error(
        "{path} already exists and is left as it is; write elsewhere or remove it first (a program may pass Overwrite::Allow to replace a bundle)"
    )]
    AlreadyExists {
        /// The destination.
        path: PathBuf,
    },
    /// The destination exists but is not a measurement bundle (it has no
    /// `bundle.ron`), so it is not replaced even with `Overwrite::Allow`.
    #[error("{path} exists and is not a measurement bundle; refusing to replace it")]
    NotABundle {
        /// The destination.
        path: PathBuf,
    },
    /// Marker observations mix rows with and without tracking standard
    /// deviations; a `markers.csv` has the `sx,sy` columns for all rows or
    /// for none.
    #[error("marker observations mix rows with and without sx,sy (first mismatch at row {row})")]
    MixedSigma {
        /// Zero-based index of the first row that differs from the first row.
        row: usize,
    },
    /// A frame file number does not fit the `NNNNNN.png` naming.
    #[error("frame number {number} does not fit six digits (NNNNNN.png)")]
    FrameNumber {
        /// The number.
        number: u64,
    },
    /// A file system operation failed.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder concerned.
        path: PathBuf,
        /// The underlying error.
        source: io::Error,
    },
}

impl BundleError {
    pub(crate) fn io(path: impl Into<PathBuf>) -> impl FnOnce(io::Error) -> Self {
        let path = path.into();
        move |source| Self::Io { path, source }
    }
}
