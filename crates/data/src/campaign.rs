//! A bundle in memory: the campaign's data with accessors by trial, frame and
//! marker id, and the builder a generator fills before writing.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use crate::error::BundleError;
use crate::report::ValidationReport;
use crate::types::{
    Bundle, CompressionPoint, FORMAT_VERSION, MarkerObservation, MarkerRest, Noise, Phantom,
    ToolSample, Trial,
};
use crate::write::{WriteOptions, write_bundle};

/// Everything one bundle holds, in memory.
///
/// Trials keep the manifest's order. Reading a bundle gives one; writing one
/// produces a bundle that reads back equal (frame and calibration paths aside,
/// which point at wherever the files are).
#[derive(Debug, Clone, PartialEq)]
pub struct Campaign {
    /// Campaign name.
    pub name: String,
    /// The phantom.
    pub phantom: Phantom,
    /// Stated measurement noise, if any.
    pub noise: Option<Noise>,
    /// Undeformed marker positions.
    pub markers_rest: MarkerSet,
    /// The trials with their data, in manifest order.
    pub trials: Vec<TrialData>,
    /// The unconfined compression curve, if measured.
    pub compression: Option<Vec<CompressionPoint>>,
    /// The calibration folder (copied as is when writing), if any.
    pub calibration_dir: Option<PathBuf>,
}

impl Campaign {
    /// An empty campaign on a phantom: no markers, no trials.
    pub fn new(name: impl Into<String>, phantom: Phantom) -> Self {
        Self {
            name: name.into(),
            phantom,
            noise: None,
            markers_rest: MarkerSet::default(),
            trials: Vec::new(),
            compression: None,
            calibration_dir: None,
        }
    }

    /// The manifest that describes this campaign (format 1).
    pub fn manifest(&self) -> Bundle {
        Bundle {
            format: FORMAT_VERSION,
            name: self.name.clone(),
            phantom: self.phantom.clone(),
            noise: self.noise,
            trials: self.trials.iter().map(|t| t.trial.clone()).collect(),
        }
    }

    /// The trial with this id.
    pub fn trial(&self, id: &str) -> Option<&TrialData> {
        self.trials.iter().find(|t| t.trial.id == id)
    }
}

/// One trial: what the manifest says about it and what was measured.
#[derive(Debug, Clone, PartialEq)]
pub struct TrialData {
    /// The manifest entry.
    pub trial: Trial,
    /// `tool.csv`: sensor samples in time order.
    pub tool: Vec<ToolSample>,
    /// `markers.csv`, if the trial has one.
    pub markers: Option<MarkerTrack>,
    /// `frames/NNNNNN.png`, sorted by number; not decoded here.
    pub frames: Vec<FrameFile>,
}

impl TrialData {
    /// A trial with no data yet.
    pub fn new(trial: Trial) -> Self {
        Self {
            trial,
            tool: Vec::new(),
            markers: None,
            frames: Vec::new(),
        }
    }

    /// The trial's marker track, created empty on first use.
    pub fn markers_mut(&mut self) -> &mut MarkerTrack {
        self.markers.get_or_insert_with(MarkerTrack::default)
    }

    /// Adds a camera frame that exists as a PNG file at `source`; writing the
    /// bundle copies it to `trials/ID/frames/NNNNNN.png`.
    pub fn add_frame_file(
        &mut self,
        number: u64,
        source: impl Into<PathBuf>,
    ) -> Result<(), BundleError> {
        if crate::layout::frame_file_name(number).is_none() {
            return Err(BundleError::FrameNumber { number });
        }
        let path = source.into();
        let at = self.frames.partition_point(|f| f.number < number);
        if self.frames.get(at).is_some_and(|f| f.number == number) {
            self.frames[at].path = path;
        } else {
            self.frames.insert(at, FrameFile { number, path });
        }
        Ok(())
    }
}

/// A camera frame file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FrameFile {
    /// Frame number, from the file name `NNNNNN.png`.
    pub number: u64,
    /// Where the file is.
    pub path: PathBuf,
}

/// The markers at rest, with a lookup by id.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MarkerSet {
    markers: Vec<MarkerRest>,
    lookup: IdLookup,
}

/// Marker id to index. Ids are usually small and dense (a grid numbered row
/// by row), and a table is then much faster than hashing for the millions of
/// rows of a campaign's `markers.csv`.
#[derive(Debug, Clone, PartialEq)]
enum IdLookup {
    /// `table[id]` is the index, or `ABSENT`.
    Table(Vec<u32>),
    Hashed(HashMap<u32, usize>),
}

