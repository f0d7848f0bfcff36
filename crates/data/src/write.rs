//! Writing bundles and lone `markers.csv` files, atomically.
//!
//! Everything is first written to a hidden sibling of the destination, then
//! validated by the same reader every consumer uses, and only then renamed to
//! its final name. A failed or invalid write therefore never leaves a
//! half-written bundle under the final name, and what is published always
//! reads back. Replacing an existing bundle must be asked for
//! ([`Overwrite::Allow`]); even then the old bundle is only moved aside, and
//! deleted once the new one is in place.

use std::fmt::Write as _;
use std::fs::{self, File};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use crate::campaign::{Campaign, MarkerTrack};
use crate::error::BundleError;
use crate::layout::{
    CALIBRATION, COMPRESSION, COMPRESSION_HEADER, MANIFEST, MARKERS, MARKERS_HEADER, MARKERS_REST,
    MARKERS_REST_HEADER, MARKERS_SIGMA_COLUMNS, TOOL, TOOL_HEADER, frame_file_name, frames_dir,
    trial_dir, trial_id_problem,
};
use crate::read::validate_bundle;
use crate::read_tables::read_markers;
use crate::report::{Collector, ValidationReport};
use crate::types::MarkerObservation;

/// Whether a write may replace what is already at its destination.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Overwrite {
    /// Fail with [`BundleError::AlreadyExists`] if the destination exists.
    #[default]
    Deny,
    /// Replace the destination (atomically: the old one is moved aside, the
    /// new one renamed into place, then the old one deleted). A folder is
    /// only replaced if it is a bundle (it has a `bundle.ron`).
    Allow,
}

/// Options of [`write_bundle`] and [`write_markers_csv`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct WriteOptions {
    /// Whether an existing destination may be replaced.
    pub overwrite: Overwrite,
}

impl WriteOptions {
    /// Options that replace an existing destination.
    pub fn overwrite() -> Self {
        Self {
            overwrite: Overwrite::Allow,
        }
    }
}

/// Writes `campaign` as a bundle folder at `path`.
///
/// Frame files and the calibration folder are copied from where the campaign
/// says they are. The bundle is validated before it gets its final name; if
/// validation finds an error, nothing is published and the result is
/// [`BundleError::Invalid`] with the report.
pub fn write_bundle(
    path: impl AsRef<Path>,
    campaign: &Campaign,
    options: WriteOptions,
) -> Result<(), BundleError> {
    let target = path.as_ref();
    let replace = check_destination(target, options, true)?;
    let staging = Staging::create(target, true)?;
    write_contents(&staging.path, campaign)?;
    let report = validate_bundle(&staging.path);
    if report.has_errors() {
        return Err(BundleError::Invalid {
            report: ValidationReport {
                root: target.to_path_buf(),
                ..report
            },
        });
    }
    staging.publish(target, replace)
}

/// Writes one trial's tracked markers as a `markers.csv` at `path`, rows in
/// the given order (rows of one frame must be consecutive).
///
/// The file is validated (everything but marker ids, which need the bundle's
/// `markers_rest.csv`) before it gets its final name.
pub fn write_markers_csv(
    path: impl AsRef<Path>,
    rows: &[MarkerObservation],
    options: WriteOptions,
) -> Result<(), BundleError> {
    let target = path.as_ref();
    let with_sigma = rows.first().is_some_and(|r| r.sigma.is_some());
    if let Some(row) = rows.iter().position(|r| r.sigma.is_some() != with_sigma) {
        return Err(BundleError::MixedSigma { row });
    }
    let replace = check_destination(target, options, false)?;
    let staging = Staging::create(target, false)?;
    write_table(
        &staging.path,
        &markers_header(with_sigma),
        rows.iter(),
        |line, r| {
            push_observation(line, r);
        },
    )?;
    let mut issues = Collector::default();
    let name = PathBuf::from(target.file_name().unwrap_or(target.as_os_str()));
    read_markers(&staging.path, &name, None, None, &mut issues);
    let report = issues.finish(target);
    if report.has_errors() {
        return Err(BundleError::Invalid { report });
    }
    staging.publish(target, replace)
}

