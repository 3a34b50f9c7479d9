//! A scenario's rows pooled over the placements, with an exact 95 % interval: ten seeds a row
//! is a coarse measure. At a true recovery rate of 90 % a row of 10 shows 8 or fewer about one
//! time in four, so a row below 9 of 10 says little on its own; pooled over the three
//! placements, 30 runs bound the rate more closely (`magic synth-check` prints this table after
//! the recovery table; `magic synth-check --pool FILE` reads recovery tables instead of running).

use super::Recovery;
use crate::numerics::{binomial_cdf, clopper_pearson};
use anyhow::{bail, Context, Result};
use std::fmt::Write as _;

/// Confidence of the interval.
pub const LEVEL: f64 = 0.95;

/// One scenario under one noise model: runs with every injected effect found, per row.
#[derive(Clone, Debug, PartialEq)]
pub struct Pooled {
    /// Scenario name.
    pub scenario: String,
    /// Noise model.
    pub noise: String,
    /// Per placement (in first-seen order): runs with every effect found, and runs.
    pub rows: Vec<(String, usize, usize)>,
}

impl Pooled {
    /// Runs with every effect found, and runs, over the rows.
    pub fn total(&self) -> (usize, usize) {
        self.rows
            .iter()
            .fold((0, 0), |(k, n), r| (k + r.1, n + r.2))
    }
}

/// Adds a row's counts to its scenario and noise model's entry.
fn add(out: &mut Vec<Pooled>, scenario: &str, noise: &str, placement: &str, k: usize, n: usize) {
    let i = match out
        .iter()
        .position(|p| p.scenario == scenario && p.noise == noise)
    {
        Some(i) => i,
        None => {
            out.push(Pooled {
                scenario: scenario.into(),
                noise: noise.into(),
                rows: vec![],
            });
            out.len() - 1
        }
    };
    match out[i].rows.iter_mut().find(|r| r.0 == placement) {
        Some(r) => {
            r.1 += k;
            r.2 += n;
        }
        None => out[i].rows.push((placement.into(), k, n)),
    }
}

/// `more` added to `all`: a scenario's rows of the same placement summed (the same rows run on
/// other seeds), new ones appended.
pub fn merge(all: &mut Vec<Pooled>, more: Vec<Pooled>) {
    for p in more {
        for (pl, k, n) in p.rows {
            add(all, &p.scenario, &p.noise, &pl, k, n);
        }
    }
}

/// The runs of a check pooled (scenarios with injected effects only).
pub fn from_runs(runs: &[Recovery]) -> Vec<Pooled> {
    let mut out = Vec::new();
    for r in runs.iter().filter(|r| !r.effects.is_empty()) {
        let k = usize::from(r.all_found());
        add(&mut out, &r.scenario, &r.noise, &r.placement, k, 1);
    }
    out
}

/// The recovery table of a Markdown text (`magic synth-check --table` output, or a README that
/// holds one) pooled: its `all found` column, `k/n`, per scenario and noise model. `what` names
/// the text in errors, which give the line.
pub fn from_markdown(text: &str, what: &str) -> Result<Vec<Pooled>> {
    let lines: Vec<&str> = text.lines().collect();
    let Some(head) = lines
        .iter()
        .position(|l| l.starts_with("| scenario | placement | noise | seeds | found |"))
    else {
        bail!("{what}: no recovery table (a line starting `| scenario | placement | noise | seeds | found |`)");
    };
    let header: Vec<&str> = cells(lines[head]);
    let col = header
        .iter()
        .position(|c| *c == "all found")
        .with_context(|| format!("{what}, line {}: no `all found` column", head + 1))?;
    let mut out = Vec::new();
    for (i, line) in lines.iter().enumerate().skip(head + 2) {
        if !line.starts_with('|') {
            break;
        }
        let c = cells(line);
        let at = || format!("{what}, line {}", i + 1);
        if c.len() != header.len() {
            bail!(
                "{}: {} cells, the header has {}",
                at(),
                c.len(),
                header.len()
            );
        }
        if c[col] == "-" {
            continue; // clean data: nothing injected
        }
        let (k, n) = c[col]
            .split_once('/')
            .and_then(|(k, n)| Some((k.trim().parse().ok()?, n.trim().parse().ok()?)))
            .filter(|(k, n): &(usize, usize)| k <= n)
            .with_context(|| {
                format!(
                    "{}, column {}: `{}` is not a count k/n",
                    at(),
                    col + 1,
                    c[col]
                )
            })?;
        add(&mut out, c[0], c[2], c[1], k, n);
    }
    Ok(out)
}

/// The cells of a Markdown table line, trimmed.
fn cells(line: &str) -> Vec<&str> {
    let t = line.trim().trim_start_matches('|').trim_end_matches('|');
    t.split('|').map(str::trim).collect()
}

