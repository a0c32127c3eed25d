//! The lines of a log, numbered from 1 without their line ends: from text in memory
//! ([`TextLines`]) or read one at a time from a file ([`ReaderLines`]), so a long log is never held
//! whole as text (docs/logs.md, "Memory"). Both split the same way: at LF (a CR before it
//! dropped), or at CR alone when the file has CR and no LF (old Mac exports), and a leading byte
//! order mark is dropped.

use super::error::{LogError, LogErrorKind};
use std::io::BufRead;

/// A source of numbered lines.
pub(super) trait Lines {
    /// The next line and its number, or `None` at the end.
    fn next_line(&mut self) -> Result<Option<(usize, &str)>, LogError>;
}

/// The lines of text in memory.
pub(super) struct TextLines<'a> {
    split: std::iter::Enumerate<std::str::Split<'a, char>>,
}

impl<'a> TextLines<'a> {
    pub(super) fn new(text: &'a str) -> Self {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let end = if text.contains('\r') && !text.contains('\n') {
            '\r'
        } else {
            '\n'
        };
        Self {
            split: text.split(end).enumerate(),
        }
    }
}

impl Lines for TextLines<'_> {
    fn next_line(&mut self) -> Result<Option<(usize, &str)>, LogError> {
        Ok(self
            .split
            .next()
            .map(|(i, l)| (i + 1, l.strip_suffix('\r').unwrap_or(l))))
    }
}

/// The lines of a file read through a buffer, each checked to be UTF-8 as it is read (a line ends
/// at an LF byte, which no multi-byte UTF-8 sequence contains, so checking line by line finds the
/// same first invalid byte as checking the whole file).
pub(super) struct ReaderLines<R: BufRead> {
    reader: R,
    file: String,
    buf: Vec<u8>,
    /// The current line's text (`buf` checked and with its line end removed).
    line: String,
    /// Number of the next line.
    number: usize,
    /// Bytes of the file before `buf`.
    offset: usize,
    /// A file with CR and no LF: its whole text, and where the next line starts in it.
    cr_text: String,
    cr_at: Option<usize>,
    done: bool,
}

impl<R: BufRead> ReaderLines<R> {
    pub(super) fn new(reader: R, file: &str) -> Self {
        Self {
            reader,
            file: file.to_owned(),
            buf: Vec::new(),
            line: String::new(),
            number: 1,
            offset: 0,
            cr_text: String::new(),
            cr_at: None,
            done: false,
        }
    }

    /// After an error found in the lines read so far: the first read or encoding error in the rest
    /// of the file, which reading the whole file first would have reported instead.
    pub(super) fn error_in_rest(&mut self) -> Option<LogError> {
        loop {
            match self.next_line() {
                Ok(Some(_)) => {}
                Ok(None) => return None,
                Err(e) => return Some(e),
            }
        }
    }
}

impl<R: BufRead> Lines for ReaderLines<R> {
    fn next_line(&mut self) -> Result<Option<(usize, &str)>, LogError> {
        if let Some(at) = self.cr_at {
            if at > self.cr_text.len() {
                return Ok(None);
            }
            let len = self.cr_text[at..].find('\r').unwrap_or(self.cr_text.len() - at);
            self.cr_at = Some(at + len + 1);
            let n = self.number;
            self.number += 1;
            return Ok(Some((n, &self.cr_text[at..at + len])));
        }
        if self.done {
            return Ok(None);
        }
        self.offset += self.buf.len();
        self.buf.clear();
        self.reader
            .read_until(b'\n', &mut self.buf)
            .map_err(|e| io_error(&self.file, e))?;
        let first = self.offset == 0;
        let ends = self.buf.last() == Some(&b'\n');
        if !ends {
            // The last line (the whole file when it has no LF).
            self.done = true;
        }
        let text =
            std::str::from_utf8(&self.buf).map_err(|e| not_utf8(&self.file, &self.buf, self.offset, self.number, e))?;
        let mut text = if first {
            text.strip_prefix('\u{feff}').unwrap_or(text)
        } else {
            text
        };
        if first && !ends && text.contains('\r') {
            // CR alone ends the lines.
            self.cr_text = text.to_owned();
            self.cr_at = Some(0);
            return self.next_line();
        }
        if ends {
            text = &text[..text.len() - 1];
        }
        let text = text.strip_suffix('\r').unwrap_or(text);
        self.line.clear();
        self.line.push_str(text);
        let n = self.number;
        self.number += 1;
        Ok(Some((n, &self.line)))
    }
}

fn io_error(file: &str, e: std::io::Error) -> LogError {
    LogError::new(file, None, None, LogErrorKind::Io, format!("cannot read: {e}"))
}

/// The error [`super::read_log`] gives for a file that is not UTF-8: the offset of the first invalid
/// byte in the file, and its line.
fn not_utf8(file: &str, buf: &[u8], offset: usize, number: usize, e: std::str::Utf8Error) -> LogError {
    let bad = offset + e.valid_up_to();
    let newlines = buf[..e.valid_up_to()].iter().filter(|&&b| b == b'\n').count();
    LogError::new(
        file,
        Some(number + newlines),
        None,
        LogErrorKind::Encoding,
        format!("not UTF-8 text (invalid byte at offset {bad})"),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read_all(bytes: &[u8]) -> Result<Vec<(usize, String)>, LogError> {
        let mut r = ReaderLines::new(std::io::BufReader::with_capacity(3, bytes), "f.csv");
        let mut out = Vec::new();
        while let Some((n, l)) = r.next_line()? {
            out.push((n, l.to_owned()));
        }
        Ok(out)
    }

    fn text_all(text: &str) -> Vec<(usize, String)> {
        let mut r = TextLines::new(text);
        let mut out = Vec::new();
        while let Some((n, l)) = r.next_line().unwrap() {
            out.push((n, l.to_owned()));
        }
        out
    }

    #[test]
    fn the_reader_splits_as_the_text_does() {
        for text in [
            "",
            "a",
            "a\n",
            "a\nb",
            "a\r\nb\r\n",
            "a\rb\rc",
            "a\rb\r",
            "\u{feff}a\nb",
            "\u{feff}a\rb",
            "\n\n",
            "a\r\rb\n",
            "é,ü\n\u{2003}\n",
        ] {
            assert_eq!(read_all(text.as_bytes()).unwrap(), text_all(text), "{text:?}");
        }
    }

    #[test]
    fn invalid_utf8_is_found_at_the_same_byte_and_line() {
        let bytes = b"ab\ncd\ne\xfff\n";
        let e = read_all(bytes).unwrap_err();
        assert_eq!(e.kind, LogErrorKind::Encoding);
        assert_eq!(e.line, Some(3));
        assert_eq!(e.message, "not UTF-8 text (invalid byte at offset 7)");
        let e = read_all(b"a\rb\xc3").unwrap_err();
        assert_eq!(
            (e.line, e.message.as_str()),
            (Some(1), "not UTF-8 text (invalid byte at offset 3)")
        );
    }
}
