//! The CSV reader of the attribute table.

/// One CSV record: the line it starts on and its fields.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CsvRecord {
    pub line: usize,
    pub fields: Vec<String>,
}

/// The separator of a CSV text: the most frequent of `;`, tab and `,` outside quotes in
/// the first record (ties in that order; `;` when there is none).
pub fn detect_separator(text: &str) -> char {
    let mut counts = [0usize; 3];
    let mut quoted = false;
    for c in text.chars() {
        match c {
            '"' => quoted = !quoted,
            '\n' | '\r' if !quoted => break,
            ';' if !quoted => counts[0] += 1,
            '\t' if !quoted => counts[1] += 1,
            ',' if !quoted => counts[2] += 1,
            _ => {}
        }
    }
    let seps = [';', '\t', ','];
    let mut best = 0;
    for i in 1..3 {
        if counts[i] > counts[best] {
            best = i;
        }
    }
    seps[best]
}

/// The fields of one CSV record as [`for_each_csv_record`] hands them out: one text buffer
/// and the end of each field in it (no `String` per field).
#[derive(Debug, Default)]
pub struct CsvFields {
    pub(super) buf: String,
    pub(super) ends: Vec<usize>,
}

impl CsvFields {
    /// The number of fields.
    pub fn len(&self) -> usize {
        self.ends.len()
    }

    pub fn is_empty(&self) -> bool {
        self.ends.is_empty()
    }

    /// Field `i` (`""` past the end).
    pub fn get(&self, i: usize) -> &str {
        match self.ends.get(i) {
            Some(&end) => &self.buf[if i == 0 { 0 } else { self.ends[i - 1] }..end],
            None => "",
        }
    }

    /// Every field, in order.
    pub fn iter(&self) -> impl Iterator<Item = &str> + '_ {
        (0..self.len()).map(|i| self.get(i))
    }

    fn start(&self) -> usize {
        self.ends.last().copied().unwrap_or(0)
    }

    /// Ends the field that started at [`CsvFields::start`]; unquoted fields are trimmed.
    fn end_field(&mut self, quoted: bool) {
        let start = self.start();
        let plain =
            |b: Option<&u8>| b.is_some_and(|&b| b.is_ascii() && !(b as char).is_whitespace());
        let field = &self.buf.as_bytes()[start..];
        // Nothing to trim when both ends are ASCII and not blank (the usual cell).
        let trimmed = field.is_empty() || plain(field.first()) && plain(field.last());
        if !quoted && !trimmed {
            let s = &self.buf[start..];
            let lead = s.len() - s.trim_start().len();
            let len = s.trim().len();
            self.buf.drain(start..start + lead);
            self.buf.truncate(start + len);
        }
        self.ends.push(self.buf.len());
    }

    pub(super) fn clear(&mut self) {
        self.buf.clear();
        self.ends.clear();
    }
}

/// Splits CSV text into records (RFC 4180 quoting: `"a ""b"""`, quoted fields may hold
/// separators and line breaks). Unquoted fields are trimmed; blank lines are skipped.
/// Errors: `(line, message)` for text after a closing quote or an unterminated quote.
pub fn parse_csv(text: &str, sep: char) -> Result<Vec<CsvRecord>, (usize, String)> {
    let mut records = Vec::new();
    for_each_csv_record(text, sep, |line, fields| {
        records.push(CsvRecord {
            line,
            fields: fields.iter().map(str::to_owned).collect(),
        });
        Ok(())
    })?;
    Ok(records)
}