impl Default for IdLookup {
    fn default() -> Self {
        Self::Table(Vec::new())
    }
}

const ABSENT: u32 = u32::MAX;

impl MarkerSet {
    /// The set of these markers, in this order. An id given twice keeps its
    /// first position in the lookup (and makes the bundle invalid when
    /// written).
    pub fn new(markers: Vec<MarkerRest>) -> Self {
        let largest = markers.iter().map(|m| m.id as usize).max().unwrap_or(0);
        let lookup = if largest < 4 * markers.len() + 1024 {
            let mut table = vec![ABSENT; largest + 1];
            for (i, m) in markers.iter().enumerate().rev() {
                table[m.id as usize] = i as u32;
            }
            IdLookup::Table(table)
        } else {
            let mut index = HashMap::with_capacity(markers.len());
            for (i, m) in markers.iter().enumerate() {
                index.entry(m.id).or_insert(i);
            }
            IdLookup::Hashed(index)
        };
        Self { markers, lookup }
    }

    /// The markers in file order.
    pub fn as_slice(&self) -> &[MarkerRest] {
        &self.markers
    }

    /// Number of markers.
    pub fn len(&self) -> usize {
        self.markers.len()
    }

    /// True when there are no markers.
    pub fn is_empty(&self) -> bool {
        self.markers.is_empty()
    }

    /// Position of marker `id` in [`as_slice`](Self::as_slice).
    pub fn index_of(&self, id: u32) -> Option<usize> {
        match &self.lookup {
            IdLookup::Table(table) => table
                .get(id as usize)
                .filter(|&&i| i != ABSENT)
                .map(|&i| i as usize),
            IdLookup::Hashed(index) => index.get(&id).copied(),
        }
    }

    /// The marker with this id.
    pub fn get(&self, id: u32) -> Option<&MarkerRest> {
        self.index_of(id).map(|i| &self.markers[i])
    }
}

/// Where a frame's rows start in the columns of a [`MarkerTrack`].
#[derive(Debug, Clone, Copy, PartialEq)]
struct FrameSpan {
    frame: u64,
    t: f64,
    start: usize,
}

/// The tracked markers of one trial (`markers.csv`), stored by column and
/// grouped by frame; within a frame, rows are sorted by marker id.
///
/// A frame in which no marker was tracked has no row in `markers.csv`, so it
/// is not stored either.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MarkerTrack {
    frames: Vec<FrameSpan>,
    ids: Vec<u32>,
    positions: Vec<[f64; 2]>,
    sigmas: Option<Vec<[f64; 2]>>,
}

/// One camera frame of a [`MarkerTrack`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameView<'a> {
    /// Frame number.
    pub frame: u64,
    /// Time since the trial began (s).
    pub t: f64,
    /// Ids of the markers tracked in this frame, ascending.
    pub ids: &'a [u32],
    /// Their positions `(x, y)` (m), aligned with `ids`.
    pub positions: &'a [[f64; 2]],
    /// Their tracking standard deviations `(sx, sy)` (m), when given.
    pub sigmas: Option<&'a [[f64; 2]]>,
}

impl FrameView<'_> {
    /// Position of marker `id` in this frame, if it was tracked.
    pub fn position(&self, id: u32) -> Option<[f64; 2]> {
        self.ids.binary_search(&id).ok().map(|i| self.positions[i])
    }

    /// `(id, position)` of every tracked marker, ascending id.
    pub fn iter(&self) -> impl Iterator<Item = (u32, [f64; 2])> + '_ {
        self.ids.iter().copied().zip(self.positions.iter().copied())
    }

    /// The frame as a map from marker id to position.
    pub fn to_map(&self) -> HashMap<u32, [f64; 2]> {
        self.iter().collect()
    }

    /// Number of markers tracked in this frame.
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    /// True when no marker was tracked (never the case for a stored frame).
    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }
}

impl MarkerTrack {
    /// A track from rows in file order: consecutive rows with the same frame
    /// number form one frame, whose time is its first row's.
    pub fn from_observations(rows: &[MarkerObservation]) -> Result<Self, BundleError> {
        let mut track = Self::default();
        if rows.first().is_some_and(|first| first.sigma.is_some()) {
            track.sigmas = Some(Vec::with_capacity(rows.len()));
        }
        for (row, obs) in rows.iter().enumerate() {
            if obs.sigma.is_some() != track.sigmas.is_some() {
                return Err(BundleError::MixedSigma { row });
            }
            track.push_row(obs.frame, obs.t, obs.id, [obs.x, obs.y], obs.sigma);
        }
        track.seal_last_frame();
        Ok(track)
    }

