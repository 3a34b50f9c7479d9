//! Numeric CSV tables with errors that name the file, line and column.
//!
//! Locations are the file's own: the line counts every line of the file from 1 (the header
//! usually being line 1), blank lines and the lines inside a quoted field included, whatever the
//! line ends (`\n`, `\r\n`, `\r`); the column is the 1-based character column where the field
//! starts, as compilers and editors count (`file:line:column`). The `csv` crate's own record
//! positions cannot serve: they skip blank lines and lag one line behind after a `\r\n`.

use anyhow::{bail, Context, Result};
use std::path::Path;

/// A place in a file: 1-based line and character column.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Loc {
    /// 1-based line.
    pub line: u64,
    /// 1-based character column.
    pub column: u64,
}

/// Where a row's fields start, and where the row ends (one past its last character).
#[derive(Clone, Debug, Default)]
pub struct RowLocs {
    /// Start of each field, in order.
    pub fields: Vec<Loc>,
    /// One past the row's last character.
    pub end: Loc,
}

/// A CSV table: header names and rows of fields (kept as text until asked for numbers).
#[derive(Clone, Debug)]
pub struct Table {
    /// File the table was read from (for messages).
    pub path: String,
    /// Column names.
    pub header: Vec<String>,
    /// The header's 1-based line.
    pub header_line: u64,
    /// Rows with their 1-based line numbers (the line where the row starts).
    pub rows: Vec<(u64, csv::StringRecord)>,
    /// Where each row's fields are.
    pub locs: Vec<RowLocs>,
    /// Per row, what is wrong with its shape (a field count other than the header's), located,
    /// for readers that report a bad row and go on ([`Table::read_lenient`]).
    pub malformed: Vec<Option<String>>,
}

/// Byte offsets where lines start, to turn offsets into [`Loc`]s.
struct Lines<'a> {
    bytes: &'a [u8],
    starts: Vec<usize>,
}

impl<'a> Lines<'a> {
    fn new(bytes: &'a [u8]) -> Lines<'a> {
        let mut starts = vec![0];
        let mut i = 0;
        while i < bytes.len() {
            match bytes[i] {
                b'\r' if bytes.get(i + 1) == Some(&b'\n') => {
                    starts.push(i + 2);
                    i += 2;
                    continue;
                }
                b'\r' | b'\n' => starts.push(i + 1),
                _ => {}
            }
            i += 1;
        }
        Lines { bytes, starts }
    }

    fn loc(&self, offset: usize) -> Loc {
        let offset = offset.min(self.bytes.len());
        let l = self.starts.partition_point(|&s| s <= offset) - 1;
        let text = String::from_utf8_lossy(&self.bytes[self.starts[l]..offset]);
        Loc {
            line: l as u64 + 1,
            column: text.chars().count() as u64 + 1,
        }
    }
}

/// Byte offsets of the fields of the record starting at `start` (after any line ends) and of its
/// end: fields split at `delim`, a field opening with `"` quoted up to the closing `"` (`""`
/// inside it), the record ending at a line end outside quotes — the `csv` crate's defaults.
fn scan_record(bytes: &[u8], mut start: usize, delim: u8) -> (Vec<usize>, usize) {
    while start < bytes.len() && matches!(bytes[start], b'\r' | b'\n') {
        start += 1;
    }
    let mut fields = vec![start];
    let mut i = start;
    let mut quoted = bytes.get(i) == Some(&b'"');
    if quoted {
        i += 1;
    }
    while i < bytes.len() {
        let b = bytes[i];
        if quoted {
            if b == b'"' {
                if bytes.get(i + 1) == Some(&b'"') {
                    i += 1;
                } else {
                    quoted = false;
                }
            }
        } else if b == delim {
            fields.push(i + 1);
            quoted = bytes.get(i + 1) == Some(&b'"');
            if quoted {
                i += 1;
            }
        } else if b == b'\r' || b == b'\n' {
            break;
        }
        i += 1;
    }
    (fields, i)
}

impl Table {
    /// Reads a comma- (or `delim`-) separated file with a header line. Every row must have as many
    /// fields as the header.
    pub fn read(path: &Path, delim: u8) -> Result<Table> {
        let t = Table::read_lenient(path, delim)?;
        if let Some(msg) = t.malformed.iter().flatten().next() {
            bail!("{msg}");
        }
        Ok(t)
    }