/// Checks what is at the destination; true when it exists and will be
/// replaced.
fn check_destination(
    target: &Path,
    options: WriteOptions,
    bundle: bool,
) -> Result<bool, BundleError> {
    if fs::symlink_metadata(target).is_err() {
        return Ok(false);
    }
    if options.overwrite == Overwrite::Deny {
        return Err(BundleError::AlreadyExists {
            path: target.to_path_buf(),
        });
    }
    let replaceable = if bundle {
        target.join(MANIFEST).is_file()
    } else {
        target.is_file()
    };
    if replaceable {
        Ok(true)
    } else {
        Err(BundleError::NotABundle {
            path: target.to_path_buf(),
        })
    }
}

/// A hidden sibling of the destination that is written first and removed
/// unless it is published.
struct Staging {
    path: PathBuf,
    is_dir: bool,
    published: bool,
}

impl Staging {
    fn create(target: &Path, is_dir: bool) -> Result<Self, BundleError> {
        let path = sibling(target, "writing");
        if let Some(parent) = path.parent() {
            fs::create_dir_all(parent).map_err(BundleError::io(parent))?;
        }
        if is_dir {
            fs::create_dir(&path).map_err(BundleError::io(&path))?;
        }
        Ok(Self {
            path,
            is_dir,
            published: false,
        })
    }

    /// Renames the staged copy to `target`, moving an existing one aside
    /// first when `replace` is set.
    fn publish(mut self, target: &Path, replace: bool) -> Result<(), BundleError> {
        if replace && self.is_dir {
            // A folder cannot be renamed over a non-empty folder: move the
            // old bundle aside, put the new one in place, then delete the old.
            let old = sibling(target, "replaced");
            fs::rename(target, &old).map_err(BundleError::io(target))?;
            if let Err(source) = fs::rename(&self.path, target) {
                // Best effort to put things back as they were; the error
                // reported is the one that matters.
                let _ = fs::rename(&old, target);
                return Err(BundleError::Io {
                    path: target.to_path_buf(),
                    source,
                });
            }
            self.published = true;
            fs::remove_dir_all(&old).map_err(BundleError::io(old))
        } else {
            // Renaming a file over a file is atomic; without `replace` the
            // destination did not exist when checked.
            fs::rename(&self.path, target).map_err(BundleError::io(target))?;
            self.published = true;
            Ok(())
        }
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        if !self.published {
            // Nothing else can be done about a failed clean-up of a hidden
            // scratch copy; the destination is untouched either way.
            let _ = if self.is_dir {
                fs::remove_dir_all(&self.path)
            } else {
                fs::remove_file(&self.path)
            };
        }
    }
}

/// `PARENT/.NAME.ROLE-PID-N`: a hidden, unique sibling of `target`.
fn sibling(target: &Path, role: &str) -> PathBuf {
    static COUNTER: AtomicUsize = AtomicUsize::new(0);
    let name = target
        .file_name()
        .map_or_else(|| "bundle".into(), |n| n.to_string_lossy().into_owned());
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let hidden = format!(".{name}.{role}-{}-{n}", std::process::id());
    match target.parent() {
        Some(parent) if !parent.as_os_str().is_empty() => parent.join(hidden),
        _ => PathBuf::from(hidden),
    }
}

