//! The Paradox reader of the attribute table: the original's `.DB` table (and its `.MB`
//! memo file), read in place of the CSV, each record handed out as text cells like a CSV
//! record so that the same table builder checks it.
//!
//! The format (Paradox 3 to 7 data files, as the Borland engines and pxlib write them):
//! a header of `headerSize` bytes (little-endian: record size, block size, record and
//! block counts, the first block, the field descriptors, the table and field names, the
//! DOS code page from version 4), then data blocks of `maxTableSize` KB, each a linked
//! list node (next block, previous block, the bytes used less one record) followed by its
//! records. A record's fields are big-endian with the sign bit flipped (so that all
//! zeroes is blank); text is in the table's code page.
//!
//! Every size and offset from the file is checked against the file's length before it is
//! used, and memory is bounded by one block and the header (both at most 64 KB) plus the
//! cells themselves, which grow at most linearly with the files (a record's text is at
//! most [`MAX_ROW_BYTES`], the memos together at most the `.MB` file): any input gives a
//! table or an error, never a panic.

use std::io::Write as _;

use super::cells::MAX_ROW_BYTES;
use super::csv::CsvFields;
use super::DbError;
use crate::text::{decode_cp852_into, decode_windows_1250_into, Warning};

/// Where the reader takes the table's bytes from: a file (read block by block) or bytes
/// in memory.
pub trait ParadoxSource {
    /// The length of the table file in bytes.
    fn size(&self) -> u64;
    /// Fills `buf` with the bytes at `offset` (the caller checked they are in the file).
    fn read_at(&mut self, offset: u64, buf: &mut [u8]) -> std::io::Result<()>;
}

impl ParadoxSource for &[u8] {
    fn size(&self) -> u64 {
        self.len() as u64
    }
    fn read_at(&mut self, offset: u64, buf: &mut [u8]) -> std::io::Result<()> {
        let start = usize::try_from(offset).unwrap_or(usize::MAX);
        match start
            .checked_add(buf.len())
            .and_then(|end| self.get(start..end))
        {
            Some(bytes) => {
                buf.copy_from_slice(bytes);
                Ok(())
            }
            None => Err(std::io::ErrorKind::UnexpectedEof.into()),
        }
    }
}

impl<S: ParadoxSource + ?Sized> ParadoxSource for &mut S {
    fn size(&self) -> u64 {
        (**self).size()
    }
    fn read_at(&mut self, offset: u64, buf: &mut [u8]) -> std::io::Result<()> {
        (**self).read_at(offset, buf)
    }
}

impl ParadoxSource for std::fs::File {
    fn size(&self) -> u64 {
        self.metadata().map_or(0, |m| m.len())
    }
    fn read_at(&mut self, offset: u64, buf: &mut [u8]) -> std::io::Result<()> {
        use std::io::{Read, Seek, SeekFrom};
        self.seek(SeekFrom::Start(offset))?;
        self.read_exact(buf)
    }
}

/// A field type of a Paradox table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FieldType {
    /// `A`: text of up to 255 bytes in the table's code page.
    Alpha,
    /// `D`: a date (days from 1 January of year 1 as day 1).
    Date,
    /// `S`: a 16-bit integer.
    Short,
    /// `I`: a 32-bit integer.
    Long,
    /// `$`: money, stored as a number.
    Currency,
    /// `N`: a real number (IEEE double).
    Number,
    /// `L`: true or false (read as `tak` / `nie`, the database's booleans).
    Logical,
    /// `M`: a memo: text whose head is in the record and whose rest is in the `.MB` file.
    Memo,
    /// `T`: a time of day (milliseconds from midnight).
    Time,
    /// `@`: a date and time (milliseconds from the start of day 1).
    Timestamp,
    /// `+`: an autoincrementing 32-bit integer.
    AutoInc,
}

