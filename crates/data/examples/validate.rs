//! Validates the bundles given on the command line and prints their reports.
//!
//! `cargo run -p needle-data --example validate -- fixtures/bundles/tiny`

fn main() {
    let mut any_errors = false;
    for path in std::env::args().skip(1) {
        let report = needle_data::validate_bundle(&path);
        any_errors |= report.has_errors();
        print!("{report}");
    }
    std::process::exit(i32::from(any_errors));
}