fn write_contents(root: &Path, campaign: &Campaign) -> Result<(), BundleError> {
    let manifest = ron::ser::to_string_pretty(
        &campaign.manifest(),
        ron::ser::PrettyConfig::new().struct_names(true),
    )
    .map_err(|err| BundleError::Io {
        path: root.join(MANIFEST),
        source: std::io::Error::other(err),
    })?;
    let manifest_path = root.join(MANIFEST);
    fs::write(&manifest_path, manifest + "\n").map_err(BundleError::io(manifest_path))?;

    write_table(
        &root.join(MARKERS_REST),
        &MARKERS_REST_HEADER.join(","),
        campaign.markers_rest.as_slice().iter(),
        |line, m| {
            let _ = write!(line, "{},{:?},{:?}", m.id, m.x, m.y);
        },
    )?;

    for data in &campaign.trials {
        let id = &data.trial.id;
        // An id that cannot name a folder is left to validation to report;
        // it must never make us write outside the bundle.
        if trial_id_problem(id).is_some() {
            continue;
        }
        let dir = trial_dir(root, id);
        fs::create_dir_all(&dir).map_err(BundleError::io(&dir))?;
        write_table(
            &dir.join(TOOL),
            &TOOL_HEADER.join(","),
            data.tool.iter(),
            |line, s| {
                let _ = write!(
                    line,
                    "{:?},{:?},{:?},{:?},{:?},{:?},{:?}",
                    s.t, s.tip_x, s.tip_y, s.theta, s.fx, s.fy, s.mz
                );
            },
        )?;
        if let Some(track) = &data.markers {
            write_track(&dir.join(MARKERS), track)?;
        }
        if !data.frames.is_empty() {
            let frames = frames_dir(root, id);
            fs::create_dir_all(&frames).map_err(BundleError::io(&frames))?;
            for frame in &data.frames {
                let name = frame_file_name(frame.number).ok_or(BundleError::FrameNumber {
                    number: frame.number,
                })?;
                fs::copy(&frame.path, frames.join(name)).map_err(BundleError::io(&frame.path))?;
            }
        }
    }

    if let Some(curve) = &campaign.compression {
        write_table(
            &root.join(COMPRESSION),
            &COMPRESSION_HEADER.join(","),
            curve.iter(),
            |line, p| {
                let _ = write!(line, "{:?},{:?}", p.strain, p.stress);
            },
        )?;
    }
    if let Some(source) = &campaign.calibration_dir {
        copy_tree(source, &root.join(CALIBRATION))?;
    }
    Ok(())
}

fn markers_header(with_sigma: bool) -> String {
    let mut columns = MARKERS_HEADER.to_vec();
    if with_sigma {
        columns.extend_from_slice(MARKERS_SIGMA_COLUMNS);
    }
    columns.join(",")
}

fn write_track(path: &Path, track: &MarkerTrack) -> Result<(), BundleError> {
    write_table(
        path,
        &markers_header(track.has_sigma()),
        track.observations(),
        |line, r| push_observation(line, &r),
    )
}

fn push_observation(line: &mut String, r: &MarkerObservation) {
    let _ = write!(line, "{},{:?},{},{:?},{:?}", r.frame, r.t, r.id, r.x, r.y);
    if let Some([sx, sy]) = r.sigma {
        let _ = write!(line, ",{sx:?},{sy:?}");
    }
}

/// Writes a CSV table: the header, then one line per item. Numbers are
/// written with `{:?}`, the shortest text that parses back to the same
/// `f64`, so tables round-trip exactly. One line buffer is reused.
fn write_table<T>(
    path: &Path,
    header: &str,
    rows: impl Iterator<Item = T>,
    mut format_row: impl FnMut(&mut String, T),
) -> Result<(), BundleError> {
    let file = File::create(path).map_err(BundleError::io(path))?;
    let mut out = BufWriter::with_capacity(1 << 16, file);
    let mut line = String::with_capacity(128);
    let result = (|| {
        writeln!(out, "{header}")?;
        for row in rows {
            line.clear();
            format_row(&mut line, row);
            line.push('\n');
            out.write_all(line.as_bytes())?;
        }
        out.flush()
    })();
    result.map_err(BundleError::io(path))
}

fn copy_tree(source: &Path, destination: &Path) -> Result<(), BundleError> {
    fs::create_dir_all(destination).map_err(BundleError::io(destination))?;
    for entry in fs::read_dir(source).map_err(BundleError::io(source))? {
        let entry = entry.map_err(BundleError::io(source))?;
        let from = entry.path();
        let to = destination.join(entry.file_name());
        if from.is_dir() {
            copy_tree(&from, &to)?;
        } else {
            fs::copy(&from, &to).map_err(BundleError::io(&from))?;
        }
    }
    Ok(())
}
