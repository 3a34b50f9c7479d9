//! Where the fields of a station file are: found by their header names (normalised: underscores
//! trimmed, case ignored), or the standard 23- or 20-field layout for a file without a header;
//! and the whitespace-separated fields of a line with their character columns.

/// The header of the current 23-field layout; older files stop after the correlations (the
/// first [`OLD_FIELDS`] fields).
pub const HEADER: [&str; 23] = [
    "site",
    "YYMMMDD",
    "yyyy.yyyy",
    "__MJD",
    "week",
    "d",
    "reflon",
    "_e0(m)",
    "__east(m)",
    "____n0(m)",
    "_north(m)",
    "u0(m)",
    "____up(m)",
    "_ant(m)",
    "sig_e(m)",
    "sig_n(m)",
    "sig_u(m)",
    "__corr_en",
    "__corr_eu",
    "__corr_nu",
    "_latitude(deg)",
    "_longitude(deg)",
    "__height(m)",
];

/// Number of fields of the older layout (up to and including `__corr_nu`).
pub const OLD_FIELDS: usize = 20;

/// Where the fields of a file are.
#[derive(Clone, Debug)]
pub(crate) struct Layout {
    /// Field names as written in the header (or the standard names).
    pub(crate) names: Vec<String>,
    pub(crate) site: usize,
    pub(crate) date: usize,
    pub(crate) mjd: usize,
    pub(crate) int: [usize; 3],
    pub(crate) frac: [usize; 3],
    pub(crate) sigma: [Option<usize>; 3],
    /// Latitude, longitude and height fields, when the layout has all three (the 23-field one).
    pub(crate) geo: Option<[usize; 3]>,
    /// Fields that must hold finite numbers.
    pub(crate) numeric: Vec<usize>,
}

fn norm(name: &str) -> String {
    name.trim_matches('_').to_ascii_lowercase()
}

/// Known numeric fields, by normalised name.
const NUMERIC: [&str; 21] = [
    "yyyy.yyyy",
    "mjd",
    "week",
    "d",
    "reflon",
    "e0(m)",
    "east(m)",
    "n0(m)",
    "north(m)",
    "u0(m)",
    "up(m)",
    "ant(m)",
    "sig_e(m)",
    "sig_n(m)",
    "sig_u(m)",
    "corr_en",
    "corr_eu",
    "corr_nu",
    "latitude(deg)",
    "longitude(deg)",
    "height(m)",
];

impl Layout {
    /// The layout of a header's field names; the message names a required field that is missing.
    pub(crate) fn from_names(names: Vec<String>) -> std::result::Result<Layout, String> {
        let normed: Vec<String> = names.iter().map(|n| norm(n)).collect();
        let find = |key: &str| normed.iter().position(|n| n == key);
        let need = |key: &str, shown: &str| {
            find(key).ok_or_else(|| format!("header has no `{shown}` field"))
        };
        Ok(Layout {
            site: need("site", "site")?,
            date: need("yymmmdd", "YYMMMDD")?,
            mjd: need("mjd", "__MJD")?,
            int: [
                need("e0(m)", "_e0(m)")?,
                need("n0(m)", "____n0(m)")?,
                need("u0(m)", "u0(m)")?,
            ],
            frac: [
                need("east(m)", "__east(m)")?,
                need("north(m)", "_north(m)")?,
                need("up(m)", "____up(m)")?,
            ],
            sigma: [find("sig_e(m)"), find("sig_n(m)"), find("sig_u(m)")],
            geo: match (
                find("latitude(deg)"),
                find("longitude(deg)"),
                find("height(m)"),
            ) {
                (Some(a), Some(b), Some(c)) => Some([a, b, c]),
                _ => None,
            },
            numeric: (0..names.len())
                .filter(|&i| NUMERIC.contains(&normed[i].as_str()))
                .collect(),
            names,
        })
    }

    /// The standard layout with `n` fields (23 or 20), if `n` is one of them.
    pub(crate) fn standard(n: usize) -> Option<Layout> {
        (n == HEADER.len() || n == OLD_FIELDS)
            .then(|| Layout::from_names(HEADER[..n].iter().map(|s| s.to_string()).collect()).ok())
            .flatten()
    }
}

/// Whitespace-separated fields with their 1-based character columns.
pub(crate) fn fields(line: &str) -> Vec<(usize, &str)> {
    let mut out = Vec::new();
    let mut start: Option<(usize, usize)> = None; // (byte, column)
    let mut col = 0usize;
    for (b, ch) in line.char_indices() {
        col += 1;
        if ch.is_whitespace() {
            if let Some((sb, sc)) = start.take() {
                out.push((sc, &line[sb..b]));
            }
        } else if start.is_none() {
            start = Some((b, col));
        }
    }
    if let Some((sb, sc)) = start {
        out.push((sc, &line[sb..]));
    }
    out
}
