//! Helpers shared by the integration tests that start from the tiny
//! fixture bundle.

use std::fs;
use std::path::{Path, PathBuf};

/// The tiny valid bundle under `fixtures/bundles/`.
pub fn tiny() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/bundles/tiny")
}

/// Copies a folder tree, for tests that alter a fixture.
pub fn copy_tree(from: &Path, to: &Path) {
    fs::create_dir_all(to).unwrap();
    for entry in fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.path().is_dir() {
            copy_tree(&entry.path(), &target);
        } else {
            fs::copy(entry.path(), &target).unwrap();
        }
    }
}
