//! INFORM / 4SAIL / PROSPECT-D held to the reference outputs in `shared/data/oracle`, the exact
//! Jacobian held to central differences, and physical invariants checked with proptest.
//!
//! Data are found through `MAGIC_DATA` or `../shared/data` next to the workspace; without them the
//! tests print a notice and pass.

use magic_core::rtm::inform::Geometry;
use magic_core::rtm::prospect::{leaf_optics, Coefficients, Leaf};
use magic_core::rtm::sail::{
    extinction, layer, medium, sail, CampbellBins, HotspotRule, Lidf, SunView,
};
use magic_core::rtm::sensor::Resampling;
use magic_core::rtm::{
    inputs_from_learned, Fixed, Inform, Tables, LEARNED_BOUNDS, N_BANDS, N_INPUTS, N_LEARNED,
};
use magic_core::Error;
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::OnceLock;

// ---------------------------------------------------------------------------------------------
// Data loading (std only)

fn data_dir() -> Option<PathBuf> {
    let dir = match std::env::var_os("MAGIC_DATA") {
        Some(d) => PathBuf::from(d),
        None => PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/data")),
    };
    if dir.join("rtm/prospect_d_coefficients.csv").exists() {
        Some(dir)
    } else {
        eprintln!(
            "notice: RTM data not found at {} (set MAGIC_DATA); skipping",
            dir.display()
        );
        None
    }
}

/// A CSV file: header and rows of raw fields.
struct Csv {
    rows: Vec<Vec<String>>,
    index: HashMap<String, usize>,
}

