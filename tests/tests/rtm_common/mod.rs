//! Shared by the `rtm_*` oracle tests: the spectral tables and the oracle files of
//! `shared/data` (std only: a small CSV reader), and points of the learned box.
#![allow(dead_code)]
// Index loops over several parallel arrays read more plainly here.
#![allow(clippy::needless_range_loop)]

use magic_core::rtm::prospect::Coefficients;
use magic_core::rtm::{Tables, LEARNED_BOUNDS, N_INPUTS, N_LEARNED};
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::OnceLock;

/// A CSV file: header and rows of raw fields.
pub struct Csv {
    pub rows: Vec<Vec<String>>,
    pub index: HashMap<String, usize>,
}

impl Csv {
    pub fn read(path: PathBuf) -> Csv {
        let text =
            std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let mut lines = text.lines().filter(|l| !l.trim().is_empty());
        let header: Vec<String> = lines
            .next()
            .expect("header")
            .split(',')
            .map(|s| s.trim().to_string())
            .collect();
        let rows: Vec<Vec<String>> = lines
            .map(|l| l.split(',').map(|s| s.trim().to_string()).collect())
            .collect();
        let index = header
            .iter()
            .enumerate()
            .map(|(i, h)| (h.clone(), i))
            .collect();
        Csv { rows, index }
    }
    pub fn col(&self, name: &str) -> usize {
        *self
            .index
            .get(name)
            .unwrap_or_else(|| panic!("no column {name}"))
    }
    pub fn f(&self, row: usize, name: &str) -> f64 {
        self.rows[row][self.col(name)].parse().unwrap()
    }
    pub fn column(&self, name: &str) -> Vec<f64> {
        let c = self.col(name);
        self.rows.iter().map(|r| r[c].parse().unwrap()).collect()
    }
    pub fn s(&self, row: usize, name: &str) -> &str {
        &self.rows[row][self.col(name)]
    }
}

/// Owned copies of the tables, lent to the model as [`Tables`].
pub struct OwnedTables {
    pub cols: [Vec<f64>; 9],
    pub soil_dry: Vec<f64>,
    pub soil_wet: Vec<f64>,
    pub es: Vec<f64>,
    pub ed: Vec<f64>,
    pub beta: Vec<f64>,
    pub resampling: Vec<f64>,
}

impl OwnedTables {
    pub fn load(dir: &std::path::Path) -> OwnedTables {
        let p = Csv::read(dir.join("rtm/prospect_d_coefficients.csv"));
        let cols = [
            "nr", "k_cab", "k_car", "k_anth", "k_brown", "k_cw", "k_cm", "t12", "tav90n",
        ]
        .map(|c| p.column(c));
        let soil = Csv::read(dir.join("rtm/soil_spectra.csv"));
        let sun = Csv::read(dir.join("rtm/solar_spectra.csv"));
        let lidf = Csv::read(dir.join("rtm/lidf_tables.csv"));
        let mut beta = Vec::new();
        for r in 0..lidf.rows.len() {
            for k in 0..6 {
                beta.push(lidf.f(r, &format!("beta_{k}")));
            }
        }
        let m = Csv::read(dir.join("rtm/sentinel2_full_resampling_matrix.csv"));
        let mut resampling = Vec::new();
        for r in 0..m.rows.len() {
            for b in magic_core::rtm::S2_BANDS {
                resampling.push(m.f(r, b));
            }
        }
        OwnedTables {
            cols,
            soil_dry: soil.column("Rsoil1_dry"),
            soil_wet: soil.column("Rsoil2_wet"),
            es: sun.column("Es_direct"),
            ed: sun.column("Ed_diffuse"),
            beta,
            resampling,
        }
    }
    pub fn coefficients(&self) -> Coefficients<'_> {
        let c = &self.cols;
        Coefficients::from_columns(c)
    }
    pub fn tables(&self) -> Tables<'_> {
        Tables {
            prospect: self.coefficients(),
            soil_dry: &self.soil_dry,
            soil_wet: &self.soil_wet,
            es: &self.es,
            ed: &self.ed,
            lidf_beta: &self.beta,
            resampling: &self.resampling,
        }
    }
}

pub struct Data {
    pub dir: PathBuf,
    pub tables: OwnedTables,
}

/// The tables and the oracle outputs (a test failure, saying what to set, without them).
pub fn data() -> &'static Data {
    static DATA: OnceLock<Data> = OnceLock::new();
    DATA.get_or_init(|| {
        let dir = magic_tests::data_with(&["rtm/prospect_d_coefficients.csv", "oracle"]);
        let tables = OwnedTables::load(&dir);
        Data { dir, tables }
    })
}

pub const INPUT_COLS: [&str; N_INPUTS] = [
    "N", "cab", "car", "anth", "cbrown", "cw", "cm", "cp", "cbc", "LAI", "typeLIDF", "LIDF",
    "hspot", "psoil", "tts", "tto", "psi", "LAIu", "cd", "sd", "h",
];

pub fn inputs(csv: &Csv, r: usize) -> [f64; N_INPUTS] {
    let mut x = [0.0; N_INPUTS];
    for (k, name) in INPUT_COLS.iter().enumerate() {
        x[k] = csv.f(r, name);
    }
    x
}

pub fn to_f32(x: &[f64; N_INPUTS]) -> [f32; N_INPUTS] {
    let mut y = [0.0f32; N_INPUTS];
    for (a, b) in y.iter_mut().zip(x) {
        *a = *b as f32;
    }
    y
}

/// The learned variables at unit-cube coordinates `u` over the paper's bounds.
pub fn box_point(u: &[f64; N_LEARNED]) -> [f64; N_LEARNED] {
    let mut z = [0.0; N_LEARNED];
    for i in 0..N_LEARNED {
        z[i] = LEARNED_BOUNDS[i][0] + u[i] * (LEARNED_BOUNDS[i][1] - LEARNED_BOUNDS[i][0]);
    }
    z
}
