//! Reading and checking `bundle.ron`.
//!
//! RON is parsed by serde with `deny_unknown_fields`; its first structural
//! error (RON stops there) becomes one issue naming the field, the file and
//! the line. A parsed manifest is then checked value by value, and every
//! problem is reported with the line of its field, found by a small scan of
//! the text that maps each field path (`trials[1].velocity`) to its line.

use std::collections::{HashMap, HashSet};
use std::path::Path;

use serde::Deserialize;

use crate::layout::trial_id_problem;
use crate::report::{Collector, IssueKind, Quoted, Severity, Shown};
use crate::ron_lines::field_lines;
use crate::types::{Bundle, FORMAT_VERSION};

/// Phantom sizes above this (m) look like millimetres.
const LARGEST_PLAUSIBLE_PHANTOM: f64 = 2.0;
/// Tool speeds above this (m/s) look like mm/s.
const FASTEST_PLAUSIBLE_TOOL: f64 = 1.0;
/// A stated force noise above this (N) looks like the wrong unit.
const LARGEST_PLAUSIBLE_FORCE_SIGMA: f64 = 100.0;

/// Parses and checks the manifest text; `None` when it cannot be parsed or
/// its format is not supported (the issues say why).
pub(crate) fn parse_manifest(text: &str, file: &Path, issues: &mut Collector) -> Option<Bundle> {
    let lines = field_lines(text);
    let line_of = |path: &str| lines.get(path).copied();
    let bundle = match ron::from_str::<Bundle>(text) {
        Ok(bundle) => bundle,
        Err(err) => {
            // A newer format may well fail the format-1 schema, and a
            // version that is no whole number fails it too; say that,
            // rather than the schema error it causes.
            if let Ok(probe) = ron::from_str::<FormatProbe>(text)
                && let Ok(written) = ron::to_string(&probe.format)
                && written != FORMAT_VERSION.to_string()
            {
                unsupported_format(&written, line_of("format"), file, issues);
                return None;
            }
            report_ron_error(&err, file, issues);
            return None;
        }
    };
    if bundle.format != FORMAT_VERSION {
        unsupported_format(&bundle.format.to_string(), line_of("format"), file, issues);
        return None;
    }
    check_values(&bundle, file, &line_of, issues);
    Some(bundle)
}

/// Just the version, whatever its type, with every other field ignored.
#[derive(Deserialize)]
#[serde(rename = "Bundle")]
struct FormatProbe {
    format: ron::Value,
}

/// `format` is the version as the file writes it.
fn unsupported_format(format: &str, line: Option<u64>, file: &Path, issues: &mut Collector) {
    issues.add(
        Severity::Error,
        IssueKind::UnsupportedFormat,
        file,
        line,
        Some("format"),
        format!(
            "format version {} is not supported; this reader reads format {FORMAT_VERSION}",
            Quoted(format)
        ),
    );
}

fn report_ron_error(err: &ron::error::SpannedError, file: &Path, issues: &mut Collector) {
    use ron::Error as E;
    let in_outer = |outer: &Option<String>| {
        outer
            .as_ref()
            .map_or_else(String::new, |o| format!(" in {o}"))
    };
    let (kind, field, message) = match &err.code {
        E::NoSuchStructField {
            expected,
            found,
            outer,
        } => (
            IssueKind::UnknownField,
            Some(found.clone()),
            format!(
                "unknown field `{found}`{}; the format defines {}",
                in_outer(outer),
                list(expected)
            ),
        ),
        E::MissingStructField { field, outer } => (
            IssueKind::MissingField,
            Some((*field).to_owned()),
            format!("required field `{field}` is missing{}", in_outer(outer)),
        ),
        E::DuplicateStructField { field, outer } => (
            IssueKind::DuplicateField,
            Some((*field).to_owned()),
            format!("field `{field}` is given twice{}", in_outer(outer)),
        ),
        E::NoSuchEnumVariant {
            expected,
            found,
            outer,
        } => (
            IssueKind::UnknownVariant,
            None,
            format!(
                "unknown value `{found}`{}; expected one of {}",
                in_outer(outer),
                list(expected)
            ),
        ),
        other => (
            IssueKind::ManifestSyntax,
            None,
            format!(
                "not a valid format-1 manifest: {other} (column {})",
                err.span.start.col
            ),
        ),
    };
    issues.add(
        Severity::Error,
        kind,
        file,
        Some(err.span.start.line as u64),
        field.as_deref(),
        message,
    );
}