    /// Appends a frame. Its markers are stored sorted by id; an empty frame is
    /// not stored. Fails if the track already holds rows with `sx,sy`.
    pub fn push_frame(
        &mut self,
        frame: u64,
        t: f64,
        markers: impl IntoIterator<Item = (u32, [f64; 2])>,
    ) -> Result<(), BundleError> {
        if self.sigmas.is_some() && !self.ids.is_empty() {
            return Err(BundleError::MixedSigma {
                row: self.ids.len(),
            });
        }
        self.sigmas = None;
        self.begin_frame(frame, t);
        for (id, position) in markers {
            self.ids.push(id);
            self.positions.push(position);
        }
        self.seal_last_frame();
        Ok(())
    }

    /// Appends a frame whose rows carry tracking standard deviations
    /// `(sx, sy)`. Fails if the track already holds rows without them.
    pub fn push_frame_with_sigma(
        &mut self,
        frame: u64,
        t: f64,
        markers: impl IntoIterator<Item = (u32, [f64; 2], [f64; 2])>,
    ) -> Result<(), BundleError> {
        if self.sigmas.is_none() && !self.ids.is_empty() {
            return Err(BundleError::MixedSigma {
                row: self.ids.len(),
            });
        }
        self.begin_frame(frame, t);
        let sigmas = self.sigmas.get_or_insert_with(Vec::new);
        for (id, position, sigma) in markers {
            self.ids.push(id);
            self.positions.push(position);
            sigmas.push(sigma);
        }
        self.seal_last_frame();
        Ok(())
    }

    /// True when the rows carry tracking standard deviations (`sx,sy`).
    pub fn has_sigma(&self) -> bool {
        self.sigmas.is_some()
    }

    /// Number of frames.
    pub fn frame_count(&self) -> usize {
        self.frames.len()
    }

    /// Number of rows (marker observations) over all frames.
    pub fn row_count(&self) -> usize {
        self.ids.len()
    }

    /// Frame `index` (0-based position in the track, not the frame number).
    pub fn frame(&self, index: usize) -> Option<FrameView<'_>> {
        let span = self.frames.get(index)?;
        let end = self
            .frames
            .get(index + 1)
            .map_or(self.ids.len(), |s| s.start);
        Some(FrameView {
            frame: span.frame,
            t: span.t,
            ids: &self.ids[span.start..end],
            positions: &self.positions[span.start..end],
            sigmas: self.sigmas.as_deref().map(|s| &s[span.start..end]),
        })
    }

    /// The frames in order.
    pub fn frames(&self) -> impl Iterator<Item = FrameView<'_>> + '_ {
        (0..self.frames.len()).filter_map(|i| self.frame(i))
    }

    /// Every row, frame by frame, ascending id within a frame.
    pub fn observations(&self) -> impl Iterator<Item = MarkerObservation> + '_ {
        self.frames().flat_map(|f| {
            (0..f.len()).map(move |i| MarkerObservation {
                frame: f.frame,
                t: f.t,
                id: f.ids[i],
                x: f.positions[i][0],
                y: f.positions[i][1],
                sigma: f.sigmas.map(|s| s[i]),
            })
        })
    }

    /// Appends one row; a new frame starts when the frame number changes.
    /// The caller seals the last frame when done.
    pub(crate) fn push_row(
        &mut self,
        frame: u64,
        t: f64,
        id: u32,
        position: [f64; 2],
        sigma: Option<[f64; 2]>,
    ) {
        if self.frames.last().is_none_or(|s| s.frame != frame) {
            self.seal_last_frame();
            self.begin_frame(frame, t);
        }
        self.ids.push(id);
        self.positions.push(position);
        if let (Some(sigmas), Some(sigma)) = (&mut self.sigmas, sigma) {
            sigmas.push(sigma);
        }
    }

    /// Declares that rows carry `sx,sy` (before the first row).
    pub(crate) fn with_sigma(mut self) -> Self {
        self.sigmas = Some(Vec::new());
        self
    }

    fn begin_frame(&mut self, frame: u64, t: f64) {
        self.frames.push(FrameSpan {
            frame,
            t,
            start: self.ids.len(),
        });
    }

    /// Sorts the last frame's rows by id, and drops it if it is empty.
    pub(crate) fn seal_last_frame(&mut self) {
        let Some(span) = self.frames.last() else {
            return;
        };
        let start = span.start;
        if start == self.ids.len() {
            self.frames.pop();
            return;
        }
        let ids = &self.ids[start..];
        if ids.windows(2).all(|w| w[0] <= w[1]) {
            return;
        }
        let mut order: Vec<usize> = (0..ids.len()).collect();
        order.sort_by_key(|&i| ids[i]);
        let ids: Vec<u32> = order.iter().map(|&i| self.ids[start + i]).collect();
        let positions: Vec<[f64; 2]> = order.iter().map(|&i| self.positions[start + i]).collect();
        self.ids[start..].copy_from_slice(&ids);
        self.positions[start..].copy_from_slice(&positions);
        if let Some(sigmas) = &mut self.sigmas {
            let sorted: Vec<[f64; 2]> = order.iter().map(|&i| sigmas[start + i]).collect();
            sigmas[start..].copy_from_slice(&sorted);
        }
    }
}

