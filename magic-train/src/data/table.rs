//! Numeric CSV tables with errors that name the file, line and column.

use anyhow::{bail, Context, Result};
use std::path::Path;

/// A CSV table: header names and rows of fields (kept as text until asked for numbers).
#[derive(Clone, Debug)]
pub struct Table {
    /// File the table was read from (for messages).
    pub path: String,
    /// Column names.
    pub header: Vec<String>,
    /// Rows with their 1-based line numbers.
    pub rows: Vec<(u64, csv::StringRecord)>,
    /// Per row, what is wrong with its shape (a field count other than the header's), for
    /// readers that report a bad row and go on ([`Table::read_lenient`]).
    pub malformed: Vec<Option<String>>,
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
    /// such row gets its message (file and line) in [`Table::malformed`]. Errors only when the
    /// file cannot be read or has no header.
    pub fn read_lenient(path: &Path, delim: u8) -> Result<Table> {
        let name = path.display().to_string();
        let mut rdr = csv::ReaderBuilder::new()
            .delimiter(delim)
            .flexible(true)
            .from_path(path)
            .with_context(|| format!("{name}: cannot open"))?;
        let header: Vec<String> = rdr
            .headers()
            .with_context(|| format!("{name}:1: cannot read the header line"))?
            .iter()
            .map(|s| s.trim().to_string())
            .collect();
        let mut rows = Vec::new();
        let mut malformed = Vec::new();
        let mut rec = csv::StringRecord::new();
        loop {
            let line = rdr.position().line();
            match rdr.read_record(&mut rec) {
                Ok(false) => break,
                Ok(true) => {
                    let line = rec.position().map_or(line, |p| p.line());
                    malformed.push((rec.len() != header.len()).then(|| {
                        format!(
                            "{name}:{line}: expected {} fields (as in the header), found {}",
                            header.len(),
                            rec.len()
                        )
                    }));
                    rows.push((line, rec.clone()));
                }
                Err(e) => {
                    let line = e.position().map_or(line, |p| p.line());
                    bail!("{name}:{line}: malformed CSV: {e}");
                }
            }
        }
        Ok(Table {
            path: name,
            header,
            rows,
            malformed,
        })
    }

    /// Index of a column by name.
    pub fn col(&self, name: &str) -> Result<usize> {
        self.header
            .iter()
            .position(|h| h == name)
            .with_context(|| format!("{}:1: no column named `{name}`", self.path))
    }

    /// Parses field `c` of row `r` as a finite number (`allow_empty`: empty or `NaN` → NaN).
    pub fn num(&self, r: usize, c: usize, allow_empty: bool) -> Result<f64> {
        let (line, rec) = &self.rows[r];
        let text = rec.get(c).unwrap_or("").trim();
        if allow_empty && (text.is_empty() || text.eq_ignore_ascii_case("nan")) {
            return Ok(f64::NAN);
        }
        let v: f64 = text.parse().map_err(|_| {
            anyhow::anyhow!(
                "{}:{line}:{}: column `{}`: expected a number, found `{text}`",
                self.path,
                c + 1,
                self.header[c]
            )
        })?;
        if !v.is_finite() {
            bail!(
                "{}:{line}:{}: column `{}`: expected a finite number, found `{text}`",
                self.path,
                c + 1,
                self.header[c]
            );
        }
        Ok(v)
    }

    /// Text of field `c` of row `r`.
    pub fn text(&self, r: usize, c: usize) -> &str {
        self.rows[r].1.get(c).unwrap_or("").trim()
    }

    /// The 1-based line of row `r`.
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
