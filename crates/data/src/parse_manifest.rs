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
use crate::report::{Collector, IssueKind, Severity};
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
            // A newer format may well fail the format-1 schema; say that,
            // rather than the schema error it causes.
            if let Ok(probe) = ron::from_str::<FormatProbe>(text)
                && probe.format != FORMAT_VERSION
            {
                unsupported_format(probe.format, line_of("format"), file, issues);
                return None;
            }
            report_ron_error(&err, file, issues);
            return None;
        }
    };
    if bundle.format != FORMAT_VERSION {
        unsupported_format(bundle.format, line_of("format"), file, issues);
        return None;
    }
    check_values(&bundle, file, &line_of, issues);
    Some(bundle)
}

/// Just the version, with every other field ignored.
#[derive(Deserialize)]
#[serde(rename = "Bundle")]
struct FormatProbe {
    format: u32,
}

fn unsupported_format(format: u32, line: Option<u64>, file: &Path, issues: &mut Collector) {
    issues.add(
        Severity::Error,
        IssueKind::UnsupportedFormat,
        file,
        line,
        Some("format"),
        format!(
            "format version {format} is not supported; this reader reads format {FORMAT_VERSION}"
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
                format!("{what} is {value}, not a finite number"),
            );
        } else if minimum.violated_by(value) {
            issues.add(
                Severity::Error,
                IssueKind::NonPhysical,
                file,
                line,
                Some(path),
                format!("{what} is {value}; it must be {}", minimum.describe()),
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
                    "phantom {name} is {value} m; is it in millimetres? (SI units are expected)"
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
                    "trial id {:?} {problem}; it must name a folder under trials/",
                    trial.id
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
                    "trial id {:?} is used by trials {first} and {i} (counting from 0)",
                    trial.id
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

/// One level of nesting while scanning RON text.
enum Level {
    /// A struct `Name(...)`, `(...)` or map `{...}`, with the field being read.
    Struct(Option<String>),
    /// A list `[...]`, with the index of the element being read.
    List(usize),
    /// `Some(...)`: adds nothing to the path.
    Transparent,
}

/// The line of every field of a RON document, keyed by its path
/// (`phantom.width`, `trials[1].velocity`, `noise.marker_sigma`).
///
/// A tolerant scan, not a parser: it skips comments, strings and literals and
/// follows brackets, so it gives lines even for values serde accepted but the
/// checks reject.
fn field_lines(text: &str) -> HashMap<String, u64> {
    let bytes = text.as_bytes();
    let mut lines = HashMap::new();
    let mut stack: Vec<Level> = Vec::new();
    let mut line: u64 = 1;
    let mut pending_ident: Option<(&str, u64)> = None;
    let mut i = 0;
    while i < bytes.len() {
        let b = bytes[i];
        match b {
            b'\n' => {
                line += 1;
                i += 1;
            }
            b'/' if bytes.get(i + 1) == Some(&b'/') => {
                while i < bytes.len() && bytes[i] != b'\n' {
                    i += 1;
                }
            }
            b'/' if bytes.get(i + 1) == Some(&b'*') => {
                // RON block comments nest.
                let mut depth = 0usize;
                while i < bytes.len() {
                    if bytes[i..].starts_with(b"/*") {
                        depth += 1;
                        i += 2;
                    } else if bytes[i..].starts_with(b"*/") {
                        depth -= 1;
                        i += 2;
                        if depth == 0 {
                            break;
                        }
                    } else {
                        line += u64::from(bytes[i] == b'\n');
                        i += 1;
                    }
                }
            }
            b'"' | b'\'' => {
                pending_ident = None;
                i += 1;
                while i < bytes.len() && bytes[i] != b {
                    line += u64::from(bytes[i] == b'\n');
                    i += if bytes[i] == b'\\' { 2 } else { 1 };
                }
                i += 1;
            }
            b'r' if raw_string_hashes(&bytes[i + 1..]).is_some() => {
                pending_ident = None;
                let hashes = raw_string_hashes(&bytes[i + 1..]).unwrap_or(0);
                let mut closing = vec![b'"'];
                closing.extend(std::iter::repeat_n(b'#', hashes));
                i += 1 + hashes + 1;
                while i < bytes.len() && !bytes[i..].starts_with(&closing) {
                    line += u64::from(bytes[i] == b'\n');
                    i += 1;
                }
                i += closing.len();
            }
            b'A'..=b'Z' | b'a'..=b'z' | b'_' => {
                let start = i;
                while i < bytes.len() && (bytes[i].is_ascii_alphanumeric() || bytes[i] == b'_') {
                    i += 1;
                }
                pending_ident = Some((&text[start..i], line));
            }
            b':' => {
                if let (Some((name, at)), Some(Level::Struct(field))) =
                    (pending_ident.take(), stack.last_mut())
                {
                    *field = Some(name.to_owned());
                    lines.entry(path_of(&stack)).or_insert(at);
                }
                i += 1;
            }
            b'(' | b'{' => {
                let level = match pending_ident.take() {
                    Some(("Some", _)) => Level::Transparent,
                    _ => Level::Struct(None),
                };
                stack.push(level);
                i += 1;
            }
            b'[' => {
                pending_ident = None;
                stack.push(Level::List(0));
                i += 1;
            }
            b')' | b'}' | b']' => {
                pending_ident = None;
                stack.pop();
                i += 1;
            }
            b',' => {
                pending_ident = None;
                match stack.last_mut() {
                    Some(Level::List(index)) => *index += 1,
                    Some(Level::Struct(field)) => *field = None,
                    _ => {}
                }
                i += 1;
            }
            _ => {
                if !b.is_ascii_whitespace() {
                    pending_ident = None;
                }
                i += 1;
            }
        }
    }
    lines
}

/// The number of `#` of a raw string `r#..."...` starting after the `r`,
/// if the bytes start one (and not a raw identifier `r#name`).
fn raw_string_hashes(after_r: &[u8]) -> Option<usize> {
    let hashes = after_r.iter().take_while(|&&c| c == b'#').count();
    (after_r.get(hashes) == Some(&b'"')).then_some(hashes)
}

fn path_of(stack: &[Level]) -> String {
    let mut path = String::new();
    for level in stack {
        match level {
            Level::Struct(Some(field)) => {
                if !path.is_empty() {
                    path.push('.');
                }
                path.push_str(field);
            }
            Level::List(index) => path.push_str(&format!("[{index}]")),
            Level::Struct(None) | Level::Transparent => {}
        }
    }
    path
}

#[cfg(test)]
mod tests {
    use super::field_lines;

    #[test]
    fn field_lines_follow_nesting_comments_and_lists() {
        let text = "Bundle(\n  format: 1, // a comment: with colon\n  name: \"a: (b\",\n  phantom: Phantom(width: 0.1,\n depth: 0.1, thickness: 0.01, fixed: [Back, Left]),\n  noise: Some(Noise(marker_sigma: 1e-6,\n force_sigma: 0.01)),\n  /* block /* nested */ x: 1 */ trials: [\n    Trial(id: \"a\", kind: Probe, velocity: 0.001, day: 0.0),\n    Trial(id: \"b\", kind: Needle,\n velocity: 0.002, day: 1.0),\n  ],\n)";
        let lines = field_lines(text);
        assert_eq!(lines["format"], 2);
        assert_eq!(lines["name"], 3);
        assert_eq!(lines["phantom.width"], 4);
        assert_eq!(lines["phantom.depth"], 5);
        assert_eq!(lines["phantom.fixed"], 5);
        assert_eq!(lines["noise.marker_sigma"], 6);
        assert_eq!(lines["noise.force_sigma"], 7);
        assert_eq!(lines["trials"], 8);
        assert_eq!(lines["trials[0].id"], 9);
        assert_eq!(lines["trials[1].id"], 10);
        assert_eq!(lines["trials[1].velocity"], 11);
        assert!(!lines.contains_key("x"));
    }
}
