//! `magic`: train, evaluate, export and run learned inversions of physical models.

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand, ValueEnum};
use magic_core::model_file::Problem;
use magic_core::{Model, Variant};
use magic_train::data::{self, gnss::GnssData};
use magic_train::{
    demo, evaluate, pipeline, records, residuals, rtm_cli, synth, OwnedModel, TrainConfig,
};
use std::path::{Path, PathBuf};

#[derive(Parser)]
#[command(
    name = "magic",
    version,
    about = "Learned inversion of physical models with bias correction"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Clone, Copy, ValueEnum)]
enum VariantArg {
    #[value(name = "A", alias = "a")]
    A,
    #[value(name = "B", alias = "b")]
    B,
    #[value(name = "C", alias = "c")]
    C,
}

impl From<VariantArg> for Variant {
    fn from(v: VariantArg) -> Variant {
        match v {
            VariantArg::A => Variant::A,
            VariantArg::B => Variant::B,
            VariantArg::C => Variant::C,
        }
    }
}

#[derive(Subcommand)]
enum Cmd {
    /// Train a model.
    Train {
        #[command(subcommand)]
        problem: TrainProblem,
    },
    /// The paper's MSE of a model on a split (standardised units).
    Eval {
        /// Model file.
        #[arg(long)]
        model: PathBuf,
        /// Data folder laid out like `shared/data/gnss` (default: $MAGIC_DATA/gnss or ../shared/data/gnss).
        #[arg(long)]
        data_dir: Option<PathBuf>,
        /// Split to evaluate.
        #[arg(long, default_value = "test")]
        split: String,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// Quantise a trained model for the microcontroller.
    Export {
        /// Trained (f32) model file.
        #[arg(long)]
        model: PathBuf,
        /// Quantisation.
        #[arg(long, default_value = "int8")]
        quant: String,
        /// Calibration data folder (default as for `eval`).
        #[arg(long)]
        data_dir: Option<PathBuf>,
        /// Output model file.
        #[arg(long)]
        out: PathBuf,
    },
    /// Invert observations on the host (physics in f64).
    Invert {
        /// Model file.
        #[arg(long)]
        model: PathBuf,
        /// Observation CSV with columns `ux_<STA>` … in mm (or standardised with --standardized).
        #[arg(long)]
        input: PathBuf,
        /// Result CSV.
        #[arg(long)]
        output: PathBuf,
        /// The input holds standardised values (the data files as they are).
        #[arg(long)]
        standardized: bool,
    },
    /// Build the firmware with a model and invert observations on it under QEMU.
    Qemu {
        /// Model file (int8, from `magic export`).
        #[arg(long)]
        model: PathBuf,
        /// Observation CSV, as for `magic invert`.
        #[arg(long)]
        input: PathBuf,
        /// Result CSV (same format as `magic invert`).
        #[arg(long)]
        output: PathBuf,
        /// The input holds standardised values.
        #[arg(long)]
        standardized: bool,
    },
    /// Talk to a board running the deployable firmware (or QEMU): upload a model, stream days.
    Station {
        /// `tcp:HOST:PORT` (QEMU's `-serial tcp::PORT,server`) or a serial device (`/dev/ttyUSB0`).
        #[arg(long)]
        port: String,
        /// Model file (int8, from `magic export`): uploaded unless the board runs it already.
        #[arg(long)]
        model: Option<PathBuf>,
        /// Observation CSV, as for `magic invert` (needs --model).
        #[arg(long)]
        days: Option<PathBuf>,
        /// Result CSV: the date, the model id, then `magic invert`'s columns (default: stdout).
        #[arg(long)]
        output: Option<PathBuf>,
        /// The days hold standardised values.
        #[arg(long)]
        standardized: bool,
    },
    /// Evaluate a forward model.
    Forward {
        #[command(subcommand)]
        problem: ForwardProblem,
    },
    /// Write a synthetic GNSS dataset in the release layout.
    Synth {
        /// Scenario (`clean`, or an injected effect family).
        #[arg(long, default_value = "clean")]
        scenario: String,
        /// Random seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
    },
    /// Residual analysis: fit each effect family to the residuals of a model (observation − F(E(x)))
    /// and rank the families by the share of residual variance they explain on held-out data
    /// beyond chance.
    Residuals {
        /// Model file (variant B or C).
        #[arg(long)]
        model: PathBuf,
        /// Data folder laid out like `shared/data/gnss` (default as for `eval`).
        #[arg(long)]
        data_dir: Option<PathBuf>,
        /// Split the families are fitted on (the fitted families are scored on the others; RTM
        /// models: scored on the next split, train → valid, valid → test).
        #[arg(long, default_value = "train")]
        split: String,
        /// Surrogates per family for the chance level.
        #[arg(long, default_value_t = 20)]
        surrogates: usize,
        /// Seed of the surrogates.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Write the ranked families as JSON here.
        #[arg(long)]
        json: Option<PathBuf>,
        /// Write `effects.png`, `residual_pattern.png` and `residual_rms.png` into this folder.
        #[arg(long)]
        plots: Option<PathBuf>,
    },
    /// The loop on synthetic data: for every scenario, generate the data (one seed), run `magic
    /// loop` on it and print what it added and the test MSE before and after.
    SynthLoop {
        /// Scenarios, comma-separated (default: all).
        #[arg(long, value_delimiter = ',')]
        scenarios: Vec<String>,
        /// Seed of the data and the training.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Maximum epochs per training.
        #[arg(long, default_value_t = 100)]
        epochs: usize,
        /// Most effects to add.
        #[arg(long, default_value_t = 3)]
        rounds: usize,
        /// Folder for each scenario's loop report.
        #[arg(long, default_value = "out/synth-loop")]
        out: PathBuf,
    },
    /// Check the residual analysis on synthetic data: for every scenario and seed, generate the
    /// data, train a B model briefly, analyse it and compare with the injected truth.
    SynthCheck {
        /// Number of seeds per scenario (seeds first-seed, first-seed + 1, …).
        #[arg(long, default_value_t = 10)]
        seeds: u64,
        /// First seed.
        #[arg(long, default_value_t = 1)]
        first_seed: u64,
        /// Scenarios, comma-separated (default: all).
        #[arg(long, value_delimiter = ',')]
        scenarios: Vec<String>,
        /// Training epochs of the B models.
        #[arg(long, default_value_t = 15)]
        epochs: usize,
        /// Write every analysis and its comparison with the truth as JSON here.
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// Reproduce a table of the paper over several seeds (mean ± std).
    Reproduce {
        /// Which table: `mogi` (Table 4) or `rtm` (Table 3).
        problem: String,
        /// Data folder.
        #[arg(long)]
        data_dir: Option<PathBuf>,
        /// RTM tables folder (default: $MAGIC_DATA/rtm or ../shared/data/rtm).
        #[arg(long)]
        tables: Option<PathBuf>,
        /// RTM variants to train, comma-separated.
        #[arg(long, default_value = "A,B,C,D")]
        variants: String,
        /// Seeds, comma-separated.
        #[arg(long, default_value = "1,2,3", value_delimiter = ',')]
        seeds: Vec<u64>,
        /// Maximum epochs.
        #[arg(long, default_value_t = 100)]
        epochs: usize,
        /// Write the numbers as JSON here.
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// Retrieved LAI of an RTM model (B, C or D) against the SNAP LAI of the site extract: rank
    /// correlation per species and date.
    Lai {
        /// RTM model file.
        #[arg(long)]
        model: PathBuf,
        /// S2 folder (default: $MAGIC_DATA/s2 or ../shared/data/s2).
        #[arg(long)]
        data_dir: Option<PathBuf>,
        /// Write the figures as JSON here.
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// Inversion with stations down: 1, 2, 4 random stations and the two nearest the source.
    Missing {
        /// Model file.
        #[arg(long)]
        model: PathBuf,
        /// Data folder.
        #[arg(long)]
        data_dir: Option<PathBuf>,
        /// Split.
        #[arg(long, default_value = "test")]
        split: String,
        /// Seed for the random removals.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Write the figures as JSON here.
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// The classical baseline: a least-squares fit of the Mogi source for every day (no encoder).
    Classical {
        /// Data folder.
        #[arg(long)]
        data_dir: Option<PathBuf>,
        /// Splits, comma-separated (train, valid, test).
        #[arg(long, default_value = "test", value_delimiter = ',')]
        split: Vec<String>,
        /// Latent effects fitted with the source, comma-separated (common_mode, elevation).
        #[arg(long, value_delimiter = ',')]
        effects: Vec<String>,
        /// Start grid NX,NY,ND,KEEP: points over x, y, depth, and how many of the best are refined.
        #[arg(long, default_value = "12,12,10,8")]
        grid: String,
        /// Write the summaries as JSON here.
        #[arg(long)]
        json: Option<PathBuf>,
        /// Write the per-day fits as CSV here.
        #[arg(long)]
        csv: Option<PathBuf>,
    },
    /// Close the loop: train, trace the residual to a missing effect, add it to F, retrain, report.
    Loop {
        /// Problem: `mogi` (GNSS) or `rtm` (Sentinel-2 forest spectra).
        #[arg(long, default_value = "mogi")]
        problem: String,
        /// Data folder (default: $MAGIC_DATA/gnss or …/s2, ../shared/data/gnss or …/s2).
        #[arg(long)]
        data_dir: Option<PathBuf>,
        /// RTM: tables folder (default: $MAGIC_DATA/rtm or ../shared/data/rtm).
        #[arg(long)]
        tables: Option<PathBuf>,
        /// RTM: INFORM geometry mode (`physical`: the published equations; `reference`: the
        /// paper's implementation, which hands INFORM cosines where angles are expected, so a
        /// declared sun would not mean what it says).
        #[arg(long, default_value = "physical")]
        geometry: String,
        /// RTM: surrogates per family in the residual analysis.
        #[arg(long, default_value_t = 20)]
        surrogates: usize,
        /// Report folder (Markdown, JSON, PNG).
        #[arg(long, default_value = "out/loop")]
        report: PathBuf,
        /// Training seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Maximum epochs per training.
        #[arg(long, default_value_t = 100)]
        epochs: usize,
        /// Most effects to add.
        #[arg(long, default_value_t = 3)]
        rounds: usize,
        /// Skip the classical per-day fit.
        #[arg(long)]
        no_classical: bool,
    },
    /// The main job: train C and B, evaluate, export int8, run the test days on the firmware.
    Demo {
        /// Data folder laid out like `shared/data/gnss` (default: $MAGIC_DATA/gnss, ../shared/data/gnss,
        /// else a built-in synthetic dataset).
        #[arg(long)]
        data_dir: Option<PathBuf>,
        /// Random seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Maximum epochs.
        #[arg(long, default_value_t = 100)]
        epochs: usize,
        /// Folder for the model files and results.
        #[arg(long, default_value = "out/demo")]
        out: PathBuf,
        /// Skip the firmware run under QEMU.
        #[arg(long)]
        no_qemu: bool,
    },
    /// Convert a folder of NGL `<STA>.tenv3` files to daily displacement rows (mm) for `invert`.
    Tenv3 {
        /// Folder holding `<STA>.tenv3` files.
        #[arg(long)]
        dir: PathBuf,
        /// Output CSV (`ux_<STA>` ×S, `uy_<STA>` ×S, `uz_<STA>` ×S, `date`; NaN = missing).
        #[arg(long)]
        out: PathBuf,
        /// Station order from a `stations.json` (default: every file in the folder, by name).
        #[arg(long, conflicts_with = "model")]
        stations: Option<PathBuf>,
        /// Station order from a model file.
        #[arg(long)]
        model: Option<PathBuf>,
        /// Reference epoch `YYYY-MM-DD` (default: the first day every station has data).
        #[arg(long)]
        reference: Option<String>,
    },
}

#[derive(Subcommand)]
enum ForwardProblem {
    /// Mogi displacements (mm) at the network's stations for rows of
    /// `xcen_km, ycen_km, d_km, dV_1e6m3`.
    Mogi {
        /// Input CSV.
        #[arg(long)]
        input: PathBuf,
        /// Output CSV (`ux_<STA>` ×S, `uy_<STA>` ×S, `uz_<STA>` ×S).
        #[arg(long)]
        output: PathBuf,
        /// Network: a `stations.json` (default: the built-in Akutan network).
        #[arg(long)]
        stations: Option<PathBuf>,
    },
    /// INFORM reflectance in the 13 Sentinel-2 bands B01…B12 for rows of the 21 inputs (columns
    /// named as in `oracle/rtm_inform_s2_10k.csv`).
    Rtm {
        /// Input CSV.
        #[arg(long)]
        input: PathBuf,
        /// Output CSV (`B01` … `B12`; `sample_id` first when the input has one).
        #[arg(long)]
        output: PathBuf,
        /// Geometry mode: `reference` (the paper's implementation) or `physical`.
        #[arg(long, default_value = "reference")]
        geometry: String,
        /// Tables folder (default: $MAGIC_DATA/rtm or ../shared/data/rtm).
        #[arg(long)]
        tables: Option<PathBuf>,
    },
}

#[derive(Subcommand)]
enum TrainProblem {
    /// The Mogi source under the GNSS network.
    Mogi {
        /// Paper variant.
        #[arg(long, value_enum, default_value = "C")]
        variant: VariantArg,
        /// Data folder laid out like `shared/data/gnss`.
        #[arg(long)]
        data_dir: Option<PathBuf>,
        /// Maximum epochs.
        #[arg(long, default_value_t = 100)]
        epochs: usize,
        /// Random seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Weight of the smoothness term (eq. 19).
        #[arg(long, default_value_t = 0.01)]
        lambda: f64,
        /// Declared latent effects added to F, comma-separated: `common_mode`, `elevation`.
        #[arg(long, value_delimiter = ',')]
        effects: Vec<String>,
        /// How the smoothness term is reduced: `sum` (eq. 19 as printed) or `mean` (per element,
        /// the scale of the MSE term).
        #[arg(long, default_value = "mean")]
        smooth: String,
        /// Output model file (f32).
        #[arg(long)]
        out: PathBuf,
    },
    /// INFORM under the Sentinel-2 forest spectra.
    Rtm {
        /// Paper variant: A, B, C, or D (the regressor baseline).
        #[arg(long, default_value = "C")]
        variant: String,
        /// Data folder laid out like `shared/data/s2`.
        #[arg(long)]
        data_dir: Option<PathBuf>,
        /// Tables folder laid out like `shared/data/rtm`.
        #[arg(long)]
        tables: Option<PathBuf>,
        /// Maximum epochs.
        #[arg(long, default_value_t = 100)]
        epochs: usize,
        /// Random seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Geometry mode: `reference` (the paper's implementation) or `physical`.
        #[arg(long, default_value = "reference")]
        geometry: String,
        /// Train on the first N training spectra only (0: all).
        #[arg(long, default_value_t = 0)]
        limit: usize,
        /// Declared effects, comma-separated: `illumination` (each spectrum's own sun from its
        /// date at 47.5° N 14.5° E, 10:00 UTC; use with `--geometry physical`).
        #[arg(long, value_delimiter = ',')]
        effects: Vec<String>,
        /// Output model file (f32).
        #[arg(long)]
        out: PathBuf,
    },
}

fn load_gnss(dir: Option<&Path>) -> Result<GnssData> {
    let Some(d) = data::locate(dir, "gnss") else {
        bail!("no GNSS data: pass --data-dir, set MAGIC_DATA, or run next to shared/data")
    };
    GnssData::read(&d)
}

fn read_model(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).with_context(|| format!("{}: cannot read model file", path.display()))
}

fn decode<'a>(path: &Path, bytes: &'a [u8]) -> Result<Model<'a>> {
    Model::decode(bytes).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
}

fn main() {
    if let Err(e) = run(Cli::parse()) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.cmd {
        Cmd::Train {
            problem:
                TrainProblem::Mogi {
                    variant,
                    data_dir,
                    epochs,
                    seed,
                    lambda,
                    effects,
                    smooth,
                    out,
                },
        } => {
            let data = load_gnss(data_dir.as_deref())?;
            let smooth_mean = match smooth.as_str() {
                "sum" => false,
                "mean" => true,
                other => bail!("--smooth {other}: expected `sum` or `mean`"),
            };
            let cfg = TrainConfig {
                epochs,
                lambda,
                smooth_mean,
                ..TrainConfig::gnss()
            };
            let effects = effects
                .iter()
                .map(|e| pipeline::latent_effect(e, &data))
                .collect::<Result<Vec<_>>>()?;
            let (model, log) =
                pipeline::train_mogi_with(&data, variant.into(), &effects, &cfg, seed)?;
            std::fs::write(&out, model.encode()?)
                .with_context(|| format!("{}: cannot write", out.display()))?;
            eprintln!(
                "trained {:?}: {} epochs ({:.2} s/epoch, {:.1} s), best valid MSE {:.4} at epoch {} -> {}",
                Variant::from(variant),
                log.epochs,
                log.seconds_per_epoch(),
                log.seconds,
                log.best_valid,
                log.best_epoch,
                out.display()
            );
        }
        Cmd::Train {
            problem:
                TrainProblem::Rtm {
                    variant,
                    data_dir,
                    tables,
                    epochs,
                    seed,
                    geometry,
                    limit,
                    effects,
                    out,
                },
        } => {
            rtm_cli::train(&rtm_cli::TrainArgs {
                variant,
                data_dir,
                tables,
                epochs,
                seed,
                geometry,
                limit,
                effects,
                out,
            })?;
        }
        Cmd::Eval {
            model,
            data_dir,
            split,
            json,
        } => {
            let bytes = read_model(&model)?;
            let m = decode(&model, &bytes)?;
            if let Problem::Rtm { .. } = m.problem {
                return rtm_cli::eval(&m, data_dir.as_deref(), &split, json);
            }
            let data = load_gnss(data_dir.as_deref())?;
            let r = evaluate(&m, data.split(&split)?, &split)?;
            if json {
                println!("{}", serde_json::to_string(&r)?);
            } else {
                print!("{split}: n = {}, MSE = {:.4}", r.n, r.mse);
                if let Some(p) = r.physics_mse {
                    print!(", physics-only MSE = {p:.4}");
                }
                println!();
            }
        }
        Cmd::Export {
            model,
            quant,
            data_dir,
            out,
        } => {
            if quant != "int8" {
                bail!("--quant {quant}: only int8 is supported");
            }
            let bytes = read_model(&model)?;
            let m = decode(&model, &bytes)?;
            let qb = if let Problem::Rtm { .. } = m.problem {
                rtm_cli::export_int8(&m, data_dir.as_deref())?
            } else {
                let data = load_gnss(data_dir.as_deref())?;
                OwnedModel::from_model(&m)
                    .quantize_int8(&data.train.x)?
                    .encode()?
            };
            std::fs::write(&out, &qb)
                .with_context(|| format!("{}: cannot write", out.display()))?;
            eprintln!(
                "exported int8 model: {} bytes -> {}",
                qb.len(),
                out.display()
            );
        }
        Cmd::Invert {
            model,
            input,
            output,
            standardized,
        } => {
            let bytes = read_model(&model)?;
            let m = decode(&model, &bytes)?;
            let rows = records::read_obs(&input, &m, standardized)?;
            let lines = records::invert_rows(&m, &rows);
            report_row_errors(&rows);
            records::write_results(&output, &m, &rows, &lines)?;
            let bad = lines.iter().filter(|l| l.starts_with("error,")).count();
            eprintln!(
                "inverted {} rows ({} errors) -> {}",
                lines.len(),
                bad,
                output.display()
            );
            if bad > 0 {
                bail!(
                    "{bad} of {} rows could not be inverted (error rows written)",
                    lines.len()
                );
            }
        }
        Cmd::Station {
            port,
            model,
            days,
            output,
            standardized,
        } => magic_train::station::run_cli(&magic_train::station::Options {
            port,
            model,
            days,
            output,
            standardized,
        })?,
        Cmd::Forward {
            problem:
                ForwardProblem::Mogi {
                    input,
                    output,
                    stations,
                },
        } => {
            forward_mogi(&input, &output, stations.as_deref())?;
        }
        Cmd::Forward {
            problem:
                ForwardProblem::Rtm {
                    input,
                    output,
                    geometry,
                    tables,
                },
        } => {
            rtm_cli::forward(&input, &output, tables.as_deref(), &geometry)?;
        }
        Cmd::Lai {
            model,
            data_dir,
            json,
        } => {
            rtm_cli::lai(&model, data_dir.as_deref(), json.as_deref())?;
        }
        Cmd::Qemu {
            model,
            input,
            output,
            standardized,
        } => {
            let bytes = read_model(&model)?;
            let m = decode(&model, &bytes)?;
            let rows = records::read_obs(&input, &m, standardized)?;
            report_row_errors(&rows);
            let run = magic_train::demo_qemu::run_rows(&model, &m, &rows)?;
            records::write_results(&output, &m, &rows, &run.results)?;
            for (k, v) in &run.costs {
                eprintln!("# {k} = {v}");
            }
            let host = records::invert_rows(&m, &rows);
            let (worst, mismatched) = magic_train::demo_qemu::agreement(&m, &run.results, &host);
            eprintln!(
                "{} rows -> {}; largest difference from the host: {:.1e} of a variable's range; {} rows failed on one side only",
                rows.len(),
                output.display(),
                worst.iter().copied().fold(0.0, f64::max),
                mismatched
            );
        }
        Cmd::Synth {
            scenario,
            seed,
            out,
        } => {
            let sc = synth::Scenario::parse(&scenario)?;
            let s = synth::generate(sc, seed);
            synth::write_dir(&s.data, &out)?;
            std::fs::write(
                out.join("truth.json"),
                serde_json::to_string_pretty(&s.truth)?,
            )?;
            eprintln!(
                "wrote synthetic dataset ({}) -> {}",
                s.data.source,
                out.display()
            );
        }
        Cmd::SynthLoop {
            scenarios,
            seed,
            epochs,
            rounds,
            out,
        } => {
            let scs = synth::Scenario::parse_list(&scenarios)?;
            let opts = magic_train::closed_loop::LoopOptions {
                seed,
                train: TrainConfig {
                    epochs,
                    progress: false,
                    ..TrainConfig::gnss()
                },
                max_rounds: rounds,
                classical: false,
            };
            let mut table = String::from(
                "| injected | effects added (explained vs chance) | B test before → after | C test before → after |\n|---|---|---|---|\n",
            );
            for sc in scs {
                let s = synth::generate(sc, seed);
                let dir = out.join(sc.name());
                eprintln!("scenario {} (seed {seed})", sc.name());
                let r = magic_train::closed_loop::run(&s.data, &opts, &dir)?;
                std::fs::write(
                    dir.join("truth.json"),
                    serde_json::to_string_pretty(&s.truth)?,
                )?;
                let (first, last) = (&r[0], &r[r.len() - 1]);
                let added: Vec<String> = r
                    .iter()
                    .filter_map(|x| x.added.as_ref())
                    .map(|a| {
                        format!(
                            "{} ({:.3} vs {:.3})",
                            a.family, a.variance_explained, a.chance_level
                        )
                    })
                    .collect();
                table += &format!(
                    "| {} | {} | {:.4} → {:.4} | {:.4} → {:.4} |\n",
                    sc.name(),
                    if added.is_empty() {
                        "none".to_string()
                    } else {
                        added.join(", ")
                    },
                    first.b.mse[2],
                    last.b.mse[2],
                    first.c.mse[2],
                    last.c.mse[2]
                );
            }
            print!("{table}");
            std::fs::write(out.join("table.md"), &table)?;
        }
        Cmd::Residuals {
            model,
            data_dir,
            split,
            surrogates,
            seed,
            json,
            plots,
        } => {
            let bytes = read_model(&model)?;
            let m = decode(&model, &bytes)?;
            if let magic_core::Problem::Rtm { .. } = m.problem {
                // Forest spectra: fitted on `split`, scored on the next split.
                let held = match split.as_str() {
                    "train" => "valid",
                    "valid" => "test",
                    _ => "valid",
                };
                let data =
                    magic_train::data::s2::S2Data::read(&rtm_cli::locate_s2(data_dir.as_deref())?)?;
                let opts = magic_train::rtm_residuals::RtmAnalysisOptions {
                    fit_split: split.clone(),
                    split: held.into(),
                    surrogates,
                    seed,
                    ..Default::default()
                };
                let a = magic_train::rtm_residuals::analyse_rtm(&m, &data, &opts)?;
                print!("{}", a.table());
                eprintln!("analysis took {:.2} s", a.seconds);
                if let Some(p) = json {
                    std::fs::write(&p, serde_json::to_string_pretty(&a.to_json())?)
                        .with_context(|| format!("{}: cannot write", p.display()))?;
                }
                if let Some(d) = plots {
                    magic_train::rtm_residuals::write_plots(&a, &d)?;
                    eprintln!("plots -> {}", d.display());
                }
                return Ok(());
            }
            let data = load_gnss(data_dir.as_deref())?;
            let opts = residuals::AnalysisOptions {
                split,
                surrogates,
                seed,
                ..Default::default()
            };
            let a = residuals::analyse(&m, &data, &opts)?;
            print!("{}", a.table());
            eprintln!("analysis took {:.2} s", a.seconds);
            if let Some(p) = json {
                std::fs::write(&p, serde_json::to_string_pretty(&a.to_json())?)
                    .with_context(|| format!("{}: cannot write", p.display()))?;
            }
            if let Some(d) = plots {
                residuals::write_plots(&a, &d)?;
                eprintln!("plots -> {}", d.display());
            }
        }
        Cmd::SynthCheck {
            seeds,
            first_seed,
            scenarios,
            epochs,
            json,
        } => {
            let scs = synth::Scenario::parse_list(&scenarios)?;
            let cfg = TrainConfig {
                epochs,
                progress: false,
                ..TrainConfig::gnss()
            };
            let opts = residuals::AnalysisOptions::default();
            let mut rows = Vec::new();
            let mut out = Vec::new();
            for sc in scs {
                for seed in first_seed..first_seed + seeds {
                    let (r, a) = residuals::check_one(sc, seed, &cfg, &opts)?;
                    eprintln!(
                        "{:<14} seed {:>3}: top {:<14} {}  {}",
                        sc.name(),
                        seed,
                        r.top,
                        if r.ok() { "ok  " } else { "FAIL" },
                        r.detail
                    );
                    out.push(serde_json::json!({"scenario": sc.name(), "seed": seed, "ok": r.ok(), "ranked_first": r.ranked_first,
                        "significant": r.significant, "params_ok": r.params_ok, "detail": r.detail, "analysis": a.to_json()}));
                    rows.push(r);
                }
            }
            print!("{}", residuals::recovery_table(&rows));
            if let Some(p) = json {
                std::fs::write(&p, serde_json::to_string_pretty(&out)?)
                    .with_context(|| format!("{}: cannot write", p.display()))?;
            }
        }
        Cmd::Reproduce {
            problem,
            data_dir,
            tables,
            variants,
            seeds,
            epochs,
            json,
        } => {
            if problem == "rtm" {
                return rtm_cli::reproduce(
                    data_dir.as_deref(),
                    tables.as_deref(),
                    &seeds,
                    epochs,
                    &variants,
                    json.as_deref(),
                );
            }
            if problem != "mogi" {
                bail!("reproduce {problem}: expected `mogi` or `rtm`");
            }
            let data = load_gnss(data_dir.as_deref())?;
            let cfg = TrainConfig {
                epochs,
                ..TrainConfig::gnss()
            };
            let v = magic_train::reproduce::table4(&data, &seeds, &cfg)?;
            if let Some(p) = json {
                std::fs::write(&p, serde_json::to_string_pretty(&v)?)
                    .with_context(|| format!("{}: cannot write", p.display()))?;
            }
        }
        Cmd::Missing {
            model,
            data_dir,
            split,
            seed,
            json,
        } => {
            let data = load_gnss(data_dir.as_deref())?;
            let bytes = read_model(&model)?;
            let m = decode(&model, &bytes)?;
            let rows = magic_train::missing::evaluate_missing(&m, &data, &split, seed)?;
            magic_train::missing::print_table(&rows);
            if let Some(p) = json {
                std::fs::write(&p, serde_json::to_string_pretty(&rows)?)
                    .with_context(|| format!("{}: cannot write", p.display()))?;
            }
        }
        Cmd::Classical {
            data_dir,
            split,
            effects,
            grid,
            json,
            csv,
        } => {
            let grid = magic_train::classical::parse_grid(&grid)?;
            let data = load_gnss(data_dir.as_deref())?;
            magic_train::classical::run(
                &data,
                &split,
                &effects,
                &grid,
                json.as_deref(),
                csv.as_deref(),
            )?;
        }
        Cmd::Loop {
            problem,
            data_dir,
            tables,
            geometry,
            surrogates,
            report,
            seed,
            epochs,
            rounds,
            no_classical,
        } => {
            if problem == "rtm" {
                let mut setup = magic_train::rtm_pipeline::RtmSetup::read(
                    &rtm_cli::locate_s2(data_dir.as_deref())?,
                    &magic_train::data::rtm_tables::locate(tables.as_deref())?,
                    rtm_cli::parse_geometry(&geometry)?,
                )?;
                let opts = magic_train::rtm_loop::RtmLoopOptions {
                    seed,
                    train: TrainConfig {
                        epochs,
                        ..TrainConfig::s2()
                    },
                    max_rounds: rounds,
                    surrogates,
                };
                let r = magic_train::rtm_loop::run(&mut setup, &opts, &report)?;
                print!("{}", std::fs::read_to_string(report.join("report.md"))?);
                eprintln!("{} rounds; report in {}", r.rounds.len(), report.display());
                return Ok(());
            }
            if problem != "mogi" {
                bail!("loop --problem {problem}: expected `mogi` or `rtm`");
            }
            let data = load_gnss(data_dir.as_deref())?;
            let opts = magic_train::closed_loop::LoopOptions {
                seed,
                train: TrainConfig {
                    epochs,
                    ..TrainConfig::gnss()
                },
                max_rounds: rounds,
                classical: !no_classical,
            };
            let r = magic_train::closed_loop::run(&data, &opts, &report)?;
            print!(
                "{}",
                std::fs::read_to_string(report.join("report.md"))?
                    .split("\n## ")
                    .next()
                    .unwrap_or("")
            );
            eprintln!("{} rounds; report in {}", r.len(), report.display());
        }
        Cmd::Demo {
            data_dir,
            seed,
            epochs,
            out,
            no_qemu,
        } => {
            demo::run(data_dir.as_deref(), seed, epochs, &out, !no_qemu)?;
        }
        Cmd::Tenv3 {
            dir,
            out,
            stations,
            model,
            reference,
        } => {
            tenv3_cmd(
                &dir,
                &out,
                stations.as_deref(),
                model.as_deref(),
                reference.as_deref(),
            )?;
        }
    }
    Ok(())
}

fn tenv3_cmd(
    dir: &Path,
    out: &Path,
    stations: Option<&Path>,
    model: Option<&Path>,
    reference: Option<&str>,
) -> Result<()> {
    use magic_train::data::tenv3;
    let names = match (stations, model) {
        (Some(p), _) => Some(read_stations(p)?.0),
        (_, Some(p)) => Some(tenv3::model_station_names(&decode(p, &read_model(p)?)?)?),
        _ => None,
    };
    let reference = match reference {
        Some(r) => tenv3::Reference::Day(
            tenv3::parse_ymd(r).with_context(|| format!("--reference {r}: expected YYYY-MM-DD"))?,
        ),
        None => tenv3::Reference::Auto,
    };
    let read = tenv3::read_dir(dir, names.as_deref(), reference)?;
    for e in &read.errors {
        eprintln!("{e}");
    }
    for n in &read.notes {
        eprintln!("note: {n}");
    }
    read.daily.write_csv(out)?;
    let d = &read.daily;
    let span = if d.is_empty() {
        String::new()
    } else {
        format!(", {} … {}", d.date(0), d.date(d.len() - 1))
    };
    eprintln!(
        "{} stations, {} days{span}, {} bad lines skipped -> {}",
        d.stations.len(),
        d.len(),
        read.errors.len(),
        out.display()
    );
    if !read.errors.is_empty() {
        bail!(
            "{} bad lines or files in {} (skipped; everything else was written)",
            read.errors.len(),
            dir.display()
        );
    }
    Ok(())
}

fn report_row_errors(rows: &[records::ObsRow]) {
    for r in rows {
        if let Err(e) = &r.obs {
            eprintln!("error: {e}");
        }
    }
}

fn forward_mogi(input: &Path, output: &Path, stations: Option<&Path>) -> Result<()> {
    let (names, st) = match stations {
        Some(p) => read_stations(p)?,
        None => (
            synth::AKUTAN.iter().map(|s| s.0.to_string()).collect(),
            synth::AKUTAN
                .iter()
                .map(|s| magic_core::mogi::Station {
                    x_km: s.1,
                    y_km: s.2,
                    z_km: s.3,
                })
                .collect(),
        ),
    };
    let t = data::table::Table::read(input, b',')?;
    let cols: Vec<usize> = ["xcen_km", "ycen_km", "d_km", "dV_1e6m3"]
        .iter()
        .map(|c| t.col(c))
        .collect::<Result<_>>()?;
    let id = t.col("sample_id").ok();
    let mut text = String::new();
    if id.is_some() {
        text.push_str("sample_id,");
    }
    text.push_str(&magic_train::data::gnss::channel_names(&names).join(","));
    text.push('\n');
    let mut u = vec![0f64; 3 * st.len()];
    for r in 0..t.rows.len() {
        let p: Vec<f64> = cols
            .iter()
            .map(|&c| t.num(r, c, false))
            .collect::<Result<_>>()?;
        let p = [p[0], p[1], p[2], p[3]];
        magic_core::mogi::field(&st, &p, &mut u)
            .map_err(|e| anyhow::anyhow!("{}:{}: {e}", t.path, t.line(r)))?;
        if let Some(c) = id {
            text.push_str(t.text(r, c));
            text.push(',');
        }
        let f: Vec<String> = u.iter().map(|v| format!("{v:e}")).collect();
        text.push_str(&f.join(","));
        text.push('\n');
    }
    std::fs::write(output, text).with_context(|| format!("{}: cannot write", output.display()))?;
    eprintln!("{} rows -> {}", t.rows.len(), output.display());
    Ok(())
}

fn read_stations(p: &Path) -> Result<(Vec<String>, Vec<magic_core::mogi::Station>)> {
    let text =
        std::fs::read_to_string(p).with_context(|| format!("{}: cannot read", p.display()))?;
    let v: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("{}: not valid JSON", p.display()))?;
    let obj = v
        .as_object()
        .with_context(|| format!("{}: expected an object of stations", p.display()))?;
    let mut names = vec![];
    let mut st = vec![];
    for (k, s) in obj {
        let g = |f: &str| {
            s.get(f)
                .and_then(|x| x.as_f64())
                .with_context(|| format!("{}: station {k}: `{f}` missing", p.display()))
        };
        names.push(k.clone());
        st.push(magic_core::mogi::Station {
            x_km: g("xE")?,
            y_km: g("yN")?,
            z_km: g("zV")?,
        });
    }
    Ok((names, st))
}
