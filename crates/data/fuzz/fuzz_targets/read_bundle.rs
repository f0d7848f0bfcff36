//! Fuzzes the bundle reader: the input is split at NUL bytes into the texts
//! of `bundle.ron`, `markers_rest.csv`, `trials/a/tool.csv`,
//! `trials/a/markers.csv`, `compression.csv` and `calibration/target.ron`
//! (missing parts are missing files), written to a scratch folder and read.
//! Any panic is a bug: bad input must become issues.
#![no_main]

use libfuzzer_sys::fuzz_target;

const FILES: [&str; 6] = [
    "bundle.ron",
    "markers_rest.csv",
    "trials/a/tool.csv",
    "trials/a/markers.csv",
    "compression.csv",
    "calibration/target.ron",
];

fuzz_target!(|data: &[u8]| {
    let dir = tempfile::tempdir().expect("scratch folder");
    let root = dir.path();
    std::fs::create_dir_all(root.join("trials/a")).expect("trial folder");
    std::fs::create_dir_all(root.join("calibration")).expect("calibration folder");
    for (name, part) in FILES.iter().zip(data.split(|&b| b == 0)) {
        std::fs::write(root.join(name), part).expect("scratch file");
    }
    let report = needle_data::validate_bundle(root);
    match needle_data::read_bundle(root) {
        Ok(bundle) => assert!(!report.has_errors() && bundle.warnings == report),
        Err(needle_data::BundleError::Invalid { report: again }) => assert_eq!(again, report),
        Err(other) => panic!("reading a folder of files failed outside validation: {other}"),
    }
    let _ = needle_data::read_markers_csv(root.join(FILES[3]));
});