impl Csv {
    fn read(path: PathBuf) -> Csv {
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
    fn col(&self, name: &str) -> usize {
        *self
            .index
            .get(name)
            .unwrap_or_else(|| panic!("no column {name}"))
    }
    fn f(&self, row: usize, name: &str) -> f64 {
        self.rows[row][self.col(name)].parse().unwrap()
    }
    fn column(&self, name: &str) -> Vec<f64> {
        let c = self.col(name);
        self.rows.iter().map(|r| r[c].parse().unwrap()).collect()
    }
    fn s(&self, row: usize, name: &str) -> &str {
        &self.rows[row][self.col(name)]
    }
}

/// Owned copies of the tables, lent to the model as [`Tables`].
struct OwnedTables {
    cols: Vec<Vec<f64>>, // 9 prospect columns
    soil_dry: Vec<f64>,
    soil_wet: Vec<f64>,
    es: Vec<f64>,
    ed: Vec<f64>,
    beta: Vec<f64>,
    resampling: Vec<f64>,
}

impl OwnedTables {
    fn load(dir: &std::path::Path) -> OwnedTables {
        let p = Csv::read(dir.join("rtm/prospect_d_coefficients.csv"));
        let cols = [
            "nr", "k_cab", "k_car", "k_anth", "k_brown", "k_cw", "k_cm", "t12", "tav90n",
        ]
        .iter()
        .map(|c| p.column(c))
        .collect();
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
    fn coefficients(&self) -> Coefficients<'_> {
        let c = &self.cols;
        Coefficients {
            nr: &c[0],
            k_cab: &c[1],
            k_car: &c[2],
            k_anth: &c[3],
            k_brown: &c[4],
            k_cw: &c[5],
            k_cm: &c[6],
            t12: &c[7],
            tav90n: &c[8],
        }
    }
    fn tables(&self) -> Tables<'_> {
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

struct Data {
    dir: PathBuf,
    tables: OwnedTables,
}

fn data() -> Option<&'static Data> {
    static DATA: OnceLock<Option<Data>> = OnceLock::new();
    DATA.get_or_init(|| {
        let dir = data_dir()?;
        let tables = OwnedTables::load(&dir);
        Some(Data { dir, tables })
    })
    .as_ref()
}

const INPUT_COLS: [&str; N_INPUTS] = [
    "N", "cab", "car", "anth", "cbrown", "cw", "cm", "cp", "cbc", "LAI", "typeLIDF", "LIDF",
    "hspot", "psoil", "tts", "tto", "psi", "LAIu", "cd", "sd", "h",
];

fn inputs(csv: &Csv, r: usize) -> [f64; N_INPUTS] {
    let mut x = [0.0; N_INPUTS];
    for (k, name) in INPUT_COLS.iter().enumerate() {
        x[k] = csv.f(r, name);
    }
    x
}

fn to_f32(x: &[f64; N_INPUTS]) -> [f32; N_INPUTS] {
    let mut y = [0.0f32; N_INPUTS];
    for (a, b) in y.iter_mut().zip(x) {
        *a = *b as f32;
    }
    y
}

// ---------------------------------------------------------------------------------------------
// Reference geometry against the INFORM oracles

fn check_bands_file(file: &str) {
    let Some(d) = data() else { return };
    let model = Inform::new(d.tables.tables()).unwrap();
    let csv = Csv::read(d.dir.join("oracle").join(file));
    let (mut e64, mut e32) = (0.0f64, 0.0f64);
    let (mut w64, mut w32) = (0usize, 0usize);
    for r in 0..csv.rows.len() {
        let x = inputs(&csv, r);
        let y64 = model.forward(&x, Geometry::Reference).unwrap();
        let y32 = model.forward(&to_f32(&x), Geometry::Reference).unwrap();
        for (b, name) in magic_core::rtm::S2_BANDS.iter().enumerate() {
            let want = csv.f(r, name);
            let d64 = (y64[b] - want).abs();
            let d32 = (y32[b] as f64 - want).abs();
            if d64 > e64 {
                e64 = d64;
                w64 = r;
            }
            if d32 > e32 {
                e32 = d32;
                w32 = r;
            }
        }
    }
    eprintln!(
        "{file}: {} rows, reference geometry: max |error| f64 {e64:.3e} (row {w64}), f32 {e32:.3e} (row {w32})",
        csv.rows.len()
    );
    assert!(e64 <= 1e-9, "{file}: f64 error {e64:e} at row {w64}");
    assert!(e32 <= 2e-5, "{file}: f32 error {e32:e} at row {w32}");
}

#[test]
fn reference_matches_inform_10k() {
    check_bands_file("rtm_inform_s2_10k.csv");
}

#[test]
fn reference_matches_inform_geometry_2k() {
    check_bands_file("rtm_inform_s2_geometry_2k.csv");
}

#[test]
fn reference_matches_stepwise() {
    let Some(d) = data() else { return };
    let model = Inform::new(d.tables.tables()).unwrap();
    let src = Csv::read(d.dir.join("oracle/rtm_inform_s2_10k.csv"));
    let pro = Csv::read(d.dir.join("oracle/rtm_stepwise_prospect.csv"));
    let sl = Csv::read(d.dir.join("oracle/rtm_stepwise_sail.csv"));
    let inf = Csv::read(d.dir.join("oracle/rtm_stepwise_inform.csv"));
    let s2 = Csv::read(d.dir.join("oracle/rtm_stepwise_s2.csv"));
    let n_wl = model.n_wavelengths();
    let names = [
        "leaf_refl",
        "leaf_trans",
        "r_understory",
        "r_crown_inf",
        "r_tts_trans",
        "r_tto_trans",
        "r_forest",
    ];
    let mut err = [0.0f64; 7];
    for k in 0..pro.rows.len() {
        let sample = pro.f(k, "sample_id") as usize;
        let wl = pro.f(k, "wavelength");
        let i = (wl - 400.0) as usize;
        assert!(i < n_wl);
        assert_eq!(sl.f(k, "wavelength"), wl);
        assert_eq!(inf.f(k, "wavelength"), wl);
        let x = inputs(&src, sample);
        let t = model.wavelength(&x, Geometry::Reference, i).unwrap();
        let got = [
            t.leaf.refl,
            t.leaf.trans,
            t.r_understory,
            t.r_crown_inf,
            t.t_s,
            t.t_o,
            t.r_forest,
        ];
        let want = [
            pro.f(k, "leaf_refl"),
            pro.f(k, "leaf_trans"),
            sl.f(k, "r_understory"),
            sl.f(k, "r_crown_inf"),
            sl.f(k, "r_tts_trans"),
            sl.f(k, "r_tto_trans"),
            inf.f(k, "r_forest"),
        ];
        for j in 0..7 {
            err[j] = err[j].max((got[j] - want[j]).abs());
        }
    }
    let mut e_s2 = 0.0f64;
    for r in 0..s2.rows.len() {
        let sample = s2.f(r, "sample_id") as usize;
        let y = model
            .forward(&inputs(&src, sample), Geometry::Reference)
            .unwrap();
        for (b, name) in magic_core::rtm::S2_BANDS.iter().enumerate() {
            e_s2 = e_s2.max((y[b] - s2.f(r, name)).abs());
        }
    }
    for j in 0..7 {
        eprintln!("stepwise {:<13} max |error| {:.3e}", names[j], err[j]);
    }
    eprintln!("stepwise s2 bands      max |error| {e_s2:.3e}");
    for j in 0..7 {
        assert!(err[j] <= 1e-9, "{}: {:e}", names[j], err[j]);
    }
    assert!(e_s2 <= 1e-9);
}

#[test]
fn reference_matches_stepwise_scalars() {
    let Some(d) = data() else { return };
    let model = Inform::new(d.tables.tables()).unwrap();
    let src = Csv::read(d.dir.join("oracle/rtm_inform_s2_10k.csv"));
    let sc = Csv::read(d.dir.join("oracle/rtm_stepwise_sail_scalars.csv"));
    let isc = Csv::read(d.dir.join("oracle/rtm_stepwise_inform_scalars.csv"));
    let mut err = 0.0f64;
    for r in 0..sc.rows.len() {
        let sample = sc.f(r, "sample_id") as usize;
        let scene = model
            .scene(&inputs(&src, sample), Geometry::Reference)
            .unwrap();
        let (e, l, skyl) = match sc.s(r, "call") {
            "understory" => (scene.ext, scene.understory, scene.skyl_s),
            "crown_inf" => (scene.ext, scene.crown_inf, scene.skyl_s),
            "tts_trans" => (scene.ext, scene.crown_s, scene.skyl_s),
            "tto_trans" => (scene.ext_o, scene.crown_o, scene.skyl_o),
            c => panic!("unknown call {c}"),
        };
        let pairs = [
            ("ks", e.ks),
            ("ko", e.ko),
            ("bf", e.bf),
            ("sob", e.sob),
            ("sof", e.sof),
            ("dso", e.dso),
            ("alf", l.alf),
            ("tss", l.tss),
            ("too", l.too),
            ("tsstoo", l.tsstoo),
            ("sumint", l.sumint),
            ("skyl", skyl),
        ];
        for (name, got) in pairs {
            let want = sc.f(r, name);
            let d = (got - want).abs();
            assert!(
                d <= 1e-9 * (1.0 + want.abs()),
                "sample {sample} {}: {name} {got} vs {want}",
                sc.s(r, "call")
            );
            err = err.max(d);
        }
    }
    for r in 0..isc.rows.len() {
        let sample = isc.f(r, "sample_id") as usize;
        let scene = model
            .scene(&inputs(&src, sample), Geometry::Reference)
            .unwrap();
        let c = scene.crown;
        let a = scene.inform_angles;
        let pairs = [
            ("inform_tts_arg", a[0]),
            ("inform_tto_arg", a[1]),
            ("inform_psi_arg", a[2]),
            ("k", c.k),
            ("co", c.co),
            ("cs", c.cs),
            ("g", c.g),
            ("p", c.p),
            ("Fcd", c.fcd),
            ("Fcs", c.fcs),
            ("Fod", c.fod),
            ("Fos", c.fos),
        ];
        for (name, got) in pairs {
            let want = isc.f(r, name);
            let d = (got - want).abs();
            assert!(d <= 1e-12, "sample {sample}: {name} {got} vs {want}");
            err = err.max(d);
        }
    }
    eprintln!("stepwise scalars (4SAIL calls, crown geometry) max |error| {err:.3e}");
}

// ---------------------------------------------------------------------------------------------
// Physical 4SAIL against the prosail package

#[test]
fn physical_sail_matches_prosail() {
    let Some(d) = data() else { return };
    let t = d.tables.tables();
    let coef = t.prospect;
    let n_wl = coef.len();
    let sensor = Resampling::new(t.resampling, n_wl, N_BANDS).unwrap();
    let csv = Csv::read(d.dir.join("oracle/sail_4sail_s2_1k.csv"));
    let factors = ["rsot", "rdot", "rsdt", "rddt"];
    // The file's `rdot_*` and `rddt_*` columns are swapped: prosail's `run_sail(...,
    // factor="ALL")` returns [rsot, rddt, rsdt, rdot] and the columns were labelled in the order
    // rsot, rdot, rsdt, rddt. Our rdot is the reference implementation's (held to the INFORM
    // oracle above), and the swapped columns agree with ours to round-off.
    let columns = ["rsot", "rddt", "rsdt", "rdot"];
    let mut err = [0.0f64; 4];
    let mut spectra = vec![vec![0.0f64; n_wl]; 4];
    for r in 0..csv.rows.len() {
        let f = |n: &str| csv.f(r, n);
        let leaf = Leaf {
            n: f("N"),
            cab: f("cab"),
            car: f("car"),
            anth: f("anth"),
            cbrown: f("cbrown"),
            cw: f("cw"),
            cm: f("cm"),
        };
        let lidf = Lidf::campbell(f("ala"), CampbellBins::Uniform18).unwrap();
        let g = SunView::from_degrees(f("tts"), f("tto"), f("psi"));
        let e = extinction(&g, &lidf);
        let l = layer(&e, f("lai"), f("hspot"), HotspotRule::Physical);
        let psoil = f("psoil");
        for i in 0..n_wl {
            let optics = leaf_optics(&coef.row(i).unwrap(), &leaf);
            let soil = psoil * t.soil_dry[i] + (1.0 - psoil) * t.soil_wet[i];
            let o = sail(&e, &l, &medium(e.bf, optics), soil);
            spectra[0][i] = o.rsot;
            spectra[1][i] = o.rdot;
            spectra[2][i] = o.rsdt;
            spectra[3][i] = o.rddt;
        }
        for k in 0..factors.len() {
            let mut bands = [0.0; N_BANDS];
            sensor.integrate_slice(&spectra[k], &mut bands).unwrap();
            for (b, band) in magic_core::rtm::S2_BANDS.iter().enumerate() {
                let want = csv.f(r, &format!("{}_{band}", columns[k]));
                err[k] = err[k].max((bands[b] - want).abs());
            }
        }
    }
    for k in 0..4 {
        eprintln!(
            "sail_4sail_s2_1k.csv physical 4SAIL {} (file column {}): max |error| {:.3e}",
            factors[k], columns[k], err[k]
        );
    }
    for k in 0..4 {
        assert!(err[k] <= 1e-6, "{}: {:e}", factors[k], err[k]);
    }
}