    /// Reads like [`Table::read`], keeping rows whose field count differs from the header's: each
    /// such row gets its message (file, line and column) in [`Table::malformed`]. Text that is
    /// not UTF-8 is read with replacement characters (it then fails as a number, in its row).
    /// Errors only when the file cannot be read or has no header.
    pub fn read_lenient(path: &Path, delim: u8) -> Result<Table> {
        let name = path.display().to_string();
        let bytes = std::fs::read(path).with_context(|| format!("{name}: cannot open"))?;
        Table::parse(&name, &bytes, delim)
    }

    /// [`Table::read_lenient`] on the bytes of a file named `name`.
    pub fn parse(name: &str, bytes: &[u8], delim: u8) -> Result<Table> {
        let lines = Lines::new(bytes);
        let mut rdr = csv::ReaderBuilder::new()
            .delimiter(delim)
            .flexible(true)
            .has_headers(false)
            .from_reader(bytes);
        let mut rec = csv::ByteRecord::new();
        let locate = |rec: &csv::ByteRecord| {
            let start = rec.position().map_or(0, |p| p.byte() as usize);
            let (fields, end) = scan_record(bytes, start, delim);
            RowLocs {
                fields: fields.into_iter().map(|o| lines.loc(o)).collect(),
                end: lines.loc(end),
            }
        };
        let lossy = |rec: &csv::ByteRecord| -> csv::StringRecord {
            rec.iter()
                .map(|f| String::from_utf8_lossy(f).into_owned())
                .collect()
        };
        let has_header = rdr
            .read_byte_record(&mut rec)
            .with_context(|| format!("{name}:1: cannot read the header line"))?;
        if !has_header {
            bail!("{name}: empty file: expected a header line");
        }
        let header: Vec<String> = lossy(&rec).iter().map(|s| s.trim().to_string()).collect();
        let header_line = locate(&rec).fields[0].line;
        let mut rows = Vec::new();
        let mut locs = Vec::new();
        let mut malformed = Vec::new();
        loop {
            match rdr.read_byte_record(&mut rec) {
                Ok(false) => break,
                Ok(true) => {
                    let at = locate(&rec);
                    let line = at.fields[0].line;
                    malformed.push((rec.len() != header.len()).then(|| {
                        let l = if rec.len() > header.len() {
                            at.fields.get(header.len()).copied().unwrap_or(at.end)
                        } else {
                            at.end
                        };
                        format!(
                            "{name}:{}:{}: expected {} fields (as in the header), found {}",
                            l.line,
                            l.column,
                            header.len(),
                            rec.len()
                        )
                    }));
                    rows.push((line, lossy(&rec)));
                    locs.push(at);
                }
                Err(e) => {
                    let at = e
                        .position()
                        .map_or(Loc::default(), |p| lines.loc(p.byte() as usize));
                    bail!("{name}:{}: malformed CSV: {e}", at.line);
                }
            }
        }
        Ok(Table {
            path: name.to_string(),
            header,
            header_line,
            rows,
            locs,
            malformed,
        })
    }

    /// Index of a column by name.
    pub fn col(&self, name: &str) -> Result<usize> {
        self.header.iter().position(|h| h == name).with_context(|| {
            format!(
                "{}:{}: no column named `{name}`",
                self.path, self.header_line
            )
        })
    }

    /// Where field `c` of row `r` starts (the row's end when it has fewer fields).
    pub fn loc(&self, r: usize, c: usize) -> Loc {
        let l = &self.locs[r];
        l.fields.get(c).copied().unwrap_or(l.end)
    }

    /// `file:line:column` of field `c` of row `r`.
    pub fn at(&self, r: usize, c: usize) -> String {
        let l = self.loc(r, c);
        format!("{}:{}:{}", self.path, l.line, l.column)
    }