/// The table: per scenario and noise model, the rows' counts, the pooled share with its exact
/// 95 % interval, and how often a row of 10 would show 9 or more at the pooled share.
pub fn table(pooled: &[Pooled]) -> String {
    let mut s = String::from(
        "| scenario | noise | rows (all found) | pooled | share | 95 % interval | a row of 10 at 9 or more, at that share |\n|---|---|---|---|---|---|---|\n",
    );
    for p in pooled {
        let (k, n) = p.total();
        if n == 0 {
            continue;
        }
        let share = k as f64 / n as f64;
        let (lo, hi) = clopper_pearson(k, n, LEVEL);
        let rows = p
            .rows
            .iter()
            .map(|(pl, k, n)| match pl.as_str() {
                "-" => format!("{k}/{n}"),
                _ => format!("{pl} {k}/{n}"),
            })
            .collect::<Vec<_>>()
            .join(", ");
        let _ = writeln!(
            s,
            "| {} | {} | {rows} | {k}/{n} | {:.0} % | {:.0}–{:.0} % | {:.0} % |",
            p.scenario,
            p.noise,
            100.0 * share,
            100.0 * lo,
            100.0 * hi,
            100.0 * (1.0 - binomial_cdf(8, 10, share)),
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gnss::recovery::Found;

    const TABLE: &str = "intro

| scenario | placement | noise | seeds | found | ranked 1st | all found | false additions | noise's own found | ok |
|---|---|---|---|---|---|---|---|---|---|
| clean | - | paper | 10 | - | - | - | 0/10 | - | 10/10 |
| lasting | train | paper | 10 | 10/10 | 10/10 | 10/10 | 0/10 | - | 10/10 |
| lasting | valid | paper | 10 | 7/10 | 9/10 | 7/10 | 2/10 (step 2/10) | - | 7/10 |
| lasting | test | paper | 10 | 9/10 | 9/10 | 9/10 | 0/10 | - | 8/10 |
| lasting | train | red | 10 | 10/10 | 10/10 | 10/10 | 0/10 | - | 10/10 |
| drift | - | red | 10 | 9/10 | 9/10 | 9/10 | 0/10 | - | 9/10 |

after
";

    #[test]
    fn pools_the_all_found_column_per_scenario_and_noise() {
        let p = from_markdown(TABLE, "t.md").unwrap();
        assert_eq!(p.len(), 3);
        assert_eq!(
            (p[0].scenario.as_str(), p[0].noise.as_str()),
            ("lasting", "paper")
        );
        assert_eq!(p[0].total(), (26, 30));
        assert_eq!(p[1].total(), (10, 10));
        let t = table(&p);
        // 26 of 30: 87 %, exact interval 69–96 %; a row of 10 at 9 or more 61 % of the time.
        assert!(
            t.contains("| lasting | paper | train 10/10, valid 7/10, test 9/10 | 26/30 | 87 % | 69–96 % | 61 % |"),
            "{t}"
        );
        assert!(
            t.contains("| lasting | red | train 10/10 | 10/10 | 100 % | 69–100 % | 100 % |"),
            "{t}"
        );
    }

    #[test]
    fn merging_sums_a_placement_run_on_other_seeds() {
        let mut all = from_markdown(TABLE, "a.md").unwrap();
        let more = from_markdown(&TABLE.replace("| 7/10 | 2/10", "| 9/10 | 2/10"), "b.md").unwrap();
        merge(&mut all, more);
        assert_eq!(all.len(), 3);
        assert_eq!(
            all[0].rows,
            vec![
                ("train".to_string(), 20, 20),
                ("valid".to_string(), 16, 20),
                ("test".to_string(), 18, 20)
            ]
        );
        assert_eq!(all[0].total(), (54, 60));
    }

    #[test]
    fn says_where_a_table_is_wrong() {
        let bad = TABLE.replace("| 7/10 | 2/10", "| seven | 2/10");
        let e = from_markdown(&bad, "t.md").unwrap_err().to_string();
        assert!(
            e.contains("t.md, line 7, column 7: `seven` is not a count"),
            "{e}"
        );
        let e = from_markdown("no table", "x.md").unwrap_err().to_string();
        assert!(e.contains("x.md: no recovery table"), "{e}");
        let short = TABLE.replace(
            "| 0/10 | - | 10/10 |\n| lasting | valid",
            "|\n| lasting | valid",
        );
        assert!(from_markdown(&short, "t.md").is_err());
    }

    #[test]
    fn pools_runs_as_the_table_counts_them() {
        let f = |found: bool| Found {
            family: "lasting_source".into(),
            significant: found,
            rank: Some(1),
            params_ok: true,
            detail: String::new(),
            rejected: None,
            at_truth: None,
        };
        let mut runs = vec![
            Recovery::single("lasting", "paper", "train", f(true)),
            Recovery::single("lasting", "paper", "valid", f(false)),
            Recovery::single("lasting", "paper", "valid", f(true)),
        ];
        let mut clean = Recovery::single("clean", "paper", "-", f(true));
        clean.effects.clear();
        runs.push(clean);
        let p = from_runs(&runs);
        assert_eq!(p.len(), 1);
        assert_eq!(
            p[0].rows,
            vec![("train".to_string(), 1, 1), ("valid".to_string(), 1, 2)]
        );
    }
}