impl FieldType {
    /// The type of code `code` with size `size`, or why an attribute table cannot hold it.
    fn from_code(code: u8, size: u8) -> Result<FieldType, String> {
        let (t, fixed) = match code {
            0x01 => (FieldType::Alpha, None),
            0x02 => (FieldType::Date, Some(4)),
            0x03 => (FieldType::Short, Some(2)),
            0x04 => (FieldType::Long, Some(4)),
            0x05 => (FieldType::Currency, Some(8)),
            0x06 => (FieldType::Number, Some(8)),
            0x09 => (FieldType::Logical, Some(1)),
            0x0C => (FieldType::Memo, None),
            0x14 => (FieldType::Time, Some(4)),
            0x15 => (FieldType::Timestamp, Some(8)),
            0x16 => (FieldType::AutoInc, Some(4)),
            0x0D => return Err("a binary BLOb (B), which is not text".into()),
            0x0E => return Err("a formatted memo (F), which is not plain text".into()),
            0x0F => return Err("an OLE object (O), which is not text".into()),
            0x10 => return Err("a graphic (G), which is not text".into()),
            0x17 => return Err("a BCD number (#), which this reader does not decode".into()),
            0x18 => return Err("bytes (Y), which are not text".into()),
            other => return Err(format!("of unknown type 0x{other:02X}")),
        };
        let ok = match (t, fixed) {
            (_, Some(n)) => size == n,
            (FieldType::Alpha, None) => size >= 1,
            // The memo's 10-byte reference and a head of at least one byte.
            _ => size > MEMO_REF,
        };
        if !ok {
            return Err(format!("{} with a size of {size} bytes", t.letter()));
        }
        Ok(t)
    }

    /// The type's letter in Paradox's own notation.
    pub fn letter(self) -> char {
        match self {
            FieldType::Alpha => 'A',
            FieldType::Date => 'D',
            FieldType::Short => 'S',
            FieldType::Long => 'I',
            FieldType::Currency => '$',
            FieldType::Number => 'N',
            FieldType::Logical => 'L',
            FieldType::Memo => 'M',
            FieldType::Time => 'T',
            FieldType::Timestamp => '@',
            FieldType::AutoInc => '+',
        }
    }
}

/// The last bytes of a memo field: where the memo is in the `.MB` file, its length and
/// its modification number.
const MEMO_REF: u8 = 10;

/// The code page of a table's text.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CodePage {
    /// Windows-1250 (the header says 1250).
    Windows1250,
    /// CP852, DOS Latin-2 (the header says 852).
    Cp852,
    /// Any other code page (the number in the header; 0 when the header has none, as in
    /// Paradox 3): read as Windows-1250, what asix writes on Polish Windows.
    Other(u16),
}

impl CodePage {
    fn from_header(n: u16) -> CodePage {
        match n {
            1250 => CodePage::Windows1250,
            852 => CodePage::Cp852,
            n => CodePage::Other(n),
        }
    }

    fn decode_into(self, bytes: &[u8], out: &mut String) {
        match self {
            CodePage::Cp852 => decode_cp852_into(bytes, out),
            CodePage::Windows1250 | CodePage::Other(_) => decode_windows_1250_into(bytes, out),
        }
    }

    fn decode(self, bytes: &[u8]) -> String {
        let mut s = String::with_capacity(bytes.len());
        self.decode_into(bytes, &mut s);
        s
    }
}

/// A field of the table.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ParadoxField {
    pub name: String,
    pub field_type: FieldType,
    /// Bytes in the record.
    pub size: usize,
}

/// What the header of a Paradox table says.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ParadoxHeader {
    pub fields: Vec<ParadoxField>,
    pub record_size: usize,
    pub records: u32,
    pub code_page: CodePage,
    /// Paradox's version number of the file (3 for 3.0 ... 12 for 7).
    pub version: u8,
    header_size: u64,
    block_size: usize,
    file_blocks: u16,
    first_block: u16,
}

fn le16(b: &[u8], at: usize) -> Option<u16> {
    Some(u16::from_le_bytes([*b.get(at)?, *b.get(at + 1)?]))
}

fn le32(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes([
        *b.get(at)?,
        *b.get(at + 1)?,
        *b.get(at + 2)?,
        *b.get(at + 3)?,
    ]))
}

/// The size of the fixed part of the header that every data file has.
const COMMON_HEADER: usize = 0x58;
/// Where the field descriptors start in tables of Paradox 4 and later.
const V4_FIELDS: usize = 0x78;
/// The bytes of a data block's own header (next, previous, size).
const BLOCK_HEADER: usize = 6;

