//! Reading one CSV table of a bundle: open, check the header, then hand each
//! row to the caller with number parsing that reports bad values in place.
//!
//! One `ByteRecord` is reused for the whole file and fields are parsed from
//! bytes, so reading millions of rows allocates nothing per row.

use std::fs::File;
use std::path::Path;

use csv::{ByteRecord, Reader, ReaderBuilder};

use crate::line_breaks::LineBreaks;
use crate::report::{Collector, IssueKind, Quoted, Severity};

/// An open table whose header has been checked.
pub(crate) struct Table<'a> {
    reader: Reader<LineBreaks<File>>,
    record: ByteRecord,
    /// The file, relative to the bundle root (for issues).
    pub(crate) file: &'a Path,
    /// Column names, as the header gives them.
    columns: Vec<&'static str>,
}

/// What a table's header must be.
pub(crate) struct Header {
    /// The leading columns every file has, in order.
    pub(crate) required: &'static [&'static str],
    /// Trailing columns that are either all present, in order, or all absent.
    pub(crate) optional: &'static [&'static str],
}

impl<'a> Table<'a> {
    /// Opens `path` and checks its header; `None` (with the issue recorded)
    /// when the file cannot be read or its header is wrong. The boolean says
    /// whether the optional trailing columns are present.
    pub(crate) fn open(
        path: &Path,
        file: &'a Path,
        header: &Header,
        issues: &mut Collector,
    ) -> Option<(Self, bool)> {
        let handle = match File::open(path) {
            Ok(handle) => handle,
            Err(err) => {
                issues.add(
                    Severity::Error,
                    IssueKind::Io,
                    file,
                    None,
                    None,
                    format!("cannot open: {err}"),
                );
                return None;
            }
        };
        let mut reader = ReaderBuilder::new()
            .has_headers(false)
            .flexible(true)
            .buffer_capacity(1 << 16)
            .from_reader(LineBreaks::new(handle));
        let mut record = ByteRecord::new();
        let expected = header.required.join(",");
        let with_optional = [header.required, header.optional].concat().join(",");
        let read = reader.read_byte_record(&mut record);
        // Blank lines before the header are legal; its line is not always 1.
        let header_line = match (&read, record.position()) {
            (Ok(true), Some(at)) => reader.get_mut().line_of(at.byte()),
            _ => 1,
        };
        let found = match read {
            Ok(true) => record
                .iter()
                .enumerate()
                .map(|(i, f)| {
                    // Spreadsheets often start a UTF-8 file with a byte order mark.
                    let f = if i == 0 {
                        f.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(f)
                    } else {
                        f
                    };
                    String::from_utf8_lossy(f.trim_ascii()).into_owned()
                })
                .collect::<Vec<_>>(),
            Ok(false) => {
                issues.add(
                    Severity::Error,
                    IssueKind::EmptyTable,
                    file,
                    None,
                    None,
                    format!("the file is empty; it must start with the header `{expected}`"),
                );
                return None;
            }
            Err(err) => {
                let line = err.position().map(|at| reader.get_mut().line_of(at.byte()));
                issues.add(
                    Severity::Error,
                    IssueKind::Io,
                    file,
                    line,
                    None,
                    format!("cannot read the header: {err}"),
                );
                return None;
            }
        };
        let matches = |names: &[&str]| {
            found.len() == names.len() && found.iter().zip(names).all(|(f, n)| f == n)
        };
        let optional_present = if matches(header.required) {
            false
        } else if !header.optional.is_empty()
            && matches(&[header.required, header.optional].concat())
        {
            true
        } else {
            let alternatives = if header.optional.is_empty() {
                format!("`{expected}`")
            } else {
                format!("`{expected}` or `{with_optional}`")
            };
            issues.add(
                Severity::Error,
                IssueKind::BadHeader,
                file,
                Some(header_line),
                None,
                format!(
                    "the header is `{}`; the format prescribes {alternatives}",
                    found.join(",")
                ),
            );
            return None;
        };
        let mut columns = header.required.to_vec();
        if optional_present {
            columns.extend_from_slice(header.optional);
        }
        Some((
            Self {
                reader,
                record,
                file,
                columns,
            },
            optional_present,
        ))
    }

