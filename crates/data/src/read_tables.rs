//! Reading and checking each CSV table of a bundle: `markers_rest.csv`,
//! `tool.csv`, `markers.csv` and `compression.csv`.
//!
//! Every row is checked; rows with errors are reported and left out of the
//! data. Magnitudes that do not look like SI units are tallied over the whole
//! file and reported once per file and check, with the first line and the
//! count, so a file in millimetres gives one warning, not a million.

use std::collections::HashMap;
use std::path::Path;

use crate::campaign::{MarkerSet, MarkerTrack};
use crate::layout::{
    COMPRESSION_HEADER, MARKERS_HEADER, MARKERS_REST_HEADER, MARKERS_SIGMA_COLUMNS, TOOL_HEADER,
};
use crate::parse_table::{Header, Table};
use crate::report::{Collector, IssueKind, Severity, Shown};
use crate::types::{CompressionPoint, MarkerRest, Phantom, ToolSample};

/// Coordinates more than this many phantom sizes from the origin look like
/// millimetres (a factor of 1000 too large).
const MILLIMETRE_FACTOR: f64 = 10.0;
/// Markers at rest may sit this fraction of the phantom size outside it
/// before it is worth a warning.
const REST_MARGIN: f64 = 0.05;
/// Force components above this (N) look like the wrong unit.
const LARGEST_PLAUSIBLE_FORCE: f64 = 1000.0;
/// Moments above this (N m) look like the wrong unit.
const LARGEST_PLAUSIBLE_MOMENT: f64 = 100.0;
/// A trial longer than this (s) looks like its time is in milliseconds.
const LONGEST_PLAUSIBLE_TRIAL: f64 = 3600.0;

/// The phantom's extent, for magnitude checks.
#[derive(Clone, Copy)]
pub(crate) struct Extent {
    width: f64,
    depth: f64,
}

impl Extent {
    /// The extent of a phantom, if its sizes are usable.
    pub(crate) fn of(phantom: &Phantom) -> Option<Self> {
        let usable = |v: f64| v.is_finite() && v > 0.0;
        (usable(phantom.width) && usable(phantom.depth)).then_some(Self {
            width: phantom.width,
            depth: phantom.depth,
        })
    }

    fn size(self) -> f64 {
        self.width.max(self.depth)
    }

    /// True when a coordinate is too far out to be in metres.
    fn looks_like_millimetres(self, value: f64) -> bool {
        value.abs() > MILLIMETRE_FACTOR * self.size()
    }

    fn millimetre_warning(self, worst: Shown) -> String {
        format!(
            "coordinates up to {worst} on a {} m x {} m phantom; are they in millimetres? (SI units are expected)",
            self.width, self.depth
        )
    }
}

/// Occurrences of one suspicious condition over a file.
#[derive(Default)]
struct Tally {
    count: u64,
    first_line: u64,
    worst: f64,
}

impl Tally {
    fn note(&mut self, line: u64, value: f64) {
        if self.count == 0 {
            self.first_line = line;
        }
        self.count += 1;
        if value.abs() > self.worst.abs() {
            self.worst = value;
        }
    }

    /// Reports one warning when the condition occurred.
    fn warn(
        &self,
        issues: &mut Collector,
        kind: IssueKind,
        file: &Path,
        field: &str,
        message: impl FnOnce(Shown) -> String,
    ) {
        if self.count > 0 {
            issues.add(
                Severity::Warning,
                kind,
                file,
                Some(self.first_line),
                Some(field),
                format!(
                    "{} ({} row{}, first at this line)",
                    message(Shown(self.worst)),
                    self.count,
                    if self.count == 1 { "" } else { "s" }
                ),
            );
        }
    }
}

