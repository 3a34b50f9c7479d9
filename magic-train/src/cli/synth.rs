//! `magic synth`, `magic synth-check`, `magic synth-loop`: synthetic GNSS data with injected
//! effects, and how well the analysis and the loop recover them.

use super::args::{write_file, JsonOut, Warmup};
use crate::analysis::{AnalysisOptions, LastingStatistic, MainSource};
use crate::closed_loop::{self, LoopOptions};
use crate::data::SplitName;
use crate::gnss::data::write_dir;
use crate::gnss::recovery::at_truth::truth_table;
use crate::gnss::recovery::coverage::Coverage;
use crate::gnss::recovery::looped::{loop_table, LoopRun};
use crate::gnss::recovery::misses::miss_table;
use crate::gnss::recovery::pooled;
use crate::gnss::recovery::{check_one, recovery_table};
use crate::gnss::synth::truth::injected;
use crate::gnss::synth::{self, NoiseModel, Scenario, Site, Spec};
use crate::problem::Problem;
use anyhow::{Context, Result};
use clap::Args;
use serde_json::json;
use std::path::{Path, PathBuf};

/// `magic synth`.
#[derive(Args, Clone, Debug)]
pub struct SynthCmd {
    /// Scenario: `clean`, the effect family injected, or a variant (`--list` shows them all).
    #[arg(long, value_enum, default_value = "clean")]
    scenario: Scenario,
    /// Random seed.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Noise model (and main-source history): `paper` (the original generator) or `red` (an
    /// independent one on the release's 2006–2024 record).
    #[arg(long, value_enum, default_value = "paper")]
    noise: NoiseModel,
    /// The period in which events (a step, a second source) begin.
    #[arg(long, value_enum, default_value = "train")]
    placement: SplitName,
    /// Output folder (the release layout, plus `truth.json`).
    #[arg(long, required_unless_present = "list")]
    out: Option<PathBuf>,
    /// List the scenarios and exit.
    #[arg(long)]
    list: bool,
    #[command(flatten)]
    site: SiteArg,
}

/// The network synthetic data are made on.
#[derive(Args, Clone, Debug, Default)]
pub struct SiteArg {
    /// The station network, a `stations.json` (`{"STA": {"xE": km, "yN": km, "zV": km}, …}`, as
    /// the release and `magic prepare` write it), the main source under its centroid 7 km deep
    /// and the source bounds over its box, or those of a `bounds.json` beside the file (default:
    /// Akutan, the paper's release).
    #[arg(long, value_name = "FILE")]
    stations: Option<PathBuf>,
}

impl SiteArg {
    /// The site: the network of `--stations`, or Akutan.
    pub fn site(&self) -> Result<Site> {
        self.stations
            .as_deref()
            .map_or_else(|| Ok(Site::akutan()), Site::read)
    }
}

/// Runs `magic synth`.
pub fn synth(a: &SynthCmd) -> Result<()> {
    if a.list {
        print!("{}", synth::scenario::list());
        return Ok(());
    }
    let Some(out) = &a.out else {
        anyhow::bail!("--out is required");
    };
    let s = Spec::new(a.scenario, a.seed)
        .noise(a.noise)
        .placed(a.placement)
        .generate_on(&a.site.site()?)?;
    write_dir(&s.problem, out)?;
    write_file(
        &out.join("truth.json"),
        serde_json::to_string_pretty(&s.truth)?,
    )?;
    eprintln!(
        "wrote synthetic dataset ({}) -> {}",
        s.problem.data.source,
        out.display()
    );
    Ok(())
}

/// Scenarios (default: all).
fn scenarios(list: &[Scenario]) -> Vec<Scenario> {
    if list.is_empty() {
        Scenario::ALL.to_vec()
    } else {
        list.to_vec()
    }
}

/// Every combination of scenario, noise model and placement (once per scenario without
/// events), each with every seed in turn.
fn specs(
    scenarios: &[Scenario],
    noises: &[NoiseModel],
    placements: &[SplitName],
    seeds: std::ops::Range<u64>,
) -> Vec<Spec> {
    let mut out = Vec::new();
    for &sc in scenarios {
        for &noise in noises {
            let places: &[SplitName] = if sc.has_event() {
                placements
            } else {
                &placements[..1]
            };
            for &pl in places {
                for seed in seeds.clone() {
                    out.push(Spec::new(sc, seed).noise(noise).placed(pl));
                }
            }
        }
    }
    out
}

