//! Reading a whole bundle: validate every file, collect every issue, and
//! hand out the data only when there is no error.

use std::collections::BTreeSet;
use std::ffi::OsString;
use std::fs;
use std::io::ErrorKind;
use std::path::{Path, PathBuf};

use crate::calibration::check_calibration_target;
use crate::campaign::{Campaign, FrameFile, LoadedBundle, MarkerSet, MarkerTrack, TrialData};
use crate::error::BundleError;
use crate::grey_png::grey_png_problem;
use crate::layout::{
    CALIBRATION, COMPRESSION, FRAMES, MANIFEST, MARKERS, MARKERS_REST, TOOL, TRIALS,
    parse_frame_file_name, trial_id_problem,
};
use crate::parse_manifest::parse_manifest;
use crate::read_tables::{Extent, read_compression, read_markers, read_markers_rest, read_tool};
use crate::report::{Collector, IssueKind, Severity, ValidationReport};
use crate::types::Bundle;

/// Reads and validates the bundle at `path`.
///
/// Every file is checked before anything is returned. On success the loaded
/// bundle carries the warnings; if there is any error, the result is
/// [`BundleError::Invalid`] with the full report (errors and warnings).
pub fn read_bundle(path: impl AsRef<Path>) -> Result<LoadedBundle, BundleError> {
    let root = path.as_ref();
    let (campaign, report) = load(root);
    match campaign {
        Some(campaign) if !report.has_errors() => Ok(LoadedBundle {
            root: root.to_path_buf(),
            campaign,
            warnings: report,
        }),
        _ => Err(BundleError::Invalid { report }),
    }
}

/// Validates the bundle at `path` and returns every issue found; an empty
/// report means the bundle is clean.
pub fn validate_bundle(path: impl AsRef<Path>) -> ValidationReport {
    load(path.as_ref()).1
}

/// Reads a lone `markers.csv` (for instance one a tracker wrote), checking
/// everything that does not need the rest of a bundle (marker ids are not
/// checked against a `markers_rest.csv`). Returns the track and its warnings.
pub fn read_markers_csv(
    path: impl AsRef<Path>,
) -> Result<(MarkerTrack, ValidationReport), BundleError> {
    let path = path.as_ref();
    let mut issues = Collector::default();
    let name = PathBuf::from(path.file_name().unwrap_or(path.as_os_str()));
    let track = read_markers(path, &name, None, None, &mut issues);
    let report = issues.finish(path);
    match track {
        Some(track) if !report.has_errors() => Ok((track, report)),
        _ => Err(BundleError::Invalid { report }),
    }
}

/// Reads everything, returning the campaign only when there was no error.
fn load(root: &Path) -> (Option<Campaign>, ValidationReport) {
    let mut issues = Collector::default();
    if !root.is_dir() {
        issues.add(
            Severity::Error,
            IssueKind::MissingFile,
            Path::new("."),
            None,
            None,
            "the bundle folder does not exist or is not a folder".to_owned(),
        );
        return (None, issues.finish(root));
    }
    check_entries(
        root,
        Path::new(""),
        &[MANIFEST, MARKERS_REST, TRIALS, CALIBRATION, COMPRESSION],
        &mut issues,
    );

    let manifest = read_manifest(root, &mut issues);
    let extent = manifest.as_ref().and_then(|b| Extent::of(&b.phantom));

    let rest_file = Path::new(MARKERS_REST);
    let rest = match Entry::at(&root.join(rest_file)) {
        Entry::File => read_markers_rest(&root.join(rest_file), rest_file, extent, &mut issues),
        Entry::Missing => {
            missing(rest_file, "the markers at rest are required", &mut issues);
            None
        }
        unreadable => unreadable.report_not_a_file(rest_file, &mut issues),
    };

    let trials = read_trials(root, manifest.as_ref(), rest.as_ref(), extent, &mut issues);

    let compression_file = Path::new(COMPRESSION);
    let compression = match Entry::at(&root.join(compression_file)) {
        Entry::File => {
            read_compression(&root.join(compression_file), compression_file, &mut issues)
        }
        Entry::Missing => None,
        unreadable => unreadable.report_not_a_file(compression_file, &mut issues),
    };

    let calibration = root.join(CALIBRATION);
    let calibration_dir = if calibration.is_dir() {
        check_calibration_target(root, &mut issues);
        Some(calibration)
    } else {
        if calibration.exists() {
            issues.add(
                Severity::Warning,
                IssueKind::Suspicious,
                Path::new(CALIBRATION),
                None,
                None,
                "calibration is not a folder; ignored".to_owned(),
            );
        }
        None
    };

    let campaign = match (issues.has_errors(), manifest, rest) {
        (false, Some(manifest), Some(markers_rest)) => Some(Campaign {
            name: manifest.name,
            phantom: manifest.phantom,
            noise: manifest.noise,
            markers_rest,
            trials,
            compression,
            calibration_dir,
        }),
        _ => None,
    };
    (campaign, issues.finish(root))
}