/// Reads and checks the header of a Paradox table.
pub fn read_paradox_header(
    src: &mut impl ParadoxSource,
    file: &str,
) -> Result<ParadoxHeader, DbError> {
    let bad = |m: String| DbError::invalid(file, 0, format!("not a usable Paradox table: {m}"));
    let len = src.size();
    if len < COMMON_HEADER as u64 {
        return Err(bad(format!(
            "{len} bytes, shorter than a Paradox header ({COMMON_HEADER} bytes)"
        )));
    }
    let mut fixed = [0u8; COMMON_HEADER];
    src.read_at(0, &mut fixed)
        .map_err(|e| bad(format!("the header cannot be read: {e}")))?;
    let h = &fixed[..];
    let field = |at: usize| le16(h, at).unwrap_or(0);
    let record_size = usize::from(field(0x00));
    let header_size = usize::from(field(0x02));
    let file_type = h[0x04];
    let max_table_size = h[0x05];
    let records = le32(h, 0x06).unwrap_or(0);
    let file_blocks = field(0x0C);
    let first_block = field(0x0E);
    let nfields = usize::from(field(0x21));
    let encryption1 = le32(h, 0x25).unwrap_or(0);
    let version = h[0x39];
    if !matches!(file_type, 0 | 2) {
        return Err(bad(format!(
            "file type {file_type} is not a data table (.DB); an index or other Paradox file?"
        )));
    }
    if !(3..=12).contains(&version) {
        return Err(bad(format!("unknown file version {version}")));
    }
    if !(1..=32).contains(&max_table_size) {
        return Err(bad(format!("unknown block size {max_table_size} KB")));
    }
    let block_size = usize::from(max_table_size) * 0x400;
    if record_size == 0 || record_size + BLOCK_HEADER > block_size {
        return Err(bad(format!(
            "a record of {record_size} bytes does not fit a block of {block_size} bytes"
        )));
    }
    if header_size < COMMON_HEADER {
        return Err(bad(format!(
            "the header size {header_size} is smaller than the fixed header ({COMMON_HEADER})"
        )));
    }
    if header_size as u64 > len {
        return Err(bad(format!(
            "the header size {header_size} is past the end of the file ({len} bytes)"
        )));
    }
    if nfields == 0 || nfields > 255 {
        return Err(bad(format!("{nfields} fields (1 to 255 are possible)")));
    }
    let mut head = vec![0u8; header_size];
    src.read_at(0, &mut head)
        .map_err(|e| bad(format!("the header cannot be read: {e}")))?;
    let v4 = version >= 5;
    let (code_page, encryption) = if v4 {
        let cp = le16(&head, 0x6A).ok_or_else(|| bad("the header is cut short".into()))?;
        let enc2 = le32(&head, 0x5C).unwrap_or(0);
        (
            CodePage::from_header(cp),
            if encryption1 == 0xFF00_FF00 {
                enc2
            } else {
                encryption1
            },
        )
    } else {
        (CodePage::Other(0), encryption1)
    };
    if encryption != 0 {
        return Err(bad(
            "the table is encrypted (password-protected); save it without a password".into(),
        ));
    }
    let short = || bad("the header is cut short (field descriptors or names)".into());
    let mut at = if v4 { V4_FIELDS } else { COMMON_HEADER };
    let mut types = Vec::with_capacity(nfields);
    for _ in 0..nfields {
        let code = *head.get(at).ok_or_else(short)?;
        let size = *head.get(at + 1).ok_or_else(short)?;
        types.push((code, size));
        at += 2;
    }
    // The table-name pointer and one pointer per field name (run-time values), then the
    // table name (79 bytes; 261 from Paradox 7), then the field names, NUL-terminated.
    at += 4 + 4 * nfields + if version >= 12 { 261 } else { 79 };
    let mut fields = Vec::with_capacity(nfields);
    for (i, &(code, size)) in types.iter().enumerate() {
        let rest = head.get(at..).ok_or_else(short)?;
        let end = rest.iter().position(|&b| b == 0).ok_or_else(short)?;
        let name = code_page.decode(&rest[..end]);
        at += end + 1;
        let field_type = FieldType::from_code(code, size).map_err(|m| {
            bad(format!(
                "field {} `{name}` is {m}; an attribute table holds text, numbers, \
                 logicals, dates, times and memos",
                i + 1
            ))
        })?;
        fields.push(ParadoxField {
            name,
            field_type,
            size: usize::from(size),
        });
    }
    let sum: usize = fields.iter().map(|f| f.size).sum();
    if sum != record_size {
        return Err(bad(format!(
            "the fields take {sum} bytes but a record has {record_size}"
        )));
    }
    Ok(ParadoxHeader {
        fields,
        record_size,
        records,
        code_page,
        version,
        header_size: header_size as u64,
        block_size,
        file_blocks,
        first_block,
    })
}