/// Reads `markers_rest.csv`.
pub(crate) fn read_markers_rest(
    path: &Path,
    file: &Path,
    extent: Option<Extent>,
    issues: &mut Collector,
) -> Option<MarkerSet> {
    let header = Header {
        required: MARKERS_REST_HEADER,
        optional: &[],
    };
    let (mut table, _) = Table::open(path, file, &header, issues)?;
    let mut markers = Vec::new();
    let mut line_of_id: HashMap<u32, u64> = HashMap::new();
    let mut millimetres = Tally::default();
    let mut off_phantom = Tally::default();
    let mut rows_seen = 0u64;
    while let Some(row) = table.next_row(issues) {
        rows_seen += 1;
        let id = row.integer::<u32>(0, issues);
        let x = row.real(1, issues);
        let y = row.real(2, issues);
        let (Some(id), Some(x), Some(y)) = (id, x, y) else {
            if let Some(id) = id {
                // Keep the id known, so that markers.csv rows are not blamed
                // for this row's bad coordinates. The bundle is invalid, so
                // this placeholder position is never handed out.
                line_of_id.entry(id).or_insert(row.line);
                markers.push(MarkerRest { id, x: 0.0, y: 0.0 });
            }
            continue;
        };
        if let Some(first) = line_of_id.get(&id) {
            row.issue(
                issues,
                IssueKind::DuplicateMarker,
                0,
                format!("marker id {id} is already defined at line {first}"),
            );
            continue;
        }
        line_of_id.insert(id, row.line);
        if let Some(extent) = extent {
            let worst = if x.abs() > y.abs() { x } else { y };
            if extent.looks_like_millimetres(worst) {
                millimetres.note(row.line, worst);
            } else {
                let margin = REST_MARGIN * extent.size();
                let outside = |v: f64, size: f64| v < -margin || v > size + margin;
                if outside(x, extent.width) || outside(y, extent.depth) {
                    off_phantom.note(row.line, worst);
                }
            }
        }
        markers.push(MarkerRest { id, x, y });
    }
    let file = table.file;
    if let Some(extent) = extent {
        millimetres.warn(issues, IssueKind::Units, file, "x,y", |w| {
            extent.millimetre_warning(w)
        });
        off_phantom.warn(issues, IssueKind::Suspicious, file, "x,y", |_| {
            format!(
                "markers lie outside the {} m x {} m top face",
                extent.width, extent.depth
            )
        });
    }
    if rows_seen == 0 {
        issues.add(
            Severity::Error,
            IssueKind::EmptyTable,
            file,
            None,
            None,
            "no marker rows after the header".to_owned(),
        );
    }
    Some(MarkerSet::new(markers))
}

/// Reads a trial's `tool.csv`.
pub(crate) fn read_tool(
    path: &Path,
    file: &Path,
    extent: Option<Extent>,
    issues: &mut Collector,
) -> Option<Vec<ToolSample>> {
    let header = Header {
        required: TOOL_HEADER,
        optional: &[],
    };
    let (mut table, _) = Table::open(path, file, &header, issues)?;
    let mut samples: Vec<ToolSample> = Vec::new();
    let mut rows_seen = 0u64;
    let mut previous: Option<(f64, u64)> = None;
    let mut repeated_time = Tally::default();
    let mut negative_time = Tally::default();
    let mut millimetres = Tally::default();
    let mut kilonewtons = Tally::default();
    let mut large_moment = Tally::default();
    let mut degrees = Tally::default();
    while let Some(row) = table.next_row(issues) {
        rows_seen += 1;
        let values: [Option<f64>; 7] = std::array::from_fn(|c| row.real(c, issues));
        if values.contains(&None) {
            continue;
        }
        let [t, tip_x, tip_y, theta, fx, fy, mz] = values.map(Option::unwrap_or_default);
        if let Some((before, line)) = previous {
            if t < before {
                row.issue(
                    issues,
                    IssueKind::TimeBackwards,
                    0,
                    format!("time goes backwards: {t} s after {before} s at line {line}"),
                );
                continue;
            }
            if t == before {
                repeated_time.note(row.line, t);
            }
        }
        previous = Some((t, row.line));
        if t < 0.0 {
            negative_time.note(row.line, t);
        }
        if let Some(extent) = extent {
            let worst = if tip_x.abs() > tip_y.abs() {
                tip_x
            } else {
                tip_y
            };
            if extent.looks_like_millimetres(worst) {
                millimetres.note(row.line, worst);
            }
        }
        let force = if fx.abs() > fy.abs() { fx } else { fy };
        if force.abs() > LARGEST_PLAUSIBLE_FORCE {
            kilonewtons.note(row.line, force);
        }
        if mz.abs() > LARGEST_PLAUSIBLE_MOMENT {
            large_moment.note(row.line, mz);
        }
        if theta.abs() > std::f64::consts::TAU {
            degrees.note(row.line, theta);
        }
        samples.push(ToolSample {
            t,
            tip_x,
            tip_y,
            theta,
            fx,
            fy,
            mz,
        });
    }
    let file = table.file;
    repeated_time.warn(issues, IssueKind::Suspicious, file, "t", |_| {
        "two samples share a time stamp".to_owned()
    });
    negative_time.warn(issues, IssueKind::Suspicious, file, "t", |w| {
        format!("negative time {w} s; t counts from the start of the trial")
    });
    if let Some(extent) = extent {
        millimetres.warn(issues, IssueKind::Units, file, "tip_x,tip_y", |w| {
            extent.millimetre_warning(w)
        });
    }
    kilonewtons.warn(issues, IssueKind::Units, file, "fx,fy", |w| {
        format!("forces up to {w} N are in the kilonewton range; are they in other units? (newtons are expected)")
    });
    large_moment.warn(issues, IssueKind::Units, file, "mz", |w| {
        format!("moments up to {w} N m are implausibly large; newton metres are expected")
    });
    degrees.warn(issues, IssueKind::Units, file, "theta", |w| {
        format!("angles up to {w} exceed a full turn; are they in degrees? (radians are expected)")
    });
    if let (Some(first), Some(last)) = (samples.first(), samples.last()) {
        warn_if_long(last.t - first.t, file, issues);
    }
    if rows_seen == 0 {
        issues.add(
            Severity::Error,
            IssueKind::EmptyTable,
            file,
            None,
            None,
            "no sample rows after the header".to_owned(),
        );
    }
    Some(samples)
}