/// What is at a path the format names.
#[derive(Debug)]
enum Entry {
    Missing,
    File,
    Folder,
    /// Something that exists but is neither: a dangling link, a pipe, a
    /// device, or what could not be examined; why.
    Other(String),
}

impl Entry {
    fn at(path: &Path) -> Self {
        match fs::metadata(path) {
            Ok(meta) if meta.is_file() => Self::File,
            Ok(meta) if meta.is_dir() => Self::Folder,
            Ok(_) => Self::Other("is not a regular file (a pipe, socket or device)".to_owned()),
            Err(err) if err.kind() == ErrorKind::NotFound => {
                if fs::symlink_metadata(path).is_ok() {
                    Self::Other("is a symbolic link to nothing".to_owned())
                } else {
                    Self::Missing
                }
            }
            Err(err) => Self::Other(format!("cannot be examined: {err}")),
        }
    }

    /// Reports a file the format names that exists but cannot be read as
    /// one (reading a pipe could block for ever, so it is not tried); its
    /// data are not there, so it is an error, never a silent skip.
    fn report_not_a_file<T>(self, file: &Path, issues: &mut Collector) -> Option<T> {
        let why = match self {
            Self::Folder => "is a folder, not a file".to_owned(),
            Self::Other(why) => why,
            Self::Missing | Self::File => unreachable!("only entries that are not files"),
        };
        issues.add(
            Severity::Error,
            IssueKind::Io,
            file,
            None,
            None,
            format!("exists but cannot be read: it {why}"),
        );
        None
    }
}

fn missing(file: &Path, why: &str, issues: &mut Collector) {
    issues.add(
        Severity::Error,
        IssueKind::MissingFile,
        file,
        None,
        None,
        format!("the file is missing; {why}"),
    );
}

fn read_manifest(root: &Path, issues: &mut Collector) -> Option<Bundle> {
    let file = Path::new(MANIFEST);
    match fs::read_to_string(root.join(file)) {
        Ok(text) => parse_manifest(text.strip_prefix('\u{feff}').unwrap_or(&text), file, issues),
        Err(err) => {
            let (kind, message) = match err.kind() {
                ErrorKind::NotFound => (
                    IssueKind::MissingFile,
                    "the file is missing; every bundle has a manifest".to_owned(),
                ),
                ErrorKind::InvalidData => (
                    IssueKind::ManifestSyntax,
                    "the file is not UTF-8 text".to_owned(),
                ),
                _ => (IssueKind::Io, format!("cannot read: {err}")),
            };
            issues.add(Severity::Error, kind, file, None, None, message);
            None
        }
    }
}