/// Reads the records of a Paradox table whose header is `header`
/// ([`read_paradox_header`]) in the order of the data blocks' chain, each handed to `record(n, fields)` as text cells (`n` counts records from 1;
/// blank fields are empty cells). `memo` is the table's `.MB` file when it has one.
/// Warnings (a code page read as Windows-1250) go to `warnings`.
///
/// The cells: alpha and memo text decoded from the table's code page (surrounding blanks
/// removed, as from an unquoted CSV cell); numbers in the shortest form that reads back
/// to the same value (`0.5`, `8`, `-20`); logicals `tak` / `nie`; dates `2024-03-01`,
/// times `13:05:00` (`.250` when there are milliseconds), timestamps both with a space.
pub fn for_each_paradox_record(
    mut src: impl ParadoxSource,
    header: &ParadoxHeader,
    memo: Option<&[u8]>,
    file: &str,
    warnings: &mut Vec<Warning>,
    mut record: impl FnMut(usize, &CsvFields) -> Result<(), (usize, String)>,
) -> Result<(), DbError> {
    let len = src.size();
    let bad_block =
        |block: u16, m: String| DbError::invalid(file, 0, format!("data block {block}: {m}"));
    let mut block = vec![0u8; header.block_size];
    let mut visited = vec![false; usize::from(header.file_blocks) + 1];
    let mut fields = CsvFields::default();
    let mut non_ascii_seen = false;
    let mut memo_bytes = 0usize;
    let mut n = 0usize;
    let mut next = header.first_block;
    while next != 0 {
        let this = next;
        if this > header.file_blocks {
            return Err(bad_block(
                this,
                format!(
                    "the chain of blocks leads past the {} blocks the header counts",
                    header.file_blocks
                ),
            ));
        }
        let seen = visited
            .get_mut(usize::from(this))
            .ok_or_else(|| bad_block(this, "outside the table".into()))?;
        if *seen {
            return Err(bad_block(this, "the chain of blocks loops".into()));
        }
        *seen = true;
        let offset = header.header_size + (u64::from(this) - 1) * header.block_size as u64;
        let end = offset + header.block_size as u64;
        // The last block may end where its records end.
        if offset + BLOCK_HEADER as u64 > len {
            return Err(bad_block(
                this,
                format!("it starts past the end of the file ({len} bytes): the file is truncated"),
            ));
        }
        let avail = (end.min(len) - offset) as usize;
        src.read_at(offset, &mut block[..avail])
            .map_err(|e| bad_block(this, format!("cannot be read: {e}")))?;
        next = le16(&block, 0).unwrap_or(0);
        let add = le16(&block, 4).unwrap_or(0) as i16;
        let in_block = if add < 0 {
            0
        } else {
            let add = add as usize;
            if !add.is_multiple_of(header.record_size)
                || add + header.record_size > header.block_size - BLOCK_HEADER
            {
                return Err(bad_block(
                    this,
                    format!(
                        "its size ({} bytes after the first record) is not a whole number of \
                         {}-byte records that fit the block",
                        add, header.record_size
                    ),
                ));
            }
            add / header.record_size + 1
        };
        let used = BLOCK_HEADER + in_block * header.record_size;
        if used > avail {
            return Err(bad_block(
                this,
                format!(
                    "its {in_block} records end past the end of the file ({len} bytes): \
                     the file is truncated"
                ),
            ));
        }
        let records = block.get(BLOCK_HEADER..used).unwrap_or_default();
        for bytes in records.chunks_exact(header.record_size) {
            n += 1;
            // The record's cells are built as bytes (valid UTF-8 by construction) in the
            // fields' own buffer and checked as text once, not once per cell.
            let mut row = std::mem::take(&mut fields.buf).into_bytes();
            row.clear();
            fields.ends.clear();
            let mut rest = bytes;
            for f in &header.fields {
                // The sizes add up to the record's (checked with the header).
                let (v, tail) = rest.split_at(f.size.min(rest.len()));
                rest = tail;
                let err = |m: String| {
                    DbError::invalid(
                        file,
                        n,
                        format!(
                            "record {n}, field `{}` ({}): {m}",
                            f.name,
                            f.field_type.letter()
                        ),
                    )
                };
                let start = row.len();
                match f.field_type {
                    FieldType::Alpha => {
                        let end = v.iter().position(|&b| b == 0).unwrap_or(v.len());
                        let text = v.get(..end).unwrap_or_default();
                        non_ascii_seen |= push_text(&mut row, header.code_page, text);
                        trim_cell(&mut row, start);
                    }
                    FieldType::Memo => {
                        let text = memo_text(v, memo).map_err(err)?;
                        // Each memo of the .MB file belongs to one record: memos taking
                        // more than the file holds are references shared (or damaged),
                        // which would multiply the text without bound.
                        if text.len() > v.len() {
                            memo_bytes += text.len();
                            if memo_bytes > memo.map_or(0, <[u8]>::len) {
                                return Err(err(
                                    "the memos take more bytes than the .MB file holds: \
                                     records share memos (a damaged table)"
                                        .into(),
                                ));
                            }
                        }
                        let text = match text.iter().rposition(|&b| b != 0) {
                            Some(last) => text.get(..=last).unwrap_or_default(),
                            None => &[],
                        };
                        non_ascii_seen |= push_text(&mut row, header.code_page, text);
                        trim_cell(&mut row, start);
                    }
                    _ => write_value(&mut row, f.field_type, v).map_err(err)?,
                }
                fields.ends.push(row.len());
            }
            if row.len() > MAX_ROW_BYTES {
                return Err(DbError::invalid(
                    file,
                    n,
                    format!("record {n} holds more than {MAX_ROW_BYTES} bytes of text"),
                ));
            }
            fields.buf = String::from_utf8(row)
                .map_err(|e| DbError::invalid(file, n, format!("record {n}: {e}")))?;
            record(n, &fields).map_err(|(line, m)| DbError::invalid(file, line, m))?;
        }
    }
    if n as u64 != u64::from(header.records) {
        return Err(DbError::invalid(
            file,
            0,
            format!(
                "the header counts {} records but the data blocks hold {n}: the table is \
                 damaged (rebuild it in Paradox or the asix database tools)",
                header.records
            ),
        ));
    }
    if let (CodePage::Other(cp), true) = (header.code_page, non_ascii_seen) {
        warnings.push(Warning::new(
            file,
            0,
            format!(
                "the table's code page is {cp}, not 1250 or 852: its text is read as \
                 Windows-1250"
            ),
        ));
    }
    Ok(())
}

