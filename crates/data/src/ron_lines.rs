//! Where things are in RON text: the line of every field, found by a
//! tolerant scan, so that a value serde accepted but a check rejects can be
//! reported at its line.

use std::collections::HashMap;

/// One level of nesting while scanning RON text.
enum Level {
    /// A struct `Name(...)`, `(...)` or map `{...}`, with the field being read.
    Struct(Option<String>),
    /// A list `[...]`, with the index of the element being read.
    List(usize),
    /// `Some(...)`: adds nothing to the path.
    Transparent,
}

/// The line of every field of a RON document, keyed by its path
/// (`phantom.width`, `trials[1].velocity`, `noise.marker_sigma`).
///
/// A tolerant scan, not a parser: it skips comments, strings and literals and
/// follows brackets, so it gives lines even for values serde accepted but the
/// checks reject. Elements of a list are not keyed, only fields. The bundle
/// reader uses it for `bundle.ron`, and needle-synth for scenario files.
pub fn field_lines(text: &str) -> HashMap<String, u64> {
    let bytes = text.as_bytes();
    let mut lines = HashMap::new();
    let mut stack: Vec<Level> = Vec::new();
    let mut line: u64 = 1;
    let mut pending_ident: Option<(&str, u64)> = None;
    let mut i = 0;
    while i < bytes.len() {
        let b = bytes[i];
        match b {
            b'\n' => {
                line += 1;
                i += 1;
            }
            b'/' if bytes.get(i + 1) == Some(&b'/') => {
                while i < bytes.len() && bytes[i] != b'\n' {
                    i += 1;
                }
            }
            b'/' if bytes.get(i + 1) == Some(&b'*') => {
                // RON block comments nest.
                let mut depth = 0usize;
                while i < bytes.len() {
                    if bytes[i..].starts_with(b"/*") {
                        depth += 1;
                        i += 2;
                    } else if bytes[i..].starts_with(b"*/") {
                        depth -= 1;
                        i += 2;
                        if depth == 0 {
                            break;
                        }
                    } else {
                        line += u64::from(bytes[i] == b'\n');
                        i += 1;
                    }
                }
            }
            b'"' | b'\'' => {
                pending_ident = None;
                i += 1;
                while i < bytes.len() && bytes[i] != b {
                    line += u64::from(bytes[i] == b'\n');
                    i += if bytes[i] == b'\\' { 2 } else { 1 };
                }
                i += 1;
            }
            b'r' if raw_string_hashes(&bytes[i + 1..]).is_some() => {
                pending_ident = None;
                let hashes = raw_string_hashes(&bytes[i + 1..]).unwrap_or(0);
                let mut closing = vec![b'"'];
                closing.extend(std::iter::repeat_n(b'#', hashes));
                i += 1 + hashes + 1;
                while i < bytes.len() && !bytes[i..].starts_with(&closing) {
                    line += u64::from(bytes[i] == b'\n');
                    i += 1;
                }
                i += closing.len();
            }
            b'A'..=b'Z' | b'a'..=b'z' | b'_' => {
                let start = i;
                while i < bytes.len() && (bytes[i].is_ascii_alphanumeric() || bytes[i] == b'_') {
                    i += 1;
                }
                pending_ident = Some((&text[start..i], line));
            }
            b':' => {
                if let (Some((name, at)), Some(Level::Struct(field))) =
                    (pending_ident.take(), stack.last_mut())
                {
                    *field = Some(name.to_owned());
                    lines.entry(path_of(&stack)).or_insert(at);
                }
                i += 1;
            }
            b'(' | b'{' => {
                let level = match pending_ident.take() {
                    Some(("Some", _)) => Level::Transparent,
                    _ => Level::Struct(None),
                };
                stack.push(level);
                i += 1;
            }
            b'[' => {
                pending_ident = None;
                stack.push(Level::List(0));
                i += 1;
            }
            b')' | b'}' | b']' => {
                pending_ident = None;
                stack.pop();
                i += 1;
            }
            b',' => {
                pending_ident = None;
                match stack.last_mut() {
                    Some(Level::List(index)) => *index += 1,
                    Some(Level::Struct(field)) => *field = None,
                    _ => {}
                }
                i += 1;
            }
            _ => {
                if !b.is_ascii_whitespace() {
                    pending_ident = None;
                }
                i += 1;
            }
        }
    }
    lines
}

/// The number of `#` of a raw string `r#..."...` starting after the `r`,
/// if the bytes start one (and not a raw identifier `r#name`).
fn raw_string_hashes(after_r: &[u8]) -> Option<usize> {
    let hashes = after_r.iter().take_while(|&&c| c == b'#').count();
    (after_r.get(hashes) == Some(&b'"')).then_some(hashes)
}

fn path_of(stack: &[Level]) -> String {
    let mut path = String::new();
    for level in stack {
        match level {
            Level::Struct(Some(field)) => {
                if !path.is_empty() {
                    path.push('.');
                }
                path.push_str(field);
            }
            Level::List(index) => path.push_str(&format!("[{index}]")),
            Level::Struct(None) | Level::Transparent => {}
        }
    }
    path
}

#[cfg(test)]
mod tests {
    use super::field_lines;

    #[test]
    fn field_lines_follow_nesting_comments_and_lists() {
        let text = "Bundle(\n  format: 1, // a comment: with colon\n  name: \"a: (b\",\n  phantom: Phantom(width: 0.1,\n depth: 0.1, thickness: 0.01, fixed: [Back, Left]),\n  noise: Some(Noise(marker_sigma: 1e-6,\n force_sigma: 0.01)),\n  /* block /* nested */ x: 1 */ trials: [\n    Trial(id: \"a\", kind: Probe, velocity: 0.001, day: 0.0),\n    Trial(id: \"b\", kind: Needle,\n velocity: 0.002, day: 1.0),\n  ],\n)";
        let lines = field_lines(text);
        assert_eq!(lines["format"], 2);
        assert_eq!(lines["name"], 3);
        assert_eq!(lines["phantom.width"], 4);
        assert_eq!(lines["phantom.depth"], 5);
        assert_eq!(lines["phantom.fixed"], 5);
        assert_eq!(lines["noise.marker_sigma"], 6);
        assert_eq!(lines["noise.force_sigma"], 7);
        assert_eq!(lines["trials"], 8);
        assert_eq!(lines["trials[0].id"], 9);
        assert_eq!(lines["trials[1].id"], 10);
        assert_eq!(lines["trials[1].velocity"], 11);
        assert!(!lines.contains_key("x"));
    }
}