    /// Parses field `c` of row `r` as a finite number (`allow_empty`: empty or `NaN` → NaN).
    pub fn num(&self, r: usize, c: usize, allow_empty: bool) -> Result<f64> {
        let text = self.text(r, c);
        if allow_empty && (text.is_empty() || text.eq_ignore_ascii_case("nan")) {
            return Ok(f64::NAN);
        }
        let v: f64 = text.parse().map_err(|_| {
            anyhow::anyhow!(
                "{}: column `{}`: expected a number, found `{text}`",
                self.at(r, c),
                self.header[c]
            )
        })?;
        if !v.is_finite() {
            bail!(
                "{}: column `{}`: expected a finite number, found `{text}`",
                self.at(r, c),
                self.header[c]
            );
        }
        Ok(v)
    }

    /// Text of field `c` of row `r`.
    pub fn text(&self, r: usize, c: usize) -> &str {
        self.rows[r].1.get(c).unwrap_or("").trim()
    }

    /// The 1-based line where row `r` starts.
    pub fn line(&self, r: usize) -> u64 {
        self.rows[r].0
    }
}

/// Reads a one-column file of numbers (no header), e.g. `train_x_mean.csv`.
pub fn read_vector(path: &Path) -> Result<Vec<f64>> {
    let name = path.display().to_string();
    let text = std::fs::read_to_string(path).with_context(|| format!("{name}: cannot read"))?;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let t = line.trim();
        if t.is_empty() {
            continue;
        }
        let v: f64 = t
            .parse()
            .map_err(|_| anyhow::anyhow!("{name}:{}:1: expected a number, found `{t}`", i + 1))?;
        if !v.is_finite() {
            bail!("{name}:{}:1: expected a finite number, found `{t}`", i + 1);
        }
        out.push(v);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(t: &Table, r: usize, c: usize) -> (u64, u64) {
        let l = t.loc(r, c);
        (l.line, l.column)
    }

    #[test]
    fn locations_count_every_line_of_the_file() {
        // Blank lines, CRLF, a lone CR and a quoted field over two lines.
        let text = b"a,b,c\r\n1,22,3\r\n\r\n\n4,x,6\r\"7\n7\",8,9\n10,11,12";
        let t = Table::parse("f.csv", text, b',').unwrap();
        assert_eq!(t.header_line, 1);
        assert_eq!(t.rows.len(), 4);
        let lines: Vec<u64> = (0..4).map(|r| t.line(r)).collect();
        assert_eq!(lines, [2, 5, 6, 8]);
        assert_eq!(at(&t, 0, 1), (2, 3));
        assert_eq!(at(&t, 1, 1), (5, 3));
        assert_eq!(at(&t, 2, 1), (7, 4), "after the quoted field's line end");
        assert_eq!(at(&t, 3, 2), (8, 7));
        let e = t.num(1, 1, false).unwrap_err().to_string();
        assert!(e.starts_with("f.csv:5:3: column `b`"), "{e}");
    }

    #[test]
    fn short_and_long_rows_are_kept_and_located() {
        let text = "a,b,c\n1,2\n1,2,3,4\n1,2,3\n";
        let t = Table::parse("g.csv", text.as_bytes(), b',').unwrap();
        assert_eq!(t.rows.len(), 3);
        let m: Vec<Option<&str>> = t.malformed.iter().map(|m| m.as_deref()).collect();
        assert_eq!(
            m[0],
            Some("g.csv:2:4: expected 3 fields (as in the header), found 2")
        );
        assert_eq!(
            m[1],
            Some("g.csv:3:7: expected 3 fields (as in the header), found 4")
        );
        assert_eq!(m[2], None);
    }

    #[test]
    fn columns_count_characters_not_bytes() {
        let text = "name,v\n\"é,ü\",zz\n";
        let t = Table::parse("u.csv", text.as_bytes(), b',').unwrap();
        assert_eq!(t.text(0, 0), "é,ü");
        assert_eq!(at(&t, 0, 1), (2, 7));
        let bad = Table::parse("u.csv", b"a,b\n\xff,1\n", b',').unwrap();
        assert!(bad
            .num(0, 0, false)
            .unwrap_err()
            .to_string()
            .starts_with("u.csv:2:1:"));
    }
}