/// Appends `text` decoded from the code page as UTF-8 (ASCII as it is); whether it held
/// anything but ASCII. Line breaks become `\n`, as the CSV reader reads them in a quoted
/// cell.
fn push_text(row: &mut Vec<u8>, cp: CodePage, text: &[u8]) -> bool {
    let start = row.len();
    let ascii = text.is_ascii();
    if ascii {
        row.extend_from_slice(text);
    } else {
        row.extend_from_slice(cp.decode(text).as_bytes());
    }
    if text.contains(&b'\r') {
        let mut out = Vec::with_capacity(row.len() - start);
        let mut bytes = row[start..].iter().peekable();
        while let Some(&b) = bytes.next() {
            if b == b'\r' {
                out.push(b'\n');
                bytes.next_if_eq(&&b'\n');
            } else {
                out.push(b);
            }
        }
        row.truncate(start);
        row.extend_from_slice(&out);
    }
    !ascii
}

/// Removes the blanks around the cell that starts at `start` (valid UTF-8, as
/// [`push_text`] writes it), as from an unquoted CSV cell: nothing to do when both ends
/// are ASCII and not blank, the usual cell.
fn trim_cell(row: &mut Vec<u8>, start: usize) {
    let plain = |b: Option<&u8>| b.is_some_and(|&b| b.is_ascii() && !b.is_ascii_whitespace());
    let cell = row.get(start..).unwrap_or_default();
    if cell.is_empty() || plain(cell.first()) && plain(cell.last()) {
        return;
    }
    let Ok(text) = std::str::from_utf8(cell) else {
        return;
    };
    let (lead, keep) = (text.len() - text.trim_start().len(), text.trim().len());
    row.drain(start..start + lead);
    row.truncate(start + keep);
}

