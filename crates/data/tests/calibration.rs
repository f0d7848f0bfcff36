//! The calibration folder's `target.ron`: a valid description reads back,
//! a malformed one, one with an unusable value and one naming a missing
//! image are errors of kind `BadCalibration` that name the file.

use std::fs;
use std::path::{Path, PathBuf};

use needle_data::{
    BundleError, CalibrationTarget, IssueKind, Severity, read_bundle, read_calibration_target,
    validate_bundle,
};

mod common;

use common::{copy_tree, grey_png, tiny};

fn target() -> CalibrationTarget {
    CalibrationTarget {
        columns: 9,
        rows: 9,
        pitch: 0.0075,
        dot_diameter: 0.003,
        images: vec!["view-00.png".into(), "view-01.png".into()],
        face_view: 0,
        face_origin: (0.0075, 0.0075),
    }
}

/// The tiny bundle with a calibration folder holding `text` as
/// `target.ron` and the images `images`.
fn bundle_with(text: &str, images: &[&str]) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("tiny");
    copy_tree(&tiny(), &root);
    let calibration = root.join("calibration");
    fs::create_dir_all(&calibration).unwrap();
    fs::write(calibration.join("target.ron"), text).unwrap();
    for image in images {
        fs::write(calibration.join(image), grey_png()).unwrap();
    }
    (dir, root)
}

fn ron_of(target: &CalibrationTarget) -> String {
    ron::ser::to_string_pretty(target, ron::ser::PrettyConfig::default().struct_names(true))
        .unwrap()
}

fn calibration_errors(root: &Path) -> Vec<(Option<String>, String)> {
    validate_bundle(root)
        .issues
        .into_iter()
        .filter(|i| i.severity == Severity::Error)
        .inspect(|i| {
            assert_eq!(i.kind, IssueKind::BadCalibration);
            assert_eq!(i.file, Path::new("calibration/target.ron"));
        })
        .map(|i| (i.field, i.message))
        .collect()
}

#[test]
fn a_valid_target_reads_back() {
    let (_dir, root) = bundle_with(&ron_of(&target()), &["view-00.png", "view-01.png"]);
    assert!(calibration_errors(&root).is_empty());
    assert_eq!(read_calibration_target(&root).unwrap(), Some(target()));
    assert!(
        read_bundle(&root)
            .unwrap()
            .campaign
            .calibration_dir
            .is_some()
    );
    // No target description: nothing to read, nothing wrong.
    assert_eq!(read_calibration_target(tiny()).unwrap(), None);
}

#[test]
fn a_missing_image_is_an_error() {
    let (_dir, root) = bundle_with(&ron_of(&target()), &["view-00.png"]);
    let errors = calibration_errors(&root);
    assert_eq!(errors.len(), 1, "{errors:?}");
    assert_eq!(errors[0].0.as_deref(), Some("images"));
    assert!(errors[0].1.contains("view-01.png"));
    assert!(matches!(
        read_calibration_target(&root),
        Err(BundleError::Invalid { .. })
    ));
}

#[test]
fn unusable_values_and_unknown_fields_are_errors() {
    let bad = CalibrationTarget {
        face_view: 2,
        dot_diameter: 0.01,
        ..target()
    };
    let (_dir, root) = bundle_with(&ron_of(&bad), &["view-00.png", "view-01.png"]);
    let fields: Vec<_> = calibration_errors(&root)
        .into_iter()
        .map(|(field, _)| field.unwrap())
        .collect();
    assert_eq!(fields, vec!["dot_diameter", "face_view"]);

    // A side of a thousand dots is accepted; beyond, a typing error.
    for (columns, refused) in [(1000, false), (1001, true), (4_294_967_295, true)] {
        let many = CalibrationTarget {
            columns,
            ..target()
        };
        let (_dir, root) = bundle_with(&ron_of(&many), &["view-00.png", "view-01.png"]);
        let errors = calibration_errors(&root);
        assert_eq!(!errors.is_empty(), refused, "{columns}: {errors:?}");
    }

    let text = ron_of(&target()).replace("pitch:", "spacing: 1.0,\n    pitch:");
    let (_dir, root) = bundle_with(&text, &["view-00.png", "view-01.png"]);
    let errors = calibration_errors(&root);
    assert_eq!(errors.len(), 1);
    assert!(errors[0].1.contains("spacing"), "{errors:?}");
}