/// Warns about entries of a folder that the format does not define (they are
/// ignored; a typo in a file name would otherwise lose data silently).
/// Hidden entries (leading dot) are skipped.
fn check_entries(dir: &Path, relative: &Path, known: &[&str], issues: &mut Collector) {
    let Ok(entries) = fs::read_dir(dir) else {
        return;
    };
    let mut unknown: Vec<String> = entries
        .filter_map(Result::ok)
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|name| !name.starts_with('.') && !known.contains(&name.as_str()))
        .collect();
    unknown.sort();
    for name in unknown {
        issues.add(
            Severity::Warning,
            IssueKind::Suspicious,
            &relative.join(&name),
            None,
            None,
            format!(
                "not part of the bundle format (expected entries: {}); ignored",
                known.join(", ")
            ),
        );
    }
}

/// Reads the trials the manifest lists, in its order, and checks that the
/// folders under `trials/` match the list. Without a manifest, the folders
/// found are still validated.
fn read_trials(
    root: &Path,
    manifest: Option<&Bundle>,
    rest: Option<&MarkerSet>,
    extent: Option<Extent>,
    issues: &mut Collector,
) -> Vec<TrialData> {
    let trials_dir = root.join(TRIALS);
    let mut on_disk = BTreeSet::new();
    // Folders whose names are not UTF-8: no manifest id can list them.
    let mut not_text: Vec<OsString> = Vec::new();
    match fs::read_dir(&trials_dir) {
        Ok(entries) => {
            for entry in entries {
                let entry = match entry {
                    Ok(entry) => entry,
                    Err(err) => {
                        issues.add(
                            Severity::Error,
                            IssueKind::Io,
                            Path::new(TRIALS),
                            None,
                            None,
                            format!("cannot list: {err}"),
                        );
                        break;
                    }
                };
                let name = entry.file_name().to_string_lossy().into_owned();
                if name.starts_with('.') {
                    continue;
                }
                if entry.path().is_dir() {
                    match entry.file_name().into_string() {
                        Ok(name) => on_disk.insert(name),
                        Err(raw) => {
                            not_text.push(raw);
                            true
                        }
                    };
                } else {
                    issues.add(
                        Severity::Warning,
                        IssueKind::Suspicious,
                        &Path::new(TRIALS).join(&name),
                        None,
                        None,
                        "not a trial folder; ignored".to_owned(),
                    );
                }
            }
        }
        Err(err) if err.kind() == ErrorKind::NotFound => {}
        Err(err) => issues.add(
            Severity::Error,
            IssueKind::Io,
            Path::new(TRIALS),
            None,
            None,
            format!("cannot list: {err}"),
        ),
    }

    not_text.sort();
    for raw in &not_text {
        let relative = Path::new(TRIALS).join(raw);
        issues.add(
            Severity::Error,
            IssueKind::UnlistedTrialFolder,
            &relative,
            None,
            None,
            "trial folder's name is not UTF-8 text, so bundle.ron cannot list it".to_owned(),
        );
        read_trial(&trials_dir.join(raw), &relative, rest, extent, issues);
    }
    let read_named = |name: &str, issues: &mut Collector| {
        let dir = crate::layout::trial_dir(root, name);
        read_trial(&dir, &Path::new(TRIALS).join(name), rest, extent, issues)
    };
    let Some(manifest) = manifest else {
        for name in &on_disk {
            read_named(name, issues);
        }
        return Vec::new();
    };
    let listed: BTreeSet<&str> = manifest.trials.iter().map(|t| t.id.as_str()).collect();
    for name in on_disk.iter().filter(|n| !listed.contains(n.as_str())) {
        issues.add(
            Severity::Error,
            IssueKind::UnlistedTrialFolder,
            &Path::new(TRIALS).join(name),
            None,
            None,
            format!("trial folder {name:?} is not listed in bundle.ron"),
        );
        read_named(name, issues);
    }
    let mut trials = Vec::with_capacity(manifest.trials.len());
    let mut read_ids = BTreeSet::new();
    for trial in &manifest.trials {
        // A bad id was reported with the manifest; never follow it on disk.
        // A duplicate id was reported too; its folder is read once.
        if trial_id_problem(&trial.id).is_some() || !read_ids.insert(trial.id.as_str()) {
            continue;
        }
        if !on_disk.contains(&trial.id) {
            issues.add(
                Severity::Error,
                IssueKind::MissingTrialFolder,
                &Path::new(TRIALS).join(&trial.id),
                None,
                None,
                format!(
                    "bundle.ron lists trial {:?} but there is no folder trials/{}",
                    trial.id, trial.id
                ),
            );
            continue;
        }
        let (tool, markers, frames) = read_named(&trial.id, issues);
        trials.push(TrialData {
            trial: trial.clone(),
            tool,
            markers,
            frames,
        });
    }
    trials
}