/// `magic synth-check`.
#[derive(Args, Clone, Debug)]
pub struct SynthCheckCmd {
    /// Number of seeds per scenario (first-seed, first-seed + 1, …).
    #[arg(long, default_value_t = 10)]
    seeds: u64,
    /// First seed.
    #[arg(long, default_value_t = 1)]
    first_seed: u64,
    /// Scenarios, comma-separated (default: all; `magic synth --list` shows them).
    #[arg(long, value_enum, value_delimiter = ',')]
    scenarios: Vec<Scenario>,
    /// Noise models, comma-separated: a line of the table per model.
    #[arg(long, value_enum, value_delimiter = ',', default_value = "paper")]
    noise: Vec<NoiseModel>,
    /// Placements of the events, comma-separated (scenarios without events run once).
    #[arg(long, value_enum, value_delimiter = ',', default_value = "train")]
    placement: Vec<SplitName>,
    /// Training epochs of the B models.
    #[arg(long, default_value_t = crate::gnss::recovery::BRIEF_EPOCHS)]
    epochs: usize,
    /// Epochs early stopping does not watch (0: every epoch, as the paper; B's brief training
    /// ends before the learning-rate step the recipe's warm-up waits for).
    #[arg(long, default_value_t = 0)]
    warmup: usize,
    /// The volcano's main source in the residual analysis: `free` to move every day (whatever
    /// moving it produces is projected off; point sources are located and scored with it held) or
    /// `held` in place (only its field's direction is projected off, so a second source near
    /// it stays visible and counts whole).
    #[arg(long, value_enum, default_value_t)]
    main_source: MainSource,
    /// The volcano: how a change that stays is detected — `matched` (a matched filter under
    /// noise fitted to the residuals; the README's tables) or `scan` (the offsets over 180-day
    /// windows, detected by the held-out gain; the earlier default, docs/matched-filter.md).
    #[arg(long, value_enum, default_value_t)]
    lasting: LastingStatistic,
    /// Write the table (Markdown) here too.
    #[arg(long)]
    table: Option<PathBuf>,
    /// Run nothing: read the recovery tables of these Markdown files (this command's `--table`
    /// output, or a README holding one), comma-separated, and print their rows pooled over the
    /// placements with exact 95 % intervals.
    #[arg(long, value_name = "FILE", value_delimiter = ',')]
    pool: Vec<PathBuf>,
    /// Write each analysis' residual series (`magic residuals --series`) and the truth injected
    /// (`truth.json`) into a folder of this one, `<scenario>_<noise>_<placement>_<seed>` (no
    /// placement for a scenario without events).
    #[arg(long, value_name = "DIR")]
    series: Option<PathBuf>,
    #[command(flatten)]
    json: JsonOut,
    #[command(flatten)]
    site: SiteArg,
}

/// The recovery tables of `files` pooled over the placements (`--pool`), a placement's rows from
/// several files (other seeds) summed.
fn pool_files(files: &[PathBuf]) -> Result<()> {
    let mut all: Vec<pooled::Pooled> = Vec::new();
    for f in files {
        let text =
            std::fs::read_to_string(f).with_context(|| format!("reading {}", f.display()))?;
        pooled::merge(
            &mut all,
            pooled::from_markdown(&text, &f.display().to_string())?,
        );
    }
    print!("{}", pooled::table(&all));
    Ok(())
}