/// Appends the decimal digits of `n` (the integers of the table, without the formatter).
fn push_int(buf: &mut Vec<u8>, n: i64) {
    let mut digits = [0u8; 20];
    let mut i = digits.len();
    let mut m = n.unsigned_abs();
    loop {
        i -= 1;
        digits[i] = b'0' + (m % 10) as u8;
        m /= 10;
        if m == 0 {
            break;
        }
    }
    if n < 0 {
        buf.push(b'-');
    }
    buf.extend_from_slice(&digits[i..]);
}

/// A big-endian field with the sign bit flipped, as an unsigned value; `None` when blank
/// (all zeroes).
fn flipped(v: &[u8]) -> Option<u64> {
    if v.iter().all(|&b| b == 0) {
        return None;
    }
    let raw = v.iter().fold(0u64, |a, &b| a << 8 | u64::from(b));
    Some(raw ^ 1 << (v.len() * 8 - 1))
}

/// A Paradox double (`N`, `$`, `@`): positive values have the sign bit set, negative
/// ones all bits inverted.
fn paradox_double(v: &[u8]) -> Option<f64> {
    let raw = v.iter().fold(0u64, |a, &b| a << 8 | u64::from(b));
    if raw == 0 {
        return None;
    }
    let bits = if raw & 1 << 63 != 0 {
        raw ^ 1 << 63
    } else {
        !raw
    };
    Some(f64::from_bits(bits))
}

/// The civil date of Paradox day `day` (day 1 is 1 January of year 1; day 719,163 is
/// 1970-01-01).
fn civil(day: i64) -> (i64, u32, u32) {
    ctopc_core::time::civil_from_days(day - 719_163)
}

/// The highest Paradox day written (31 December 9999).
const LAST_DAY: i64 = 3_652_059;
const DAY_MS: i64 = 86_400_000;

fn write_time(buf: &mut Vec<u8>, ms: i64) {
    let (h, m, s, f) = (ms / 3_600_000, ms / 60_000 % 60, ms / 1000 % 60, ms % 1000);
    let _ = write!(buf, "{h:02}:{m:02}:{s:02}");
    if f != 0 {
        let _ = write!(buf, ".{f:03}");
    }
}

fn write_date(buf: &mut Vec<u8>, day: i64) -> Result<(), String> {
    if !(1..=LAST_DAY).contains(&day) {
        return Err(format!("day {day} is not a date of years 1 to 9999"));
    }
    let (y, m, d) = civil(day);
    let _ = write!(buf, "{y:04}-{m:02}-{d:02}");
    Ok(())
}

/// Appends the text of a field that is not text (empty when blank).
fn write_value(buf: &mut Vec<u8>, t: FieldType, v: &[u8]) -> Result<(), String> {
    match t {
        FieldType::Short | FieldType::Long | FieldType::AutoInc => {
            if let Some(u) = flipped(v) {
                let n = if v.len() == 2 {
                    i64::from(u as u16 as i16)
                } else {
                    i64::from(u as u32 as i32)
                };
                push_int(buf, n);
            }
        }
        FieldType::Number | FieldType::Currency => {
            if let Some(x) = paradox_double(v) {
                if !x.is_finite() {
                    return Err(format!("{x} is not a number"));
                }
                // Whole numbers (most limits and ranges) without the float formatter;
                // the same text as `{x}` (`-0` included).
                if x.fract() == 0.0 && x.abs() < 1e15 && !(x == 0.0 && x.is_sign_negative()) {
                    push_int(buf, x as i64);
                } else {
                    let _ = write!(buf, "{x}");
                }
            }
        }
        FieldType::Logical => match v.first() {
            Some(0) | None => {}
            Some(0x80) => buf.extend_from_slice(b"nie"),
            Some(0x81) => buf.extend_from_slice(b"tak"),
            Some(b) => return Err(format!("0x{b:02X} is neither true nor false")),
        },
        FieldType::Date => {
            if let Some(u) = flipped(v) {
                write_date(buf, i64::from(u as u32 as i32))?;
            }
        }
        FieldType::Time => {
            if let Some(u) = flipped(v) {
                let ms = i64::from(u as u32 as i32);
                if !(0..DAY_MS).contains(&ms) {
                    return Err(format!("{ms} ms is not a time of day"));
                }
                write_time(buf, ms);
            }
        }
        FieldType::Timestamp => {
            if let Some(x) = paradox_double(v) {
                if !x.is_finite() || x < DAY_MS as f64 || x >= (LAST_DAY + 1) as f64 * DAY_MS as f64
                {
                    return Err(format!("{x} ms is not a time of years 1 to 9999"));
                }
                let ms = x.round() as i64;
                write_date(buf, ms / DAY_MS)?;
                buf.push(b' ');
                write_time(buf, ms % DAY_MS);
            }
        }
        FieldType::Alpha | FieldType::Memo => {}
    }
    Ok(())
}

