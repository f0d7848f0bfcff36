//! Line numbers of CSV records as an editor shows them.
//!
//! The csv crate's record positions count a line per record, not per line
//! break: after `\r\n` endings, lone `\r` endings or blank lines that it
//! skips, its line (and byte) is that of the previous record's end, so an
//! issue would name a line before the offending row. [`LineBreaks`] passes
//! the file's bytes through to the csv reader and notes where every line
//! break is (`\r\n`, `\n` or a lone `\r`, each one break); a record's line is
//! then one more than the breaks before its first byte, found by skipping
//! the breaks at the position csv gives. Only the breaks not yet passed are
//! kept, at most one read-ahead buffer's worth.

use std::collections::VecDeque;
use std::io::{self, Read};

/// A reader that notes its line breaks as they pass (see the module doc).
pub(crate) struct LineBreaks<R> {
    inner: R,
    /// Bytes passed through so far.
    offset: u64,
    /// Breaks as `[first byte, byte after]`, in order, not yet passed.
    ahead: VecDeque<[u64; 2]>,
    /// Breaks before those in `ahead`.
    passed: u64,
    /// A `\r` just read whose next byte is not known yet.
    pending_cr: Option<u64>,
}

impl<R: Read> LineBreaks<R> {
    pub(crate) fn new(inner: R) -> Self {
        Self {
            inner,
            offset: 0,
            ahead: VecDeque::new(),
            passed: 0,
            pending_cr: None,
        }
    }

    /// The one-based line of the record csv says starts at byte `start`.
    /// Calls must come with `start` not decreasing, as records do.
    pub(crate) fn line_of(&mut self, start: u64) -> u64 {
        let mut first = start;
        while let Some(&[from, to]) = self.ahead.front() {
            if to <= first {
                self.passed += 1;
            } else if from <= first {
                // A break csv's position stops at or in: the record begins after it.
                first = to;
                self.passed += 1;
            } else {
                break;
            }
            self.ahead.pop_front();
        }
        self.passed + 1
    }

    fn note(&mut self, bytes: &[u8]) {
        // memchr finds the breaks at many bytes a cycle; a loop over every
        // byte made reading a campaign a third slower (`docs/benchmarks.md`).
        for at in memchr::memchr2_iter(b'\r', b'\n', bytes) {
            let offset = self.offset + at as u64;
            if let Some(cr) = self.pending_cr.take() {
                if bytes[at] == b'\n' && offset == cr + 1 {
                    self.ahead.push_back([cr, offset + 1]);
                    continue;
                }
                self.ahead.push_back([cr, cr + 1]);
            }
            if bytes[at] == b'\r' {
                self.pending_cr = Some(offset);
            } else {
                self.ahead.push_back([offset, offset + 1]);
            }
        }
        self.offset += bytes.len() as u64;
        // A `\r` not followed by `\n` is a break of its own once a byte
        // after it is known.
        if let Some(cr) = self.pending_cr
            && cr + 1 < self.offset
        {
            self.pending_cr = None;
            self.ahead.push_back([cr, cr + 1]);
        }
    }
}

impl<R: Read> Read for LineBreaks<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let n = self.inner.read(buf)?;
        if n == 0 {
            if let Some(cr) = self.pending_cr.take() {
                self.ahead.push_back([cr, cr + 1]);
            }
        } else {
            self.note(&buf[..n]);
        }
        Ok(n)
    }
}

#[cfg(test)]
mod tests {
    use super::LineBreaks;
    use csv::{ByteRecord, ReaderBuilder};

    /// Each record's first field and line, read through csv as the tables are.
    fn lines(text: &[u8]) -> Vec<(String, u64)> {
        let mut reader = ReaderBuilder::new()
            .has_headers(false)
            .flexible(true)
            // A small buffer, so that breaks and `\r\n` pairs straddle reads.
            .buffer_capacity(3)
            .from_reader(LineBreaks::new(text));
        let mut record = ByteRecord::new();
        let mut out = Vec::new();
        while reader.read_byte_record(&mut record).unwrap() {
            let start = record.position().unwrap().byte();
            let line = reader.get_mut().line_of(start);
            out.push((String::from_utf8_lossy(&record[0]).into_owned(), line));
        }
        out
    }

    fn expected(pairs: &[(&str, u64)]) -> Vec<(String, u64)> {
        pairs.iter().map(|&(f, l)| (f.to_owned(), l)).collect()
    }

    #[test]
    fn every_kind_of_line_ending_counts_one_line() {
        let want = expected(&[("h", 1), ("a", 2), ("b", 3), ("c", 4)]);
        assert_eq!(lines(b"h\na\nb\nc\n"), want);
        assert_eq!(lines(b"h\r\na\r\nb\r\nc\r\n"), want);
        assert_eq!(lines(b"h\ra\rb\rc\r"), want);
        assert_eq!(lines(b"h\r\na\nb\rc"), want);
    }

    #[test]
    fn blank_lines_count_though_csv_skips_them() {
        assert_eq!(
            lines(b"\n\nh\na\n\n\nb\n  \nc\n"),
            expected(&[("h", 3), ("a", 4), ("b", 7), ("  ", 8), ("c", 9)])
        );
        assert_eq!(
            lines(b"h\r\n\r\n\r\na\r\n\r\nb"),
            expected(&[("h", 1), ("a", 4), ("b", 6)])
        );
    }

    /// The line of the byte at `start`, counted the plain way: one more
    /// than the breaks before it.
    fn line_by_counting(text: &[u8], start: usize) -> u64 {
        let (mut line, mut i) = (1, 0);
        while i < start {
            match text[i] {
                b'\r' if text.get(i + 1) == Some(&b'\n') && i + 1 < start => {
                    line += 1;
                    i += 1;
                }
                b'\r' | b'\n' => line += 1,
                _ => {}
            }
            i += 1;
        }
        line
    }

    proptest::proptest! {
        /// Any mix of endings and blank lines, any read sizes: each record's
        /// line is the plain count of the breaks before its first byte.
        #[test]
        fn lines_agree_with_a_plain_count(
            text in proptest::collection::vec(
                proptest::sample::select(vec![b'a', b'b', b',', b' ', b'\r', b'\n']),
                0..200,
            ),
            buffer in 1usize..20,
        ) {
            let mut reader = ReaderBuilder::new()
                .has_headers(false)
                .flexible(true)
                .buffer_capacity(buffer)
                .from_reader(LineBreaks::new(text.as_slice()));
            let mut record = ByteRecord::new();
            while reader.read_byte_record(&mut record).unwrap() {
                let csv_start = record.position().unwrap().byte() as usize;
                // The record's first byte: past the breaks csv stops before.
                let first = (csv_start..text.len())
                    .find(|&i| !matches!(text[i], b'\r' | b'\n'))
                    .unwrap_or(text.len());
                let line = reader.get_mut().line_of(csv_start as u64);
                proptest::prop_assert_eq!(line, line_by_counting(&text, first));
            }
        }
    }

    #[test]
    fn a_quoted_line_break_is_a_line_of_its_record() {
        assert_eq!(
            lines(b"h\n\"a\r\nx\"\nb\n"),
            expected(&[("h", 1), ("a\r\nx", 2), ("b", 4)])
        );
    }
}