/// Runs `magic synth-check`: for every scenario, noise model, placement and seed, generate the
/// data, train a B model briefly, analyse it and compare with the injected truth.
pub fn check(a: &SynthCheckCmd) -> Result<()> {
    if !a.pool.is_empty() {
        return pool_files(&a.pool);
    }
    let cfg = crate::gnss::recovery::brief_recipe()
        .with(a.epochs, true)
        .with_warmup(Some(a.warmup));
    let opts = AnalysisOptions {
        main_source: a.main_source,
        lasting: a.lasting,
        ..AnalysisOptions::default()
    };
    let site = a.site.site()?;
    let (mut rows, mut out) = (Vec::new(), Vec::new());
    let mut coverage = Coverage::default();
    let start = std::time::Instant::now();
    for spec in specs(
        &scenarios(&a.scenarios),
        &a.noise,
        &a.placement,
        a.first_seed..a.first_seed + a.seeds,
    ) {
        let t0 = std::time::Instant::now();
        let check = check_one(&spec, &site, &cfg, &opts)?;
        if let Some(dir) = &a.series {
            let r = &check.recovery;
            let mut parts = vec![r.scenario.as_str(), r.noise.as_str()];
            if r.placement != "-" {
                parts.push(&r.placement);
            }
            let d = dir.join(format!("{}_{}", parts.join("_"), spec.seed));
            crate::gnss::residuals::series::write(&check.residuals, &d)?;
            write_file(
                &d.join("truth.json"),
                serde_json::to_string_pretty(&check.truth)?,
            )?;
        }
        let (r, an) = (check.recovery, check.analysis);
        let secs = t0.elapsed().as_secs_f64();
        eprintln!(
            "{:<22} {:<5} {:<5} seed {:>3}: top {:<14} {}  {}",
            r.scenario,
            r.placement,
            r.noise,
            spec.seed,
            r.top,
            if r.ok() { "ok  " } else { "FAIL" },
            r.detail()
        );
        coverage.add(&an, &injected(&check.truth), &r.noise);
        out.push(json!({"recovery": r.to_json(), "seconds": secs, "analysis": an.to_json()}));
        rows.push(r);
    }
    let mut table = recovery_table(&rows);
    table.push_str(
        "\nPooled over the placements (every injected effect found; a row of 10 seeds is a coarse measure):\n\n",
    );
    table.push_str(&pooled::table(&pooled::from_runs(&rows)));
    table.push_str("\nWhy an injected effect was missed (placements together):\n\n");
    table.push_str(&miss_table(&rows));
    let at_truth = truth_table(&rows);
    if !at_truth.is_empty() {
        table.push_str(
            "\nLasting changes judged at the truth (its position, the best scanned onset within its change):\n\n",
        );
        table.push_str(&at_truth);
    }
    if !coverage.is_empty() {
        table.push_str(
            "\nBootstrap standard deviations against the truth, and the shift its draws see beside the mean error (significant candidates):\n\n",
        );
        table.push_str(&coverage.table());
    }
    print!("{table}");
    eprintln!(
        "{} analyses in {:.0} s",
        rows.len(),
        start.elapsed().as_secs_f64()
    );
    if let Some(p) = &a.table {
        write_file(p, &table)?;
    }
    a.json.write(&out)
}

/// `magic synth-loop`.
#[derive(Args, Clone, Debug)]
pub struct SynthLoopCmd {
    /// Scenarios, comma-separated (default: all).
    #[arg(long, value_enum, value_delimiter = ',')]
    scenarios: Vec<Scenario>,
    /// Seed of the data and the training (the first, with `--seeds`).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Number of seeds per scenario (seed, seed + 1, …): a line per run and a summary over
    /// the seeds.
    #[arg(long, default_value_t = 1)]
    seeds: u64,
    /// Noise models, comma-separated.
    #[arg(long, value_enum, value_delimiter = ',', default_value = "paper")]
    noise: Vec<NoiseModel>,
    /// The periods in which events begin, comma-separated (scenarios without events run once).
    #[arg(long, value_enum, value_delimiter = ',', default_value = "train")]
    placement: Vec<SplitName>,
    /// Maximum epochs per training.
    #[arg(long, default_value_t = 100)]
    epochs: usize,
    #[command(flatten)]
    warmup: Warmup,
    /// Most rounds after the first, each adding one effect (kept, or taken out again and the
    /// next candidate tried in the following round).
    #[arg(long, default_value_t = 3)]
    rounds: usize,
    /// The volcano's main source in the residual analysis: `free` to move every day (whatever
    /// moving it produces is projected off; point sources are located and scored with it held) or
    /// `held` in place (only its field's direction is projected off, so a second source near
    /// it stays visible and counts whole).
    #[arg(long, value_enum, default_value_t)]
    main_source: MainSource,
    /// The volcano: how a change that stays is detected — `matched` (a matched filter under
    /// noise fitted to the residuals; the README's tables) or `scan` (the offsets over 180-day
    /// windows, detected by the held-out gain; the earlier default, docs/matched-filter.md).
    #[arg(long, value_enum, default_value_t)]
    lasting: LastingStatistic,
    /// The volcano: the most extra point sources F may hold (the loop adds a second beside a
    /// first only where the main source does not trade with that one; measured in
    /// docs/synthetic-check.md, *A second source term in F*).
    #[arg(long, default_value_t = 1, value_parser = super::args::terms)]
    extra_sources: usize,
    /// The volcano: the most steps F may hold, each at its own station and time (measured in
    /// docs/synthetic-check.md, *Steps at several stations*).
    #[arg(long, default_value_t = 1, value_parser = super::args::terms)]
    steps: usize,
    /// Folder for each run's loop report (and the tables).
    #[arg(long, default_value = "out/synth-loop")]
    out: PathBuf,
    /// Run nothing: rebuild the summary over the seeds from the runs already under this folder
    /// (each run's `report.json` beside its `truth.json`; runs split over several processes, or
    /// a stopped command's).
    #[arg(long, value_name = "DIR")]
    summarise: Option<PathBuf>,
    #[command(flatten)]
    site: SiteArg,
}