fn list(names: &[&str]) -> String {
    names
        .iter()
        .map(|n| format!("`{n}`"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Checks the values of a parsed manifest, reporting every problem.
fn check_values(
    bundle: &Bundle,
    file: &Path,
    line_of: &dyn Fn(&str) -> Option<u64>,
    issues: &mut Collector,
) {
    let check = |issues: &mut Collector, path: &str, value: f64, what: &str, minimum: Minimum| {
        let line = line_of(path);
        if !value.is_finite() {
            issues.add(
                Severity::Error,
                IssueKind::NonFinite,
                file,
                line,
                Some(path),
                format!("{what} is {}, not a finite number", Shown(value)),
            );
        } else if minimum.violated_by(value) {
            issues.add(
                Severity::Error,
                IssueKind::NonPhysical,
                file,
                line,
                Some(path),
                format!(
                    "{what} is {}; it must be {}",
                    Shown(value),
                    minimum.describe()
                ),
            );
        }
        value.is_finite()
    };

    let phantom = &bundle.phantom;
    for (name, value) in [
        ("width", phantom.width),
        ("depth", phantom.depth),
        ("thickness", phantom.thickness),
    ] {
        let path = format!("phantom.{name}");
        if check(
            issues,
            &path,
            value,
            &format!("phantom {name}"),
            Minimum::Positive,
        ) && value > LARGEST_PLAUSIBLE_PHANTOM
        {
            issues.add(
                Severity::Warning,
                IssueKind::Units,
                file,
                line_of(&path),
                Some(&path),
                format!(
                    "phantom {name} is {} m; is it in millimetres? (SI units are expected)",
                    Shown(value)
                ),
            );
        }
    }
    let mut faces = HashSet::new();
    for face in &phantom.fixed {
        if !faces.insert(face) {
            issues.add(
                Severity::Warning,
                IssueKind::Suspicious,
                file,
                line_of("phantom.fixed"),
                Some("phantom.fixed"),
                format!("face {face:?} is listed twice"),
            );
        }
    }

    if let Some(noise) = &bundle.noise {
        let size = phantom.width.max(phantom.depth);
        if check(
            issues,
            "noise.marker_sigma",
            noise.marker_sigma,
            "marker noise",
            Minimum::NonNegative,
        ) && noise.marker_sigma > 0.1 * size
        {
            issues.add(
                Severity::Warning,
                IssueKind::Units,
                file,
                line_of("noise.marker_sigma"),
                Some("noise.marker_sigma"),
                format!(
                    "marker noise of {} m is more than a tenth of the phantom; is it in millimetres?",
                    noise.marker_sigma
                ),
            );
        }
        if check(
            issues,
            "noise.force_sigma",
            noise.force_sigma,
            "force noise",
            Minimum::NonNegative,
        ) && noise.force_sigma > LARGEST_PLAUSIBLE_FORCE_SIGMA
        {
            issues.add(
                Severity::Warning,
                IssueKind::Units,
                file,
                line_of("noise.force_sigma"),
                Some("noise.force_sigma"),
                format!(
                    "force noise of {} N is implausibly large; newtons are expected",
                    noise.force_sigma
                ),
            );
        }
    }

    if bundle.trials.is_empty() {
        issues.add(
            Severity::Warning,
            IssueKind::Suspicious,
            file,
            line_of("trials"),
            Some("trials"),
            "the manifest lists no trials".to_owned(),
        );
    }
    let mut first_index: HashMap<&str, usize> = HashMap::new();
    for (i, trial) in bundle.trials.iter().enumerate() {
        let id_path = format!("trials[{i}].id");
        if let Some(problem) = trial_id_problem(&trial.id) {
            issues.add(
                Severity::Error,
                IssueKind::BadTrialId,
                file,
                line_of(&id_path),
                Some(&id_path),
                format!(
                    "trial id {} {problem}; it must name a folder under trials/",
                    Quoted(&format!("{:?}", trial.id))
                ),
            );
        }
        if let Some(&first) = first_index.get(trial.id.as_str()) {
            issues.add(
                Severity::Error,
                IssueKind::DuplicateTrialId,
                file,
                line_of(&id_path),
                Some(&id_path),
                format!(
                    "trial id {} is used by trials {first} and {i} (counting from 0)",
                    Quoted(&format!("{:?}", trial.id))
                ),
            );
        } else {
            first_index.insert(&trial.id, i);
        }
        let velocity_path = format!("trials[{i}].velocity");
        let velocity_name = format!("velocity of trial {:?}", trial.id);
        if check(
            issues,
            &velocity_path,
            trial.velocity,
            &velocity_name,
            Minimum::NonNegative,
        ) && trial.velocity > FASTEST_PLAUSIBLE_TOOL
        {
            issues.add(
                Severity::Warning,
                IssueKind::Units,
                file,
                line_of(&velocity_path),
                Some(&velocity_path),
                format!(
                    "{velocity_name} is {} m/s; is it in mm/s? (SI units are expected)",
                    trial.velocity
                ),
            );
        }
        check(
            issues,
            &format!("trials[{i}].day"),
            trial.day,
            &format!("day of trial {:?}", trial.id),
            Minimum::NonNegative,
        );
    }
}

/// The physical lower bound of a manifest value.
#[derive(Clone, Copy)]
enum Minimum {
    Positive,
    NonNegative,
}

impl Minimum {
    fn violated_by(self, value: f64) -> bool {
        match self {
            Self::Positive => value <= 0.0,
            Self::NonNegative => value < 0.0,
        }
    }

    fn describe(self) -> &'static str {
        match self {
            Self::Positive => "positive",
            Self::NonNegative => "zero or positive",
        }
    }
}
