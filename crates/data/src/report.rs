//! The validation report: every problem found in a bundle, with where it is.
//!
//! Validation never stops at the first problem. Each [`Issue`] names its
//! file (relative to the bundle root), the line when the problem is on one,
//! the field or column, and says in plain words what is wrong. Errors make a
//! bundle unreadable; warnings (typically magnitudes that do not look like SI
//! units) are returned with the loaded bundle.

use std::collections::HashMap;
use std::fmt;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// How bad an issue is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum Severity {
    /// Suspicious but readable; the bundle loads and the warning is returned.
    Warning,
    /// The bundle cannot be used as it is.
    Error,
}

/// What kind of problem an issue is; stable names that tests and tools can
/// match on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum IssueKind {
    /// A file or folder could not be read.
    Io,
    /// A required file or folder is absent.
    MissingFile,
    /// `bundle.ron` is not valid RON or does not have the manifest's shape.
    ManifestSyntax,
    /// `bundle.ron` has a field the format does not define.
    UnknownField,
    /// `bundle.ron` lacks a required field.
    MissingField,
    /// `bundle.ron` gives a field twice.
    DuplicateField,
    /// `bundle.ron` names an enum variant the format does not define
    /// (a trial kind or a face).
    UnknownVariant,
    /// The manifest's `format` is not a version this crate reads.
    UnsupportedFormat,
    /// A CSV file's header is not the one the format prescribes.
    BadHeader,
    /// A CSV row has the wrong number of fields.
    RowLength,
    /// A value is not a number (or not an integer where one is required).
    BadNumber,
    /// A number is NaN or infinite.
    NonFinite,
    /// A value is outside its physical range (a negative length, speed,
    /// day or standard deviation).
    NonPhysical,
    /// A required table has no data rows.
    EmptyTable,
    /// A trial id cannot name a folder (empty, a path separator, a leading dot).
    BadTrialId,
    /// Two trials of the manifest share an id.
    DuplicateTrialId,
    /// A folder under `trials/` that the manifest does not list.
    UnlistedTrialFolder,
    /// A trial the manifest lists has no folder under `trials/`.
    MissingTrialFolder,
    /// A marker id appears twice in `markers_rest.csv`.
    DuplicateMarker,
    /// `markers.csv` names a marker id that `markers_rest.csv` does not have.
    UnknownMarker,
    /// Time decreases from one row to the next.
    TimeBackwards,
    /// A frame number decreases from one row to the next.
    FrameBackwards,
    /// Rows of the same frame carry different times.
    FrameTimeMismatch,
    /// The same marker appears twice in one frame.
    DuplicateRow,
    /// A magnitude that does not look like SI units (millimetres, kilonewtons,
    /// degrees, milliseconds); a warning.
    Units,
    /// Something legal but probably not intended (an unknown file, a repeated
    /// timestamp, a marker off the phantom); a warning.
    Suspicious,
    /// `calibration/target.ron` is not valid RON of the target description,
    /// has an unusable value, or names an image that is not there.
    BadCalibration,
    /// A camera frame is not a PNG image of 8- or 16-bit grey (judged from
    /// its header; the reader does not decode images).
    BadFrame,
    /// Further issues of one kind in one file that were counted but not listed.
    Suppressed,
}

/// One problem found in a bundle.
#[derive(Debug, Clone, PartialEq)]
pub struct Issue {
    /// Error or warning.
    pub severity: Severity,
    /// What kind of problem.
    pub kind: IssueKind,
    /// The file, relative to the bundle root.
    pub file: PathBuf,
    /// One-based line in that file, when the problem is on one line.
    pub line: Option<u64>,
    /// The field (manifest) or column (CSV) concerned, when there is one.
    pub field: Option<String>,
    /// What is wrong, in words.
    pub message: String,
}

impl fmt::Display for Issue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let severity = match self.severity {
            Severity::Error => "error",
            Severity::Warning => "warning",
        };
        write!(f, "{severity}: {}", self.file.display())?;
        if let Some(line) = self.line {
            write!(f, ", line {line}")?;
        }
        if let Some(field) = &self.field {
            write!(f, ", {field}")?;
        }
        write!(f, ": {}", self.message)
    }
}

/// Everything validation found in one bundle (or one file).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ValidationReport {
    /// The bundle (or file) that was validated.
    pub root: PathBuf,
    /// Every issue, in the order found (file by file).
    pub issues: Vec<Issue>,
}

impl ValidationReport {
    /// True when at least one issue is an error.
    pub fn has_errors(&self) -> bool {
        self.issues.iter().any(|i| i.severity == Severity::Error)
    }

    /// The errors.
    pub fn errors(&self) -> impl Iterator<Item = &Issue> {
        self.issues.iter().filter(|i| i.severity == Severity::Error)
    }

    /// The warnings.
    pub fn warnings(&self) -> impl Iterator<Item = &Issue> {
        self.issues
            .iter()
            .filter(|i| i.severity == Severity::Warning)
    }