/// A bundle read from disk: its data, where it is, and the warnings
/// validation raised.
#[derive(Debug, Clone)]
pub struct LoadedBundle {
    /// The bundle folder.
    pub root: PathBuf,
    /// The data.
    pub campaign: Campaign,
    /// Warnings found while validating (no errors: a bundle with errors does
    /// not load).
    pub warnings: ValidationReport,
}

impl LoadedBundle {
    /// The trial with this id.
    pub fn trial(&self, id: &str) -> Option<&TrialData> {
        self.campaign.trial(id)
    }

    /// Where the frames of trial `id` are (whether or not it has any).
    pub fn frames_dir(&self, id: &str) -> PathBuf {
        crate::layout::frames_dir(&self.root, id)
    }
}

/// Fills a campaign trial by trial in memory, then writes it atomically.
///
/// ```
/// use needle_data::{BundleBuilder, Face, MarkerRest, Phantom, ToolSample, Trial, TrialKind, WriteOptions};
/// let phantom = Phantom { width: 0.075, depth: 0.075, thickness: 0.0075, fixed: vec![Face::Back] };
/// let mut builder = BundleBuilder::new("demo", phantom);
/// builder.markers_rest(vec![MarkerRest { id: 0, x: 0.01, y: 0.02 }]);
/// let trial = builder.trial(Trial { id: "probe-01".into(), kind: TrialKind::Probe, velocity: 0.001, day: 0.0 });
/// trial.tool.push(ToolSample { t: 0.0, tip_x: 0.03, tip_y: 0.0, theta: 0.0, fx: 0.0, fy: 0.0, mz: 0.0 });
/// trial.markers_mut().push_frame(0, 0.0, [(0, [0.01, 0.02])])?;
/// let dir = tempfile::tempdir()?;
/// builder.write(&dir.path().join("demo"), WriteOptions::default())?;
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone)]
pub struct BundleBuilder {
    campaign: Campaign,
}

impl BundleBuilder {
    /// An empty campaign on a phantom.
    pub fn new(name: impl Into<String>, phantom: Phantom) -> Self {
        Self {
            campaign: Campaign::new(name, phantom),
        }
    }

    /// States the measurement noise.
    pub fn noise(&mut self, noise: Noise) -> &mut Self {
        self.campaign.noise = Some(noise);
        self
    }

    /// Sets the markers at rest.
    pub fn markers_rest(&mut self, markers: Vec<MarkerRest>) -> &mut Self {
        self.campaign.markers_rest = MarkerSet::new(markers);
        self
    }

    /// Sets the unconfined compression curve.
    pub fn compression(&mut self, curve: Vec<CompressionPoint>) -> &mut Self {
        self.campaign.compression = Some(curve);
        self
    }

    /// Sets a calibration folder to copy into the bundle.
    pub fn calibration_dir(&mut self, dir: impl Into<PathBuf>) -> &mut Self {
        self.campaign.calibration_dir = Some(dir.into());
        self
    }

    /// Appends a trial and returns it for filling.
    pub fn trial(&mut self, trial: Trial) -> &mut TrialData {
        self.campaign.trials.push(TrialData::new(trial));
        self.campaign.trials.last_mut().expect("just pushed")
    }

    /// The campaign so far.
    pub fn campaign(&self) -> &Campaign {
        &self.campaign
    }

    /// The finished campaign.
    pub fn finish(self) -> Campaign {
        self.campaign
    }

    /// Writes the campaign as a bundle at `path` (see [`write_bundle`]).
    pub fn write(&self, path: &Path, options: WriteOptions) -> Result<(), BundleError> {
        write_bundle(path, &self.campaign, options)
    }
}