/// [`parse_csv`] streaming: calls `record(line, fields)` for each record as it is read,
/// with one reused buffer; an error of `record` stops the reading and is returned.
///
/// Reads bytes, not chars: every byte that means something (the separator's first byte,
/// `"`, CR, LF) is ASCII or starts a char, so the text between two of them is copied as
/// one slice (a large plant's million rows are read at start).
pub fn for_each_csv_record(
    text: &str,
    sep: char,
    mut record: impl FnMut(usize, &CsvFields) -> Result<(), (usize, String)>,
) -> Result<(), (usize, String)> {
    let mut sep_utf8 = [0u8; 4];
    let sep_str: &str = sep.encode_utf8(&mut sep_utf8);
    let sep0 = sep_str.as_bytes()[0];
    let bytes = text.as_bytes();
    let special = |b: u8| b == sep0 || matches!(b, b'"' | b'\r' | b'\n');
    let mut fields = CsvFields::default();
    let mut line = 1usize;
    let mut record_line = 1usize;
    // State of the current field: was it quoted, and is the quote closed.
    let mut quoted = false;
    let mut in_quotes = false;
    let mut quote_line = 0usize;
    let mut after_quote = false;
    let mut end_record =
        |fields: &mut CsvFields, quoted: bool, record_line: usize| -> Result<(), (usize, String)> {
            fields.end_field(quoted);
            let r = if !(fields.len() == 1 && fields.get(0).is_empty() && !quoted) {
                record(record_line, fields)
            } else {
                Ok(())
            };
            fields.clear();
            r
        };
    let mut i = 0;
    while i < bytes.len() {
        let b = bytes[i];
        if in_quotes {
            match b {
                b'"' if bytes.get(i + 1) == Some(&b'"') => {
                    fields.buf.push('"');
                    i += 2;
                }
                b'"' => {
                    in_quotes = false;
                    after_quote = true;
                    i += 1;
                }
                b'\r' | b'\n' => {
                    i += if b == b'\r' && bytes.get(i + 1) == Some(&b'\n') {
                        2
                    } else {
                        1
                    };
                    line += 1;
                    fields.buf.push('\n');
                }
                _ => {
                    let run = bytes[i..]
                        .iter()
                        .position(|&b| matches!(b, b'"' | b'\r' | b'\n'))
                        .map_or(bytes.len(), |k| i + k);
                    fields.buf.push_str(&text[i..run]);
                    i = run;
                }
            }
            continue;
        }
        if b == sep0 && (sep_str.len() == 1 || text[i..].starts_with(sep_str)) {
            fields.end_field(quoted);
            quoted = false;
            after_quote = false;
            i += sep_str.len();
            continue;
        }
        match b {
            b'\r' | b'\n' => {
                i += if b == b'\r' && bytes.get(i + 1) == Some(&b'\n') {
                    2
                } else {
                    1
                };
                end_record(&mut fields, quoted, record_line)?;
                quoted = false;
                after_quote = false;
                line += 1;
                record_line = line;
            }
            _ if after_quote => {
                let c = text[i..].chars().next().unwrap_or(' ');
                if !c.is_whitespace() {
                    return Err((line, format!("text `{c}` after a closing quote")));
                }
                i += c.len_utf8();
            }
            b'"' if fields.buf[fields.start()..].trim().is_empty() => {
                let start = fields.start();
                fields.buf.truncate(start);
                quoted = true;
                in_quotes = true;
                quote_line = line;
                i += 1;
            }
            _ => {
                // Up to the next byte that means something (a char boundary).
                let run = bytes[i + 1..]
                    .iter()
                    .position(|&b| special(b))
                    .map_or(bytes.len(), |k| i + 1 + k);
                fields.buf.push_str(&text[i..run]);
                i = run;
            }
        }
    }
    if in_quotes {
        return Err((quote_line, "quoted field is not closed".into()));
    }
    if !fields.is_empty() || fields.buf.len() > fields.start() || quoted {
        end_record(&mut fields, quoted, record_line)?;
    }
    Ok(())
}

#[cfg(test)]
/// A char-by-char reader, the plain reference that [`for_each_csv_record`]'s tests
/// compare the byte reader with.
///
/// [`parse_csv`] streaming: calls `record(line, fields)` for each record as it is read,
/// with one reused buffer; an error of `record` stops the reading and is returned.
pub(super) fn for_each_csv_record_chars(
    text: &str,
    sep: char,
    mut record: impl FnMut(usize, &CsvFields) -> Result<(), (usize, String)>,
) -> Result<(), (usize, String)> {
    let mut fields = CsvFields::default();
    let mut line = 1usize;
    let mut record_line = 1usize;
    let mut chars = text.chars().peekable();
    // State of the current field: was it quoted, and is the quote closed.
    let mut quoted = false;
    let mut in_quotes = false;
    let mut quote_line = 0usize;
    let mut after_quote = false;
    let mut end_record =
        |fields: &mut CsvFields, quoted: bool, record_line: usize| -> Result<(), (usize, String)> {
            fields.end_field(quoted);
            let r = if !(fields.len() == 1 && fields.get(0).is_empty() && !quoted) {
                record(record_line, fields)
            } else {
                Ok(())
            };
            fields.clear();
            r
        };
    while let Some(c) = chars.next() {
        if in_quotes {
            match c {
                '"' if chars.peek() == Some(&'"') => {
                    chars.next();
                    fields.buf.push('"');
                }
                '"' => {
                    in_quotes = false;
                    after_quote = true;
                }
                '\r' => {
                    if chars.peek() == Some(&'\n') {
                        chars.next();
                    }
                    line += 1;
                    fields.buf.push('\n');
                }
                '\n' => {
                    line += 1;
                    fields.buf.push('\n');
                }
                _ => fields.buf.push(c),
            }
            continue;
        }
        if c == sep {
            fields.end_field(quoted);
            quoted = false;
            after_quote = false;
            continue;
        }
        match c {
            '\r' | '\n' => {
                if c == '\r' && chars.peek() == Some(&'\n') {
                    chars.next();
                }
                end_record(&mut fields, quoted, record_line)?;
                quoted = false;
                after_quote = false;
                line += 1;
                record_line = line;
            }
            _ if after_quote => {
                if !c.is_whitespace() {
                    return Err((line, format!("text `{c}` after a closing quote")));
                }
            }
            '"' if fields.buf[fields.start()..].trim().is_empty() => {
                let start = fields.start();
                fields.buf.truncate(start);
                quoted = true;
                in_quotes = true;
                quote_line = line;
            }
            _ => fields.buf.push(c),
        }
    }
    if in_quotes {
        return Err((quote_line, "quoted field is not closed".into()));
    }
    if !fields.is_empty() || fields.buf.len() > fields.start() || quoted {
        end_record(&mut fields, quoted, record_line)?;
    }
    Ok(())
}