/// `magic synth-loop --summarise DIR`: the summary table of the runs under `dir`, read back from
/// their reports, in the order of their folders' paths.
fn summarise(dir: &Path) -> Result<()> {
    let mut folders = Vec::new();
    run_folders(dir, &mut folders)?;
    folders.sort();
    if folders.is_empty() {
        anyhow::bail!(
            "{}: no run under it (a folder holding report.json and truth.json)",
            dir.display()
        );
    }
    let read = |f: &Path, name: &str| -> Result<serde_json::Value> {
        let path = f.join(name);
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("{}: cannot read it", path.display()))?;
        serde_json::from_str(&text).with_context(|| format!("{}: not JSON", path.display()))
    };
    let mut runs = Vec::new();
    for f in &folders {
        let run = LoopRun::from_report(&read(f, "truth.json")?, &read(f, "report.json")?)
            .map_err(|e| anyhow::anyhow!("{}: {e}", f.join("report.json").display()))?;
        runs.push(run);
    }
    print!(
        "{} runs under {}: the kept additions against the truth, and the test MSE (mean ± sd):\n\n{}",
        runs.len(),
        dir.display(),
        loop_table(&runs)
    );
    Ok(())
}

/// The folders under `dir` (itself included) that hold a run: `report.json` and `truth.json`.
/// Links into folders are followed, each folder read once (by its canonical path), so a link
/// back up the tree ends the walk there instead of recursing.
fn run_folders(dir: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
    let mut seen = std::collections::HashSet::new();
    walk_runs(dir, &mut seen, out)
}

fn walk_runs(
    dir: &Path,
    seen: &mut std::collections::HashSet<PathBuf>,
    out: &mut Vec<PathBuf>,
) -> Result<()> {
    let canonical = dir
        .canonicalize()
        .with_context(|| format!("{}: cannot resolve it", dir.display()))?;
    if !seen.insert(canonical) {
        return Ok(());
    }
    if dir.join("report.json").is_file() && dir.join("truth.json").is_file() {
        out.push(dir.to_path_buf());
    }
    let entries =
        std::fs::read_dir(dir).with_context(|| format!("{}: cannot list it", dir.display()))?;
    for e in entries {
        let path = e?.path();
        if path.is_dir() {
            walk_runs(&path, seen, out)?;
        }
    }
    Ok(())
}

/// A folder name for a scenario (`+` spelled `-and-`).
fn folder(spec: &Spec) -> String {
    let mut name = spec.scenario.name().replace('+', "-and-");
    if spec.noise != NoiseModel::Paper {
        name += &format!("-{}", spec.noise.name());
    }
    if spec.scenario.has_event() && spec.placement != SplitName::Train {
        name += &format!("-{}", spec.placement);
    }
    name
}

