//! The malformed-bundle corpus: every case under `fixtures/bad-bundles/`
//! holds a `bundle/` folder and an `expected.ron` listing the issues that
//! validating it must produce (kind, file, line, and the field where the
//! case names one). The errors must match exactly, no more and no fewer;
//! listed warnings must be present.

use std::fs;
use std::path::{Path, PathBuf};

use needle_data::{BundleError, IssueKind, Severity, read_bundle, validate_bundle};
use serde::Deserialize;

#[derive(Debug, Deserialize, PartialEq, Eq, Clone)]
struct Expected {
    severity: Severity,
    kind: IssueKind,
    file: String,
    line: Option<u64>,
    /// Checked only when the case gives it.
    #[serde(default)]
    field: Option<String>,
}

impl Expected {
    /// The same issue with the field left out, for the exact comparison.
    fn without_field(&self) -> Self {
        Self {
            field: None,
            ..self.clone()
        }
    }
}

fn corpus() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/bad-bundles")
}

fn sort_key(e: &Expected) -> (String, Option<u64>, String) {
    (
        e.file.clone(),
        e.line,
        format!("{:?}{:?}", e.severity, e.kind),
    )
}

#[test]
fn every_bad_bundle_reports_exactly_its_expected_errors() {
    let mut cases: Vec<PathBuf> = fs::read_dir(corpus())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_dir())
        .collect();
    cases.sort();
    assert!(cases.len() >= 20, "the corpus has {} cases", cases.len());
    let mut failures = Vec::new();
    for case in &cases {
        let name = case.file_name().unwrap().to_string_lossy();
        let text = fs::read_to_string(case.join("expected.ron")).unwrap();
        let expected: Vec<Expected> = ron::from_str(&text).unwrap();
        let bundle = case.join("bundle");
        let report = validate_bundle(&bundle);
        let found: Vec<Expected> = report
            .issues
            .iter()
            .map(|i| Expected {
                severity: i.severity,
                kind: i.kind,
                file: i.file.to_string_lossy().into_owned(),
                line: i.line,
                field: i.field.clone(),
            })
            .collect();
        let mut expected_errors: Vec<_> = expected
            .iter()
            .filter(|e| e.severity == Severity::Error)
            .map(Expected::without_field)
            .collect();
        let mut found_errors: Vec<_> = found
            .iter()
            .filter(|e| e.severity == Severity::Error)
            .map(Expected::without_field)
            .collect();
        expected_errors.sort_by_key(sort_key);
        found_errors.sort_by_key(sort_key);
        let missing_warnings: Vec<_> = expected
            .iter()
            .filter(|e| e.severity == Severity::Warning)
            .map(Expected::without_field)
            .filter(|e| !found.iter().any(|f| f.without_field() == *e))
            .collect();
        // Where a case names the field, an issue at that place names it too.
        let wrong_fields: Vec<_> = expected
            .iter()
            .filter(|e| e.field.is_some() && !found.contains(e))
            .collect();
        if expected_errors != found_errors
            || !missing_warnings.is_empty()
            || !wrong_fields.is_empty()
        {
            failures.push(format!(
                "{name}: expected {expected:?}\nbut validation reported\n{report}"
            ));
        }
        // Reading agrees with validating: it fails exactly when there are errors.
        match read_bundle(&bundle) {
            Ok(loaded) => assert!(
                expected_errors.is_empty() && loaded.warnings == report,
                "{name}"
            ),
            Err(BundleError::Invalid {
                report: read_report,
            }) => {
                assert!(!expected_errors.is_empty(), "{name}");
                assert_eq!(read_report, report, "{name}");
            }
            Err(other) => panic!("{name}: {other}"),
        }
        // Every message names what went wrong in words.
        assert!(report.issues.iter().all(|i| i.message.len() > 10), "{name}");
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}
