//! [`CellTable`]: every cell of the attribute table in one text.

use super::csv::CsvFields;

/// Every cell of the attribute table in one text, row after row: the start of each row
/// in it (`u32`) and the end of each cell relative to its row's start: cell `k` (row
/// `r = k / ncols`, column `c = k % ncols`) is `text[starts[r] + ends[k - 1]..starts[r] +
/// ends[k]]` (from the row's start when `c` is 0). The ends are one byte (`u8`) for rows
/// of up to 255 bytes of text, the usual row; a longer row (at most 65,535 bytes) has its
/// ends in `wide_ends` (`u16`), found through `wide_rows`, and zeros in `ends`. So 1 byte
/// per cell and 4 per row plus the text itself, and a line per run of rows on consecutive
/// lines (one run for a file without blank lines or line breaks in quoted cells).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub(super) struct CellTable {
    pub(super) text: String,
    pub(super) starts: Vec<u32>,
    pub(super) ends: Vec<u8>,
    /// The rows of more than 255 bytes, by row: (row, where its ends start in `wide_ends`).
    pub(super) wide_rows: Vec<(u32, u32)>,
    pub(super) wide_ends: Vec<u16>,
    pub(super) ncols: usize,
    /// Runs of rows on consecutive lines of the file, by row: (first row, its line).
    pub(super) line_runs: Vec<(u32, u32)>,
}

/// The most text a row of the attribute table may hold ([`CellTable`]'s `u16` ends).
pub const MAX_ROW_BYTES: usize = u16::MAX as usize;

/// The most text of a row whose cell ends are one byte each ([`CellTable`]).
pub(super) const NARROW_ROW_BYTES: usize = u8::MAX as usize;

impl CellTable {
    pub(super) fn rows(&self) -> usize {
        self.starts.len()
    }

    pub(super) fn push_row<'a>(
        &mut self,
        line: usize,
        cells: impl Iterator<Item = &'a str>,
    ) -> Result<(), (usize, String)> {
        let start = self.text.len();
        let too_long = |m: &str| (line, m.to_owned());
        let start32 = u32::try_from(start)
            .map_err(|_| too_long("the attribute table holds more than 4 GB of text"))?;
        let row = u32::try_from(self.starts.len())
            .map_err(|_| too_long("the attribute table holds more than 4 billion rows"))?;
        let cells_before = self.ends.len();
        let wide_before = self.wide_ends.len();
        let wide_start = u32::try_from(wide_before)
            .map_err(|_| too_long("the attribute table holds too many long rows"))?;
        let mut wide = false;
        for c in cells {
            self.text.push_str(c);
            let len = self.text.len() - start;
            let Ok(end) = u16::try_from(len) else {
                self.text.truncate(start);
                self.ends.truncate(cells_before);
                self.wide_ends.truncate(wide_before);
                return Err(too_long(&format!(
                    "the row holds more than {MAX_ROW_BYTES} bytes of text"
                )));
            };
            if !wide && len > NARROW_ROW_BYTES {
                // The row's ends so far move to `wide_ends`.
                wide = true;
                let row_ends = &mut self.ends[cells_before..];
                self.wide_ends
                    .extend(row_ends.iter().map(|&e| u16::from(e)));
                row_ends.fill(0);
            }
            if wide {
                self.wide_ends.push(end);
                self.ends.push(0);
            } else {
                self.ends.push(end as u8);
            }
        }
        if wide {
            self.wide_rows.push((row, wide_start));
        }
        self.starts.push(start32);
        self.push_line(row, line);
        Ok(())
    }

    /// [`CellTable::push_row`] of the first `ncols` fields of a CSV record (missing ones
    /// empty): the record's buffer is its cells one after the other, so a row of up to
    /// 255 bytes is copied at once with its ends.
    pub(super) fn push_fields(
        &mut self,
        line: usize,
        fields: &CsvFields,
        ncols: usize,
    ) -> Result<(), (usize, String)> {
        let n = fields.len().min(ncols);
        let len = n.checked_sub(1).map_or(0, |last| fields.ends[last]);
        let (Ok(start), Ok(row)) = (
            u32::try_from(self.text.len()),
            u32::try_from(self.starts.len()),
        ) else {
            return self.push_row(line, (0..ncols).map(|i| fields.get(i)));
        };
        if len > NARROW_ROW_BYTES {
            return self.push_row(line, (0..ncols).map(|i| fields.get(i)));
        }
        self.text.push_str(&fields.buf[..len]);
        self.ends.extend(fields.ends[..n].iter().map(|&e| e as u8));
        self.ends.extend(std::iter::repeat_n(len as u8, ncols - n));
        self.starts.push(start);
        self.push_line(row, line);
        Ok(())
    }

    /// Notes that `row` is on `line` (a new run unless the last run goes on to it).
    pub(super) fn push_line(&mut self, row: u32, line: usize) {
        let line = u32::try_from(line).unwrap_or(u32::MAX);
        if self
            .line_runs
            .last()
            .map(|&(r, l)| l.saturating_add(row - r))
            != Some(line)
        {
            self.line_runs.push((row, line));
        }
    }

    /// The line of `row` in the file.
    pub(super) fn line(&self, row: usize) -> usize {
        let run = self.line_runs.partition_point(|&(r, _)| r as usize <= row);
        match run.checked_sub(1).and_then(|k| self.line_runs.get(k)) {
            Some(&(r, l)) => l.saturating_add((row - r as usize) as u32) as usize,
            None => 0,
        }
    }

    pub(super) fn cell(&self, row: usize, col: usize) -> &str {
        let base = self.starts[row] as usize;
        let row_end = self
            .starts
            .get(row + 1)
            .map_or(self.text.len(), |&s| s as usize);
        let (start, end) = if row_end - base <= NARROW_ROW_BYTES {
            let k = row * self.ncols + col;
            let start = if col == 0 { 0 } else { self.ends[k - 1] };
            (usize::from(start), usize::from(self.ends[k]))
        } else {
            let w = self.wide_rows.partition_point(|&(r, _)| (r as usize) < row);
            let k = self.wide_rows[w].1 as usize + col;
            let start = if col == 0 { 0 } else { self.wide_ends[k - 1] };
            (usize::from(start), usize::from(self.wide_ends[k]))
        };
        &self.text[base + start..base + end]
    }

    pub(super) fn shrink_to_fit(&mut self) {
        self.text.shrink_to_fit();
        self.starts.shrink_to_fit();
        self.ends.shrink_to_fit();
        self.wide_rows.shrink_to_fit();
        self.wide_ends.shrink_to_fit();
        self.line_runs.shrink_to_fit();
    }
}
