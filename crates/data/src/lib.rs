//! needle-data: the measurement bundle, format 1 — its types, reader, writer
//! and validation.
//!
//! A measurement bundle is one folder holding everything measured in one
//! campaign on one phantom: the manifest `bundle.ron`, the markers at rest
//! `markers_rest.csv`, and per trial the tool samples `tool.csv`, optionally
//! the tracked markers `markers.csv` and the raw frames `frames/NNNNNN.png`,
//! plus an optional `compression.csv` and `calibration/` folder. The format
//! is specified in `docs/measurement-bundle.md`; all quantities are SI.
//!
//! # Where it sits
//!
//! At the bottom of the chain: every other crate (fem, vision, synth,
//! identify, force, diagnose) and the `xtask` pipeline read bundles through
//! [`read_bundle`], and the synthetic generator and the tracker write them
//! through [`BundleBuilder`] / [`write_bundle`] and [`write_markers_csv`].
//! It depends on no other crate of the project.
//!
//! It does not decode images (frames are listed, sorted, and copied as
//! files, and only their PNG headers are checked; the vision crate decodes
//! them), interpret the measurements, or write into a bundle it reads.
//!
//! # Error model
//!
//! Reading validates the whole bundle before returning anything and collects
//! every problem, not just the first: each [`Issue`] has a [`Severity`], an
//! [`IssueKind`], the file (relative to the bundle root), the line and the
//! field or column when they apply, and a message a lab engineer can act on.
//!
//! - **Errors** make the bundle unusable: unparsable or non-finite numbers,
//!   wrong CSV headers or row lengths, marker ids missing from
//!   `markers_rest.csv` or defined twice, time or frame numbers going
//!   backwards, the same marker twice in a frame, trial folders the manifest
//!   does not list (or listed trials without a folder), duplicate trial ids,
//!   files the format names that exist but cannot be read (a folder, a link
//!   to nothing or a pipe where a file belongs), frames that are not PNGs of
//!   8- or 16-bit grey, unknown, missing or duplicate manifest fields, an
//!   unsupported format version, non-physical values (a phantom size
//!   `<= 0`, a negative speed, day or standard deviation). [`read_bundle`]
//!   then returns [`BundleError::Invalid`] carrying the full
//!   [`ValidationReport`].
//! - **Warnings** flag what is legal but suspicious, chiefly magnitudes that
//!   do not look like SI units (coordinates far larger than the phantom,
//!   forces in the kilonewton range, speeds above 1 m/s, angles above a full
//!   turn, trials longer than an hour) and files the format does not define.
//!   A bundle with only warnings reads; the warnings come with it in
//!   [`LoadedBundle::warnings`].
//!
//! RON stops at its first structural error, so `bundle.ron` contributes at
//! most one unknown/missing-field or syntax error per run; once it parses,
//! all its values are checked. Issues repeated many times in one file are
//! listed up to 20 times per kind, then counted.
//!
//! Writing goes through a hidden sibling folder that is validated by the
//! same reader and then renamed into place, so no half-written or invalid
//! bundle ever appears under its final name, and an existing bundle is only
//! replaced when [`Overwrite::Allow`] is given.
//!
//! # Example
//!
//! ```no_run
//! use needle_data::{BundleError, read_bundle};
//!
//! match read_bundle("fixtures/bundles/tiny") {
//!     Ok(bundle) => {
//!         for warning in bundle.warnings.warnings() {
//!             eprintln!("{warning}");
//!         }
//!         let trial = bundle.trial("probe-01").expect("listed trial");
//!         println!("{} tool samples", trial.tool.len());
//!         if let Some(track) = &trial.markers {
//!             for frame in track.frames() {
//!                 let marker_0 = frame.position(0); // Option<[x, y]>
//!                 println!("frame {} at {} s: marker 0 at {marker_0:?}", frame.frame, frame.t);
//!             }
//!         }
//!     }
//!     Err(BundleError::Invalid { report }) => eprintln!("{report}"),
//!     Err(other) => eprintln!("{other}"),
//! }
//! ```
//!
//! # Fuzzing
//!
//! `crates/data/fuzz/` holds a `cargo fuzz` target for the readers (outside
//! the workspace, not run in CI). With a nightly toolchain and `cargo-fuzz`
//! installed (`cargo install cargo-fuzz`):
//!
//! ```text
//! cd crates/data/fuzz
//! cargo +nightly fuzz run read_bundle -- -max_total_time=60
//! ```
//!
//! Last run on 2026-12-07, on the reader and target as they are now:
//! 262,931 inputs in 17 minutes, no failure (and 855,480 inputs in 44
//! minutes on the earlier versions of that day).

mod calibration;
mod campaign;
mod error;
mod grey_png;
pub mod layout;
mod line_breaks;
mod parse_manifest;
mod parse_table;
mod read;
mod read_tables;
mod report;
mod ron_lines;
mod types;
mod write;

pub use calibration::{CalibrationTarget, read_calibration_target};
pub use campaign::{
    BundleBuilder, Campaign, FrameFile, FrameView, LoadedBundle, MarkerSet, MarkerTrack, TrialData,
};
pub use error::BundleError;
pub use read::{read_bundle, read_markers_csv, validate_bundle};
pub use report::{Issue, IssueKind, Severity, ValidationReport};
pub use ron_lines::field_lines as ron_field_lines;
pub use types::{
    Bundle, CompressionPoint, FORMAT_VERSION, Face, MarkerObservation, MarkerRest, Noise, Phantom,
    ToolSample, Trial, TrialKind,
};
pub use write::{Overwrite, WriteOptions, write_bundle, write_markers_csv};