    /// True when there is nothing to report.
    pub fn is_empty(&self) -> bool {
        self.issues.is_empty()
    }
}

impl fmt::Display for ValidationReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let errors = self.errors().count();
        let warnings = self.issues.len() - errors;
        writeln!(
            f,
            "{}: {errors} error{}, {warnings} warning{}",
            self.root.display(),
            if errors == 1 { "" } else { "s" },
            if warnings == 1 { "" } else { "s" },
        )?;
        for issue in &self.issues {
            writeln!(f, "  {issue}")?;
        }
        Ok(())
    }
}

/// A number as a message shows it: in exponent form when it is very large
/// or very small, so that a value of 1e300 does not print 301 digits.
pub(crate) struct Shown(pub f64);

impl fmt::Display for Shown {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let size = self.0.abs();
        if size == 0.0 || !size.is_finite() || (1e-4..1e9).contains(&size) {
            write!(f, "{}", self.0)
        } else {
            write!(f, "{:e}", self.0)
        }
    }
}

/// The longest text from a file that a message quotes whole.
const LONGEST_QUOTE: usize = 40;

/// Text from a file as a message quotes it: cut after [`LONGEST_QUOTE`]
/// characters, so that one bad field of a million digits gives one line.
pub(crate) struct Quoted<'a>(pub &'a str);

impl fmt::Display for Quoted<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let length = self.0.chars().count();
        if length <= LONGEST_QUOTE {
            return f.write_str(self.0);
        }
        let head: String = self.0.chars().take(LONGEST_QUOTE).collect();
        write!(f, "{head}... ({length} characters)")
    }
}

/// How many issues of one kind one file may list before the rest are only
/// counted: a file with a million bad rows gives a readable report.
const LISTED_PER_FILE_AND_KIND: usize = 20;

/// Collects the issues of one validation run, capping repeats per file and
/// kind.
#[derive(Debug, Default)]
pub(crate) struct Collector {
    issues: Vec<Issue>,
    counts: HashMap<(PathBuf, IssueKind), usize>,
}

impl Collector {
    fn push(&mut self, issue: Issue) {
        let count = self
            .counts
            .entry((issue.file.clone(), issue.kind))
            .or_insert(0);
        *count += 1;
        if *count <= LISTED_PER_FILE_AND_KIND {
            self.issues.push(issue);
        }
    }

    /// Shorthand for an issue at a file, line and field.
    pub(crate) fn add(
        &mut self,
        severity: Severity,
        kind: IssueKind,
        file: &Path,
        line: Option<u64>,
        field: Option<&str>,
        message: String,
    ) {
        self.push(Issue {
            severity,
            kind,
            file: file.to_path_buf(),
            line,
            field: field.map(str::to_owned),
            message,
        });
    }

    /// True when an error has been recorded.
    pub(crate) fn has_errors(&self) -> bool {
        self.issues.iter().any(|i| i.severity == Severity::Error)
    }

    pub(crate) fn finish(self, root: &Path) -> ValidationReport {
        let mut issues = self.issues;
        let mut suppressed: Vec<_> = self
            .counts
            .into_iter()
            .filter(|(_, count)| *count > LISTED_PER_FILE_AND_KIND)
            .collect();
        suppressed.sort();
        for ((file, kind), count) in suppressed {
            let severity = issues
                .iter()
                .find(|i| i.file == file && i.kind == kind)
                .map_or(Severity::Error, |i| i.severity);
            issues.push(Issue {
                severity,
                kind: IssueKind::Suppressed,
                file,
                line: None,
                field: None,
                message: format!(
                    "{} more issues of kind {kind:?} not listed ({count} in all)",
                    count - LISTED_PER_FILE_AND_KIND
                ),
            });
        }
        ValidationReport {
            root: root.to_path_buf(),
            issues,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{Quoted, Shown};

    #[test]
    fn numbers_far_from_one_are_shown_in_exponent_form() {
        assert_eq!(Shown(0.0375).to_string(), "0.0375");
        assert_eq!(Shown(-2500.0).to_string(), "-2500");
        assert_eq!(Shown(0.0).to_string(), "0");
        assert_eq!(Shown(1e300).to_string(), "1e300");
        assert_eq!(Shown(-2.5e-7).to_string(), "-2.5e-7");
        assert_eq!(Shown(f64::INFINITY).to_string(), "inf");
    }

    #[test]
    fn long_text_is_cut_and_its_length_given() {
        assert_eq!(Quoted("0.5x").to_string(), "0.5x");
        let digits = "9".repeat(5_000_000);
        let quoted = Quoted(&digits).to_string();
        assert_eq!(
            quoted,
            format!("{}... (5000000 characters)", "9".repeat(40))
        );
        // Cut between characters, not inside one.
        assert!(
            Quoted(&"é".repeat(50))
                .to_string()
                .starts_with(&"é".repeat(40))
        );
    }
}