/// The bytes of a memo field `v`: in the record when short (the head holds it all), else
/// in the `.MB` file `mb` (a block of its own, type 2, or a slot of a shared block,
/// type 3).
fn memo_text<'a>(v: &'a [u8], mb: Option<&'a [u8]>) -> Result<&'a [u8], String> {
    let head_len = v.len() - usize::from(MEMO_REF);
    let (head, reference) = v.split_at(head_len);
    let loc = le32(reference, 0).unwrap_or(0);
    let len = le32(reference, 4).unwrap_or(0) as usize;
    if len == 0 {
        return Ok(&[]);
    }
    if len <= head_len {
        return Ok(&head[..len]);
    }
    let Some(mb) = mb else {
        return Err(format!(
            "the memo ({len} bytes) is in the table's .MB file, which was not found"
        ));
    };
    let bad = |m: &str| format!("the memo ({len} bytes) in the .MB file: {m}");
    let offset = (loc & !0xFF) as usize;
    let index = (loc & 0xFF) as usize;
    let block = mb
        .get(offset..)
        .filter(|b| offset > 0 && b.len() >= 12)
        .ok_or_else(|| bad(&format!("offset {offset} is outside the file")))?;
    match block[0] {
        2 => {
            if index != 0xFF {
                return Err(bad("a block of its own but a slot number"));
            }
            if le32(block, 3) != Some(len as u32) {
                return Err(bad("its block holds another length"));
            }
            block
                .get(9..len.saturating_add(9))
                .ok_or_else(|| bad("its block ends past the end of the file"))
        }
        3 => {
            let slot = block
                .get(12 + index * 5..12 + index * 5 + 5)
                .filter(|_| index < 64)
                .ok_or_else(|| bad(&format!("slot {index} does not exist")))?;
            let (start, units, last) = (
                usize::from(slot[0]) * 16,
                usize::from(slot[1]),
                usize::from(slot[4]),
            );
            if start == 0 || units == 0 || (units - 1) * 16 + last != len {
                return Err(bad(&format!("slot {index} holds another length")));
            }
            block
                .get(start..start + len)
                .filter(|_| start + len <= 4096)
                .ok_or_else(|| bad(&format!("slot {index} ends past its block")))
        }
        t => Err(bad(&format!(
            "offset {offset} is a block of type {t}, not a memo"
        ))),
    }
}

/// The cells of a Paradox table as a CSV attribute table (`;`-separated, quoted where a
/// cell holds `;`, `"`, a line break or surrounding blanks; UTF-8 with a byte-order mark,
/// CRLF): what `opcdiag export-db` writes for plants that prefer text; the loader reads
/// it back to the same table.
pub fn paradox_to_csv(
    src: impl ParadoxSource,
    memo: Option<&[u8]>,
    file: &str,
    warnings: &mut Vec<Warning>,
) -> Result<String, DbError> {
    let mut src = src;
    let header = read_paradox_header(&mut src, file)?;
    let mut out = String::from("\u{FEFF}");
    push_csv_row(&mut out, header.fields.iter().map(|f| f.name.as_str()));
    for_each_paradox_record(src, &header, memo, file, warnings, |_, fields| {
        push_csv_row(&mut out, fields.iter());
        Ok(())
    })?;
    Ok(out)
}

fn push_csv_row<'a>(out: &mut String, cells: impl Iterator<Item = &'a str>) {
    let start = out.len();
    for (i, c) in cells.enumerate() {
        if i > 0 {
            out.push(';');
        }
        let quote = c.contains([';', '"', '\r', '\n', '\t', ','])
            || c.starts_with(char::is_whitespace)
            || c.ends_with(char::is_whitespace);
        if quote {
            out.push('"');
            out.push_str(&c.replace('"', "\"\""));
            out.push('"');
        } else {
            out.push_str(c);
        }
    }
    // A blank line would be skipped: one empty cell is written quoted.
    if out.len() == start {
        out.push_str("\"\"");
    }
    out.push_str("\r\n");
}