/// How `markers.csv` ids are mapped to a dense index, for duplicate checks.
enum IdIndex<'m> {
    /// Ids must be in the rest set.
    Known(&'m MarkerSet),
    /// No rest set could be read: every id is accepted and numbered on sight.
    Open(HashMap<u32, usize>),
}

impl IdIndex<'_> {
    fn index(&mut self, id: u32) -> Option<usize> {
        match self {
            Self::Known(set) => set.index_of(id),
            Self::Open(seen) => {
                let next = seen.len();
                Some(*seen.entry(id).or_insert(next))
            }
        }
    }
}

/// Reads a trial's `markers.csv` (or a lone markers file when `rest` is
/// `None`, in which case ids are not checked against a rest set).
pub(crate) fn read_markers(
    path: &Path,
    file: &Path,
    rest: Option<&MarkerSet>,
    extent: Option<Extent>,
    issues: &mut Collector,
) -> Option<MarkerTrack> {
    let header = Header {
        required: MARKERS_HEADER,
        optional: MARKERS_SIGMA_COLUMNS,
    };
    let (mut table, with_sigma) = Table::open(path, file, &header, issues)?;
    let mut ids = match rest {
        Some(set) => IdIndex::Known(set),
        None => IdIndex::Open(HashMap::new()),
    };
    let mut track = MarkerTrack::default();
    if with_sigma {
        track = track.with_sigma();
    }
    // For each marker index: the ordinal (1-based) of the last frame it was
    // seen in, and on which line.
    let mut last_seen: Vec<(u32, u64)> = vec![(0, 0); rest.map_or(0, MarkerSet::len)];
    // The frame being read: number, time, ordinal, first line.
    let mut current: Option<(u64, f64, u32, u64)> = None;
    let mut rows_seen = 0u64;
    let mut repeated_time = Tally::default();
    let mut negative_time = Tally::default();
    let mut millimetres = Tally::default();
    let mut large_sigma = Tally::default();
    // Times of the first and the last frame.
    let mut span: Option<[f64; 2]> = None;
    while let Some(row) = table.next_row(issues) {
        rows_seen += 1;
        let frame = row.integer::<u64>(0, issues);
        let t = row.real(1, issues);
        let id = row.integer::<u32>(2, issues);
        let x = row.real(3, issues);
        let y = row.real(4, issues);
        let sigma = if with_sigma {
            let sx = row.real(5, issues);
            let sy = row.real(6, issues);
            for (column, value) in [(5, sx), (6, sy)] {
                if let Some(value) = value.filter(|v| *v < 0.0) {
                    row.issue(
                        issues,
                        IssueKind::NonPhysical,
                        column,
                        format!("standard deviation {value} is negative"),
                    );
                }
            }
            match (sx, sy) {
                (Some(sx), Some(sy)) if sx >= 0.0 && sy >= 0.0 => Some(Some([sx, sy])),
                _ => None,
            }
        } else {
            Some(None)
        };
        let (Some(frame), Some(t)) = (frame, t) else {
            continue;
        };
        // Frame bookkeeping first, so that later rows of a frame are judged
        // against the right frame even when this row has other problems.
        let ordinal = match current {
            Some((number, frame_t, ordinal, first_line)) if number == frame => {
                if t != frame_t {
                    row.issue(
                        issues,
                        IssueKind::FrameTimeMismatch,
                        1,
                        format!(
                            "frame {frame} has time {frame_t} s at line {first_line} but {t} s here"
                        ),
                    );
                    continue;
                }
                ordinal
            }
            previous => {
                let ordinal = previous.map_or(1, |p| p.2 + 1);
                if let Some((number, frame_t, _, first_line)) = previous {
                    if frame < number {
                        row.issue(
                            issues,
                            IssueKind::FrameBackwards,
                            0,
                            format!(
                                "frame number goes backwards: {frame} after {number} (line {first_line})"
                            ),
                        );
                    }
                    if t < frame_t {
                        row.issue(
                            issues,
                            IssueKind::TimeBackwards,
                            1,
                            format!(
                                "time goes backwards: frame {frame} at {t} s after frame {number} at {frame_t} s"
                            ),
                        );
                    } else if t == frame_t {
                        repeated_time.note(row.line, t);
                    }
                }
                if t < 0.0 {
                    negative_time.note(row.line, t);
                }
                current = Some((frame, t, ordinal, row.line));
                span = Some(span.map_or([t, t], |[first, _]| [first, t]));
                ordinal
            }
        };
        let (Some(id), Some(x), Some(y), Some(sigma)) = (id, x, y, sigma) else {
            continue;
        };
        let Some(index) = ids.index(id) else {
            row.issue(
                issues,
                IssueKind::UnknownMarker,
                2,
                format!("marker id {id} is not in markers_rest.csv"),
            );
            continue;
        };
        if index >= last_seen.len() {
            last_seen.resize(index + 1, (0, 0));
        }
        let (seen_in, seen_at) = last_seen[index];
        if seen_in == ordinal {
            row.issue(
                issues,
                IssueKind::DuplicateRow,
                2,
                format!("marker {id} already has a row in frame {frame}, at line {seen_at}"),
            );
            continue;
        }
        last_seen[index] = (ordinal, row.line);
        if let Some(extent) = extent {
            let worst = if x.abs() > y.abs() { x } else { y };
            if extent.looks_like_millimetres(worst) {
                millimetres.note(row.line, worst);
            }
            if let Some([sx, sy]) = sigma
                && sx.max(sy) > 0.1 * extent.size()
            {
                large_sigma.note(row.line, sx.max(sy));
            }
        }
        track.push_row(frame, t, id, [x, y], sigma);
    }
    track.seal_last_frame();
    let file = table.file;
    repeated_time.warn(issues, IssueKind::Suspicious, file, "t", |_| {
        "two frames share a time stamp".to_owned()
    });
    negative_time.warn(issues, IssueKind::Suspicious, file, "t", |w| {
        format!("negative time {w} s; t counts from the start of the trial")
    });
    if let Some(extent) = extent {
        millimetres.warn(issues, IssueKind::Units, file, "x,y", |w| {
            extent.millimetre_warning(w)
        });
        large_sigma.warn(issues, IssueKind::Units, file, "sx,sy", |w| {
            format!("standard deviations up to {w} m exceed a tenth of the phantom; are they in millimetres?")
        });
    }
    if let Some([first, last]) = span {
        warn_if_long(last - first, file, issues);
    }
    if rows_seen == 0 {
        issues.add(
            Severity::Warning,
            IssueKind::Suspicious,
            file,
            None,
            None,
            "no rows after the header: no marker was tracked".to_owned(),
        );
    }
    Some(track)
}

