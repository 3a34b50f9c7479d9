//! Argument groups shared by the commands (flattened into each), the enumerated options, and
//! the loading they imply: data folders, model files, problems.

use crate::gnss::GnssProblem;
use crate::rtm::{GeometryArg, RtmProblem};
use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use magic_core::Model;
use std::path::{Path, PathBuf};

/// Which problem.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ProblemArg {
    /// The Mogi source under a GNSS network.
    Mogi,
    /// INFORM under Sentinel-2 forest spectra.
    Rtm,
}

/// Where the data is.
#[derive(Args, Clone, Debug, Default)]
pub struct DataArgs {
    /// Data folder laid out like `shared/data/gnss` (volcano) or `shared/data/s2` (forest)
    /// (default: `$MAGIC_DATA/gnss` or `…/s2`, else `../shared/data/…`).
    #[arg(long)]
    pub data_dir: Option<PathBuf>,
    /// Forest: the INFORM tables folder laid out like `shared/data/rtm` (default:
    /// `$MAGIC_DATA/rtm`, else `../shared/data/rtm`).
    #[arg(long)]
    pub tables: Option<PathBuf>,
}

impl DataArgs {
    /// The volcano problem from the GNSS folder.
    pub fn gnss(&self) -> Result<GnssProblem> {
        let dir =
            crate::data::require(self.data_dir.as_deref(), "gnss", "GNSS data", "--data-dir")?;
        GnssProblem::read(&dir)
    }

    /// The forest problem from the S2 and tables folders.
    pub fn rtm(&self, geometry: magic_core::rtm::Geometry) -> Result<RtmProblem> {
        let dir = crate::data::require(self.data_dir.as_deref(), "s2", "S2 data", "--data-dir")?;
        let tables = self.tables_dir()?;
        RtmProblem::read(&dir, &tables, geometry)
    }

    /// The INFORM tables folder.
    pub fn tables_dir(&self) -> Result<PathBuf> {
        crate::data::require(self.tables.as_deref(), "rtm", "RTM tables", "--tables")
    }

    /// The problem a model file was made for, with its data.
    pub fn problem_of(&self, model: &Model<'_>) -> Result<AnyProblem> {
        Ok(match model.problem {
            magic_core::Problem::Mogi { .. } => AnyProblem::Mogi(Box::new(self.gnss()?)),
            magic_core::Problem::Rtm { geometry, .. } => {
                AnyProblem::Rtm(Box::new(self.rtm(geometry)?))
            }
        })
    }

    /// `problem` with its data.
    pub fn problem(&self, problem: ProblemArg, geometry: GeometryArg) -> Result<AnyProblem> {
        Ok(match problem {
            ProblemArg::Mogi => AnyProblem::Mogi(Box::new(self.gnss()?)),
            ProblemArg::Rtm => AnyProblem::Rtm(Box::new(self.rtm(geometry.into())?)),
        })
    }
}

/// Either problem, with its data.
pub enum AnyProblem {
    /// The volcano.
    Mogi(Box<GnssProblem>),
    /// The forest.
    Rtm(Box<RtmProblem>),
}

/// Runs `$body` with `$p` bound to the concrete problem inside an [`AnyProblem`].
#[macro_export]
macro_rules! with_problem {
    ($any:expr, |$p:ident| $body:expr) => {
        match $any {
            $crate::cli::args::AnyProblem::Mogi($p) => {
                let $p = &**$p;
                $body
            }
            $crate::cli::args::AnyProblem::Rtm($p) => {
                let $p = &**$p;
                $body
            }
        }
    };
}

/// A model file.
#[derive(Args, Clone, Debug)]
pub struct ModelArg {
    /// Model file (`magic train` writes f32 models, `magic export` int8 ones).
    #[arg(long)]
    pub model: PathBuf,
}

impl ModelArg {
    /// The file's bytes.
    pub fn read(&self) -> Result<Vec<u8>> {
        read_model(&self.model)
    }
}

/// A model file's bytes.
pub fn read_model(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).with_context(|| format!("{}: cannot read model file", path.display()))
}

/// Decodes model bytes read from `path` (errors name the file, and say what to do with a
/// format-5 C model whose steps or drifts the correction saw then).
pub fn decode<'a>(path: &Path, bytes: &'a [u8]) -> Result<Model<'a>> {
    Model::decode(bytes).map_err(|e| {
        let hint = match e {
            magic_core::Error::UnsupportedVersion { found: 5, .. } => {
                " (a variant-C model with steps or drifts, written when C saw them; since format \
                 6 they are added after C: train it again with this build)"
            }
            _ => "",
        };
        anyhow::Error::new(e).context(format!("{}: not a usable model file{hint}", path.display()))
    })
}

/// The warm-up of early stopping (`--warmup`), on every command that trains with a recipe.
#[derive(Args, Clone, Copy, Debug, Default)]
pub struct Warmup {
    /// Epochs early stopping does not watch, their weights never kept (default: the recipe's,
    /// the volcano's learning-rate step 50, the forest's 0; 0 is the paper's rule).
    #[arg(long)]
    warmup: Option<usize>,
}

impl Warmup {
    /// The epochs given, or `None` for the recipe's.
    pub fn get(self) -> Option<usize> {
        self.warmup
    }
}

/// Where to write JSON.
#[derive(Args, Clone, Debug, Default)]
pub struct JsonOut {
    /// Write the figures as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

impl JsonOut {
    /// Writes `value` when a path was given.
    pub fn write<T: serde::Serialize>(&self, value: &T) -> Result<()> {
        if let Some(p) = &self.json {
            std::fs::write(p, serde_json::to_string_pretty(value)?)
                .with_context(|| format!("{}: cannot write", p.display()))?;
        }
        Ok(())
    }
}

/// Writes `text` to `path`, naming the file on failure.
pub fn write_file(path: &Path, text: impl AsRef<[u8]>) -> Result<()> {
    std::fs::write(path, text).with_context(|| format!("{}: cannot write", path.display()))
}

/// Parses a count of terms F may hold of one family (`--extra-sources`, `--steps`): at most
/// [`MAX_EFFECTS`](magic_core::effects::MAX_EFFECTS), the effects a model file carries.
pub fn terms(s: &str) -> std::result::Result<usize, String> {
    let most = magic_core::effects::MAX_EFFECTS;
    let n: usize = s
        .parse()
        .map_err(|_| format!("`{s}` is not a whole number"))?;
    if n > most {
        return Err(format!(
            "{n} is more than F can hold: a model file carries at most {most} effects"
        ));
    }
    Ok(n)
}

#[cfg(test)]
mod tests {
    #[test]
    fn terms_are_counted_up_to_what_a_model_file_carries() {
        assert_eq!(super::terms("0"), Ok(0));
        assert_eq!(super::terms("4"), Ok(4));
        let more = super::terms("5").unwrap_err();
        assert!(more.contains("at most 4 effects"), "{more}");
        assert!(super::terms("two").unwrap_err().contains("`two`"));
    }
}