#[cfg(test)]
mod tests {
    use super::*;

    fn text(b: &[u8]) -> &str {
        std::str::from_utf8(b).unwrap()
    }

    #[test]
    fn numbers_decode_with_the_sign_bit_flipped() {
        let mut s = Vec::new();
        write_value(&mut s, FieldType::Short, &[0x80, 0x01]).unwrap();
        s.push(b' ');
        write_value(&mut s, FieldType::Short, &[0x7F, 0xFF]).unwrap();
        s.push(b' ');
        write_value(&mut s, FieldType::Long, &[0x80, 0, 1, 0]).unwrap();
        s.push(b' ');
        write_value(&mut s, FieldType::Short, &[0, 0]).unwrap();
        s.push(b'|');
        let n = |x: f64| {
            let b = x.to_bits();
            (if x.is_sign_negative() {
                !b
            } else {
                b | 1 << 63
            })
            .to_be_bytes()
        };
        for x in [0.5, 8.0, -20.0, 1e-7, -0.25] {
            write_value(&mut s, FieldType::Number, &n(x)).unwrap();
            s.push(b' ');
        }
        write_value(&mut s, FieldType::Number, &[0; 8]).unwrap();
        assert_eq!(text(&s), "1 -1 256 |0.5 8 -20 0.0000001 -0.25 ");
    }

    #[test]
    fn whole_numbers_read_as_the_formatter_writes_them() {
        let n = |x: f64| {
            let b = x.to_bits();
            (if x.is_sign_negative() {
                !b
            } else {
                b | 1 << 63
            })
            .to_be_bytes()
        };
        for x in [
            0.0,
            -0.0,
            1.0,
            -1.0,
            10.0,
            99.0,
            1e14,
            -1e14 + 1.0,
            1e15,
            1e16,
            2.5,
        ] {
            let mut s = Vec::new();
            write_value(&mut s, FieldType::Number, &n(x)).unwrap();
            assert_eq!(text(&s), format!("{x}"));
        }
        for i in [
            0i64,
            7,
            -7,
            32767,
            -32767,
            i64::from(i32::MAX),
            i64::from(i32::MIN),
        ] {
            let mut s = Vec::new();
            push_int(&mut s, i);
            assert_eq!(text(&s), i.to_string());
        }
    }

    #[test]
    fn dates_and_times() {
        let mut s = Vec::new();
        let d = |day: u32| (day ^ 1 << 31).to_be_bytes();
        write_value(&mut s, FieldType::Date, &d(1)).unwrap();
        s.push(b' ');
        // 2024-02-29: day 738,945 (the proleptic Gregorian ordinal).
        write_value(&mut s, FieldType::Date, &d(738_945)).unwrap();
        s.push(b' ');
        write_value(
            &mut s,
            FieldType::Time,
            &d(13 * 3_600_000 + 5 * 60_000 + 250),
        )
        .unwrap();
        assert_eq!(text(&s), "0001-01-01 2024-02-29 13:05:00.250");
        assert!(write_value(&mut s, FieldType::Date, &d(0x7FFF_FFFF)).is_err());
        assert!(write_value(&mut s, FieldType::Time, &d(86_400_000)).is_err());
    }

    #[test]
    fn cells_are_trimmed_as_unquoted_csv_cells() {
        for (cell, want) in [
            ("abc", "abc"),
            ("  abc ", "abc"),
            ("\u{A0}x\u{A0}", "x"),
            ("   ", ""),
            ("a b", "a b"),
        ] {
            let mut row = b"pre".to_vec();
            row.extend_from_slice(cell.as_bytes());
            trim_cell(&mut row, 3);
            assert_eq!(text(&row), format!("pre{want}"), "{cell:?}");
        }
        let mut row = Vec::new();
        push_text(&mut row, CodePage::Windows1250, b"a\r\nb\rc\n");
        assert_eq!(text(&row), "a\nb\nc\n");
    }

    #[test]
    fn garbage_is_an_error_not_a_panic() {
        let mut w = Vec::new();
        for len in [0usize, 10, 0x57, 0x58, 0x100, 0x800] {
            let bytes = vec![0xFFu8; len];
            let r = paradox_to_csv(&bytes[..], None, "t.DB", &mut w);
            assert!(r.is_err(), "{len}");
        }
    }
}
