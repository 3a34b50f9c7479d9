//! `magic forward`: evaluate a forward model on rows of its inputs — one output row per input
//! row (a row that cannot be evaluated gives NaN values and an error message naming its line).

use super::args::write_file;
use crate::data::table::Table;
use crate::gnss::Network;
use crate::rtm::{GeometryArg, RtmTables};
use anyhow::{bail, Result};
use clap::Subcommand;
use magic_core::rtm::prosail::{self, Prosail};
use magic_core::rtm::{INPUT_NAMES, N_BANDS, N_INPUTS, S2_BANDS};
use std::path::{Path, PathBuf};

/// `magic forward`.
#[derive(Subcommand, Clone, Debug)]
pub enum ForwardCmd {
    /// Mogi displacements (mm) at the network's stations for rows of
    /// `xcen_km, ycen_km, d_km, dV_1e6m3`.
    Mogi {
        /// Input CSV.
        #[arg(long)]
        input: PathBuf,
        /// Output CSV (`ux_<STA>` ×S, `uy_<STA>` ×S, `uz_<STA>` ×S; `sample_id` first when the
        /// input has one).
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
        /// Geometry mode.
        #[arg(long, value_enum, default_value = "reference")]
        geometry: GeometryArg,
        /// Tables folder (default: `$MAGIC_DATA/rtm` or `../shared/data/rtm`).
        #[arg(long)]
        tables: Option<PathBuf>,
    },
    /// PROSAIL (PROSPECT-D leaves in one 4SAIL layer over a soil): the four reflectance factors
    /// in the 13 Sentinel-2 bands for rows of its 14 inputs (columns named as in
    /// `oracle/sail_4sail_s2_1k.csv`: `N, cab, car, anth, cbrown, cw, cm, lai, ala, hspot, tts,
    /// tto, psi, psoil`; angles in degrees).
    Prosail {
        /// Input CSV.
        #[arg(long)]
        input: PathBuf,
        /// Output CSV (`rsot_B01` … `rddt_B12`: factor by factor, band by band; `sample_id`
        /// first when the input has one).
        #[arg(long)]
        output: PathBuf,
        /// Tables folder (default: `$MAGIC_DATA/rtm` or `../shared/data/rtm`).
        #[arg(long)]
        tables: Option<PathBuf>,
    },
}

/// Evaluates `f` on every row of `input` (its numeric columns `cols`), writing `header` then one
/// line per row (values, or NaN where `f` fails); fails at the end when any row failed.
fn rows(
    input: &Path,
    output: &Path,
    cols: &[&str],
    header: &[String],
    f: &dyn Fn(&[f64]) -> Result<Vec<f64>>,
) -> Result<()> {
    let t = Table::read_lenient(input, b',')?;
    let idx: Vec<usize> = cols.iter().map(|c| t.col(c)).collect::<Result<_>>()?;
    let id = t.col("sample_id").ok();
    let mut text = String::new();
    if id.is_some() {
        text.push_str("sample_id,");
    }
    text.push_str(&header.join(","));
    text.push('\n');
    let mut errors = 0;
    for r in 0..t.rows.len() {
        if let Some(c) = id {
            text.push_str(t.text(r, c));
            text.push(',');
        }
        let values = match &t.malformed[r] {
            Some(m) => Err(anyhow::anyhow!("{m}")),
            None => idx
                .iter()
                .map(|&c| t.num(r, c, false))
                .collect::<Result<Vec<f64>>>()
                .and_then(|x| f(&x).map_err(|e| anyhow::anyhow!("{}:{}: {e}", t.path, t.line(r)))),
        };
        match values {
            Ok(y) => {
                let v: Vec<String> = y.iter().map(|v| format!("{v:e}")).collect();
                text.push_str(&v.join(","));
            }
            Err(e) => {
                eprintln!("error: {e}");
                errors += 1;
                text.push_str(&vec!["NaN"; header.len()].join(","));
            }
        }
        text.push('\n');
    }
    write_file(output, text)?;
    eprintln!("{} rows -> {}", t.rows.len(), output.display());
    if errors > 0 {
        bail!(
            "{errors} of {} rows could not be evaluated (NaN rows written)",
            t.rows.len()
        );
    }
    Ok(())
}

/// Runs `magic forward`.
pub fn run(cmd: &ForwardCmd) -> Result<()> {
    match cmd {
        ForwardCmd::Mogi {
            input,
            output,
            stations,
        } => {
            let net = match stations {
                Some(p) => Network::read_json(p, None)?,
                None => Network::akutan(),
            };
            rows(
                input,
                output,
                &["xcen_km", "ycen_km", "d_km", "dV_1e6m3"],
                &net.channel_names(),
                &|p| {
                    let mut out = vec![0f64; 3 * net.len()];
                    magic_core::mogi::field(&net.stations, &[p[0], p[1], p[2], p[3]], &mut out)?;
                    Ok(out)
                },
            )
        }
        ForwardCmd::Rtm {
            input,
            output,
            geometry,
            tables,
        } => {
            let dir = crate::data::require(tables.as_deref(), "rtm", "RTM tables", "--tables")?;
            let t = RtmTables::read(&dir)?;
            let model = t.inform()?;
            let g = (*geometry).into();
            let header: Vec<String> = S2_BANDS.iter().map(|s| s.to_string()).collect();
            rows(input, output, &INPUT_NAMES, &header, &|x| {
                let x: [f64; N_INPUTS] = x.try_into().map_err(|_| anyhow::anyhow!("inputs"))?;
                let y = model.forward(&x, g)?;
                Ok(y[..N_BANDS].to_vec())
            })
        }
        ForwardCmd::Prosail {
            input,
            output,
            tables,
        } => {
            let dir = crate::data::require(tables.as_deref(), "rtm", "RTM tables", "--tables")?;
            let t = RtmTables::read(&dir)?;
            let core = t.tables();
            let model = Prosail::new(&core)?;
            let header: Vec<String> = prosail::FACTOR_NAMES
                .iter()
                .flat_map(|f| S2_BANDS.iter().map(move |b| format!("{f}_{b}")))
                .collect();
            rows(input, output, &prosail::INPUT_NAMES, &header, &|x| {
                let x: [f64; prosail::N_INPUTS] =
                    x.try_into().map_err(|_| anyhow::anyhow!("inputs"))?;
                Ok(model.forward(&x)?.iter().flatten().copied().collect())
            })
        }
    }
}