    /// The next data row whose field count matches the header; rows of the
    /// wrong length are reported and skipped. `None` at the end of the file
    /// (or on a read error, which is reported).
    pub(crate) fn next_row(&mut self, issues: &mut Collector) -> Option<Row<'_>> {
        loop {
            match self.reader.read_byte_record(&mut self.record) {
                Ok(true) => {}
                Ok(false) => return None,
                Err(err) => {
                    let line = err
                        .position()
                        .map(|at| self.reader.get_mut().line_of(at.byte()));
                    issues.add(
                        Severity::Error,
                        IssueKind::Io,
                        self.file,
                        line,
                        None,
                        format!("cannot read further: {err}"),
                    );
                    return None;
                }
            }
            let start = self.record.position().map_or(0, |at| at.byte());
            let line = self.reader.get_mut().line_of(start);
            if self.record.len() == self.columns.len() {
                return Some(Row {
                    record: &self.record,
                    line,
                    file: self.file,
                    columns: &self.columns,
                });
            }
            issues.add(
                Severity::Error,
                IssueKind::RowLength,
                self.file,
                Some(line),
                None,
                format!(
                    "the row has {} fields; the header has {} ({})",
                    self.record.len(),
                    self.columns.len(),
                    self.columns.join(",")
                ),
            );
        }
    }
}

/// One data row; its fields are parsed on demand.
pub(crate) struct Row<'r> {
    record: &'r ByteRecord,
    /// One-based line in the file.
    pub(crate) line: u64,
    file: &'r Path,
    columns: &'r [&'static str],
}

impl Row<'_> {
    /// Column `column` as text, without surrounding white space. (Trimming
    /// here rather than in the csv reader, which copies every record to trim.)
    fn text(&self, column: usize, issues: &mut Collector) -> Option<&str> {
        let bytes = self.record[column].trim_ascii();
        match std::str::from_utf8(bytes) {
            Ok(text) => Some(text),
            Err(_) => {
                self.issue(
                    issues,
                    IssueKind::BadNumber,
                    column,
                    "is not valid UTF-8 text, let alone a number".to_owned(),
                );
                None
            }
        }
    }

    /// Column `column` as a finite real number.
    pub(crate) fn real(&self, column: usize, issues: &mut Collector) -> Option<f64> {
        let text = self.text(column, issues)?;
        match text.parse::<f64>() {
            Ok(value) if value.is_finite() => Some(value),
            Ok(value) => {
                self.issue(
                    issues,
                    IssueKind::NonFinite,
                    column,
                    format!("`{}` is {value}, not a finite number", Quoted(text)),
                );
                None
            }
            Err(_) => {
                self.issue(
                    issues,
                    IssueKind::BadNumber,
                    column,
                    format!("`{}` is not a number", Quoted(text)),
                );
                None
            }
        }
    }

    /// Column `column` as a non-negative integer of type `T`.
    pub(crate) fn integer<T: std::str::FromStr>(
        &self,
        column: usize,
        issues: &mut Collector,
    ) -> Option<T> {
        let text = self.text(column, issues)?;
        let parsed = if text.starts_with('+') {
            None
        } else {
            text.parse::<T>().ok()
        };
        if parsed.is_none() {
            self.issue(
                issues,
                IssueKind::BadNumber,
                column,
                format!(
                    "`{}` is not a non-negative integer of at most {} bits",
                    Quoted(text),
                    8 * size_of::<T>()
                ),
            );
        }
        parsed
    }

    /// Reports an error about this row; `column` is an index into the header.
    pub(crate) fn issue(
        &self,
        issues: &mut Collector,
        kind: IssueKind,
        column: usize,
        message: String,
    ) {
        issues.add(
            Severity::Error,
            kind,
            self.file,
            Some(self.line),
            Some(self.columns[column]),
            message,
        );
    }
}
