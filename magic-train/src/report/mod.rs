//! Reports: figures (PNG through plotters, with a compiled-in font), Markdown tables, and the
//! loop's report.

pub mod loop_report;
pub mod plots;

/// A number with four decimals, or `–` when not finite.
pub fn f4(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.4}")
    } else {
        "–".into()
    }
}

/// A Markdown table: a header row, the separator, then the rows.
pub fn markdown_table(header: &[String], rows: &[Vec<String>]) -> String {
    let line = |cells: &[String]| format!("| {} |\n", cells.join(" | "));
    let mut s = line(header);
    s.push_str(&format!("|{}\n", "---|".repeat(header.len())));
    for r in rows {
        s.push_str(&line(r));
    }
    s
}