/// Reads the trial folder `dir`, `relative` to the bundle root.
fn read_trial(
    dir: &Path,
    relative: &Path,
    rest: Option<&MarkerSet>,
    extent: Option<Extent>,
    issues: &mut Collector,
) -> (Vec<crate::ToolSample>, Option<MarkerTrack>, Vec<FrameFile>) {
    check_entries(dir, relative, &[TOOL, MARKERS, FRAMES], issues);

    let tool_file = relative.join(TOOL);
    let tool = match Entry::at(&dir.join(TOOL)) {
        Entry::File => read_tool(&dir.join(TOOL), &tool_file, extent, issues).unwrap_or_default(),
        Entry::Missing => {
            missing(&tool_file, "every trial has its tool samples", issues);
            Vec::new()
        }
        unreadable => unreadable
            .report_not_a_file(&tool_file, issues)
            .unwrap_or_default(),
    };

    let markers_file = relative.join(MARKERS);
    let markers = match Entry::at(&dir.join(MARKERS)) {
        Entry::File => read_markers(&dir.join(MARKERS), &markers_file, rest, extent, issues),
        Entry::Missing => None,
        unreadable => unreadable.report_not_a_file(&markers_file, issues),
    };

    let frames_dir = dir.join(FRAMES);
    let frames = match Entry::at(&frames_dir) {
        Entry::Folder => list_frames(&frames_dir, &relative.join(FRAMES), issues),
        Entry::Missing => Vec::new(),
        _ => {
            issues.add(
                Severity::Warning,
                IssueKind::Suspicious,
                &relative.join(FRAMES),
                None,
                None,
                "frames is not a folder; ignored".to_owned(),
            );
            Vec::new()
        }
    };
    (tool, markers, frames)
}

/// The `NNNNNN.png` files of a frames folder, sorted by number.
fn list_frames(dir: &Path, relative: &Path, issues: &mut Collector) -> Vec<FrameFile> {
    let entries = match fs::read_dir(dir) {
        Ok(entries) => entries,
        Err(err) => {
            issues.add(
                Severity::Error,
                IssueKind::Io,
                relative,
                None,
                None,
                format!("cannot list: {err}"),
            );
            return Vec::new();
        }
    };
    let mut frames = Vec::new();
    let mut strays = Vec::new();
    for entry in entries.filter_map(Result::ok) {
        let name = entry.file_name().to_string_lossy().into_owned();
        match parse_frame_file_name(&name) {
            Some(number) if entry.path().is_file() => {
                // Named by the folder so that a thousand bad frames are
                // listed up to the cap, then counted.
                if let Some(problem) = grey_png_problem(&entry.path()) {
                    issues.add(
                        Severity::Error,
                        IssueKind::BadFrame,
                        relative,
                        None,
                        None,
                        format!("{name} {problem}"),
                    );
                }
                frames.push(FrameFile {
                    number,
                    path: entry.path(),
                });
            }
            _ if name.starts_with('.') => {}
            _ => strays.push(name),
        }
    }
    strays.sort();
    for name in strays {
        issues.add(
            Severity::Warning,
            IssueKind::Suspicious,
            &relative.join(&name),
            None,
            None,
            "not a frame file (six digits and .png, like 000042.png); ignored".to_owned(),
        );
    }
    if frames.is_empty() {
        issues.add(
            Severity::Warning,
            IssueKind::Suspicious,
            relative,
            None,
            None,
            "the frames folder holds no frame".to_owned(),
        );
    }
    frames.sort_by_key(|f| f.number);
    frames
}