/// Runs `magic synth-loop`: the loop on one synthetic dataset per scenario and seed, with a
/// line per run (the effects it added and kept, the test MSE of B and C before and after) and,
/// over several seeds, a summary of what it recovered ([`loop_table`]).
pub fn run_loop(a: &SynthLoopCmd) -> Result<()> {
    if let Some(dir) = &a.summarise {
        return summarise(dir);
    }
    let mut table = String::from(
        "| injected | placement | noise | seed | effects added (explained vs chance) | B test before → after | C test before → after |\n|---|---|---|---|---|---|---|\n",
    );
    print!("{table}");
    let site = a.site.site()?;
    std::fs::create_dir_all(&a.out)?;
    let mut runs = Vec::new();
    for spec in specs(
        &scenarios(&a.scenarios),
        &a.noise,
        &a.placement,
        a.seed..a.seed + a.seeds.max(1),
    ) {
        let seed = spec.seed;
        let s = spec.generate_on(&site)?;
        let opts = LoopOptions {
            seed,
            train: s
                .problem
                .recipe()
                .with(a.epochs, true)
                .with_warmup(a.warmup.get()),
            max_rounds: a.rounds,
            baseline: false,
            analysis: AnalysisOptions {
                main_source: a.main_source,
                lasting: a.lasting,
                extra_sources: a.extra_sources,
                steps: a.steps,
                ..AnalysisOptions::default()
            },
        };
        let mut dir = a.out.join(folder(&spec));
        if a.seeds > 1 {
            dir = dir.join(format!("seed-{seed}"));
        }
        eprintln!(
            "scenario {} ({})",
            spec.scenario.name(),
            s.problem.data.source
        );
        let r = closed_loop::run(&s.problem, &opts, &dir)?;
        write_file(
            &dir.join("truth.json"),
            serde_json::to_string_pretty(&s.truth)?,
        )?;
        let (first, last) = (r.first(), r.last_kept());
        let run = LoopRun::new(
            &s.truth,
            &r.kept_additions(),
            [first.b.mse[2], last.b.mse[2]],
            [first.c.mse[2], last.c.mse[2]],
        );
        let line = format!(
            "| {} | {} | {} | {seed} | {} | {:.4} → {:.4} | {:.4} → {:.4} |\n",
            spec.scenario.name(),
            spec.placement_label(),
            spec.noise.name(),
            if run.added.is_empty() {
                "none".to_string()
            } else {
                run.added.join(", ")
            },
            run.b[0],
            run.b[1],
            run.c[0],
            run.c[1]
        );
        // Each run's line as it comes, on the screen and in the file: a stopped run keeps
        // what it did.
        print!("{line}");
        std::io::Write::flush(&mut std::io::stdout())?;
        table += &line;
        write_file(&a.out.join("table.md"), &table)?;
        runs.push(run);
    }
    let summary = format!(
        "\nOver the seeds: the kept additions against the truth, and the test MSE (mean ± sd):\n\n{}",
        loop_table(&runs)
    );
    print!("{summary}");
    table += &summary;
    write_file(&a.out.join("table.md"), &table)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scenarios_without_events_run_once() {
        let all = [SplitName::Train, SplitName::Valid, SplitName::Test];
        let s = specs(
            &[
                Scenario::Clean,
                Scenario::Step,
                Scenario::CommonModeSeasonal,
            ],
            &NoiseModel::ALL,
            &all,
            1..2,
        );
        assert_eq!(s.len(), 2 * (1 + 3 + 1));
        assert_eq!(s.iter().filter(|x| x.scenario == Scenario::Step).count(), 6);
        assert_eq!(
            folder(&Spec::new(Scenario::SecondSourceStep, 1).placed(SplitName::Test)),
            "second_source-and-step-test"
        );
        assert_eq!(
            folder(&Spec::new(Scenario::Clean, 1).noise(NoiseModel::Red)),
            "clean-red"
        );
    }

    #[test]
    fn summarise_says_where_a_run_is_missing_or_broken() {
        let dir = std::env::temp_dir().join(format!("magic-summarise-{}", std::process::id()));
        let run = dir.join("step").join("seed-1");
        std::fs::create_dir_all(&run).unwrap();
        let err = summarise(&dir).unwrap_err().to_string();
        assert!(err.contains("no run under it"), "{err}");
        std::fs::write(
            run.join("truth.json"),
            r#"{"scenario": "step", "effects": []}"#,
        )
        .unwrap();
        std::fs::write(run.join("report.json"), r#"{"loop": {"rounds": [}}"#).unwrap();
        let err = format!("{:#}", summarise(&dir).unwrap_err());
        assert!(err.contains("report.json: not JSON"), "{err}");
        std::fs::write(run.join("report.json"), r#"{"loop": {}}"#).unwrap();
        let err = summarise(&dir).unwrap_err().to_string();
        assert!(err.contains("seed-1/report.json: no rounds"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[cfg(unix)]
    #[test]
    fn run_folders_reads_each_folder_once_through_links() {
        let dir = std::env::temp_dir().join(format!("magic-runs-{}", std::process::id()));
        let run = dir.join("step").join("seed-1");
        std::fs::create_dir_all(&run).unwrap();
        std::fs::write(run.join("truth.json"), "{}").unwrap();
        std::fs::write(run.join("report.json"), "{}").unwrap();
        // A link back up the tree, and a second way into the same run.
        std::os::unix::fs::symlink(&dir, run.join("up")).unwrap();
        std::os::unix::fs::symlink(&run, dir.join("again")).unwrap();
        let mut found = Vec::new();
        run_folders(&dir, &mut found).unwrap();
        assert_eq!(found.len(), 1, "{found:?}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