/// Warns when a trial lasting `duration` seconds is implausibly long.
fn warn_if_long(duration: f64, file: &Path, issues: &mut Collector) {
    if duration > LONGEST_PLAUSIBLE_TRIAL {
        issues.add(
            Severity::Warning,
            IssueKind::Units,
            file,
            None,
            Some("t"),
            format!(
                "the trial lasts {} s; is time in milliseconds? (seconds are expected)",
                Shown(duration)
            ),
        );
    }
}

/// Reads `compression.csv`.
pub(crate) fn read_compression(
    path: &Path,
    file: &Path,
    issues: &mut Collector,
) -> Option<Vec<CompressionPoint>> {
    let header = Header {
        required: COMPRESSION_HEADER,
        optional: &[],
    };
    let (mut table, _) = Table::open(path, file, &header, issues)?;
    let mut curve = Vec::new();
    let mut percent = Tally::default();
    while let Some(row) = table.next_row(issues) {
        let strain = row.real(0, issues);
        let stress = row.real(1, issues);
        let (Some(strain), Some(stress)) = (strain, stress) else {
            continue;
        };
        if strain.abs() > 1.0 {
            percent.note(row.line, strain);
        }
        curve.push(CompressionPoint { strain, stress });
    }
    let file = table.file;
    percent.warn(issues, IssueKind::Units, file, "strain", |w| {
        format!("strain {w} is beyond 1; is it in percent? (a plain ratio is expected)")
    });
    if curve.is_empty() {
        issues.add(
            Severity::Warning,
            IssueKind::Suspicious,
            file,
            None,
            None,
            "no rows after the header".to_owned(),
        );
    }
    Some(curve)
}
