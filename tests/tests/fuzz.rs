//! Fuzzing on stable Rust: no panic, no hang, on any model file or observation.
//!
//! Three targets, each a plain test:
//! * `fuzz_model_decode` — `Model::decode` on mutated valid model files (bit flips, byte sets,
//!   truncations, insertions, deletions, splices, header edits; most resealed with a correct CRC so
//!   the structural checks behind it are reached) and on random bytes; every model that decodes
//!   is re-encoded and inverted (`f32` and `f64`) on a few observation vectors.
//! * `fuzz_invert_observations` — `invert` on arbitrary bytes read as `f32` (NaN, ±inf,
//!   subnormals, huge values) of random length, on int8 and f32 models of variants A, B and C.
//! * `fuzz_parse_obs` — `magic_core::line::parse_obs` on arbitrary byte strings (lossy UTF-8)
//!   and on near-valid lines; lines that parse are inverted, as the firmware does.
//!
//! `MAGIC_FUZZ_CASES` is the total number of cases (default 20 000: half for model decoding, a
//! quarter for each of the others); `MAGIC_FUZZ_SEED` seeds the generator (default fixed), and
//! `MAGIC_FUZZ_ONLY=<case>` reruns one case. Case `i` is generated from (seed, target, i) alone, so
//! a failure report (seed, case and input in hex) reproduces exactly. A panic is caught with
//! `catch_unwind` and reported with its input before the test fails; a case that runs longer than
//! `MAGIC_FUZZ_CASE_SECS` (default 10 s, 300 times the slowest case measured, 32 ms) is reported
//! as a hang: a watchdog against non-termination, not a speed requirement (the run's rate and
//! slowest case are printed).
//!
//! The long run: `MAGIC_FUZZ_CASES=1000000 cargo test --release -p magic-tests --test fuzz -- --nocapture`.

use magic_core::line::parse_obs;
use magic_core::model_file::{Model, MAGIC, VERSION};
use magic_core::{invert, Variant, Workspace};
use magic_tests::{random_mogi_model, reseal};
use magic_train::gnss::synth;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{mpsc, Arc, OnceLock};
use std::time::{Duration, Instant};

// ---------------------------------------------------------------------------------------------
// Generator and harness

/// SplitMix64: tiny, fast, deterministic.
#[derive(Clone)]
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        magic_tests::splitmix64(&mut self.0)
    }
    fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            (self.next() % n as u64) as usize
        }
    }
    fn chance(&mut self, num: u64, den: u64) -> bool {
        self.next() % den < num
    }
    fn byte(&mut self) -> u8 {
        self.next() as u8
    }
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// An "interesting" f32: any bit pattern, a special value, or a plausible observation.
    fn f32(&mut self) -> f32 {
        const SPECIAL: [f32; 16] = [
            0.0,
            -0.0,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MIN_POSITIVE,
            1.0e-45,
            -1.0e-45,
            f32::MAX,
            f32::MIN,
            1.0e4,
            -1.0e4,
            10_000.001,
            9_999.999,
            1.0e30,
            f32::EPSILON,
        ];
        match self.below(4) {
            0 => f32::from_bits(self.next() as u32),
            1 => SPECIAL[self.below(SPECIAL.len())],
            _ => ((self.unit() * 2.0 - 1.0) * [1.0, 30.0, 300.0, 1.0e4][self.below(4)]) as f32,
        }
    }
    fn hash(bytes: &[u8]) -> Rng {
        // FNV-1a over the input: checks derive their extra randomness from the input alone.
        let mut h = 0xcbf2_9ce4_8422_2325u64;
        for b in bytes {
            h = (h ^ *b as u64).wrapping_mul(0x0000_0100_0000_01B3);
        }
        Rng(h)
    }
}

fn env_u64(name: &str, default: u64) -> u64 {
    match std::env::var(name) {
        Ok(v) => v
            .trim()
            .parse()
            .unwrap_or_else(|_| panic!("{name}={v}: expected an integer")),
        Err(_) => default,
    }
}

fn total_cases() -> u64 {
    env_u64("MAGIC_FUZZ_CASES", 20_000)
}

fn seed() -> u64 {
    env_u64("MAGIC_FUZZ_SEED", 0x6D61_6769_6321)
}

fn case_rng(target: u64, case: u64) -> Rng {
    let mut r = Rng(seed() ^ target.wrapping_mul(0xA076_1D64_78BD_642F));
    let base = r.next();
    Rng(base ^ case.wrapping_mul(0xE703_7ED1_A0B4_28DB))
}

fn hex(bytes: &[u8]) -> String {
    const MAX: usize = 4096;
    let mut s: String = bytes.iter().take(MAX).map(|b| format!("{b:02x}")).collect();
    if bytes.len() > MAX {
        s.push_str(&format!("… ({} bytes in all)", bytes.len()));
    }
    s
}

type Gen = Arc<dyn Fn(&mut Rng) -> Vec<u8> + Send + Sync>;
type Check = Arc<dyn Fn(&[u8]) + Send + Sync>;

/// Saves a failing input next to the report and returns where.
fn save(name: &str, case: u64, input: &[u8]) -> String {
    let p = std::env::temp_dir().join(format!("magic-fuzz-{name}-seed{}-case{case}.bin", seed()));
    match std::fs::write(&p, input) {
        Ok(()) => p.display().to_string(),
        Err(e) => format!("(could not save: {e})"),
    }
}

/// Runs `cases` cases of a target on a worker thread, watched for hangs; panics (failing the
/// test) with the failing input on the first panic or hang.
fn run(name: &'static str, target: u64, cases: u64, gen: Gen, check: Check) {
    let only = std::env::var("MAGIC_FUZZ_ONLY")
        .ok()
        .map(|v| v.parse::<u64>().expect("MAGIC_FUZZ_ONLY: a case number"));
    let case_limit = Duration::from_secs(env_u64("MAGIC_FUZZ_CASE_SECS", 10));
    let progress = Arc::new(AtomicU64::new(0));
    let (tx, rx) = mpsc::channel::<Result<(u64, f64), (u64, Vec<u8>)>>();
    let (g, c, p) = (gen.clone(), check.clone(), progress.clone());
    let start = Instant::now();
    std::thread::Builder::new()
        .name(format!("fuzz-{name}"))
        .spawn(move || {
            let range = match only {
                Some(i) => i..i + 1,
                None => 0..cases,
            };
            let mut slowest = 0f64;
            for i in range {
                p.store(i, Ordering::Relaxed);
                let input = g(&mut case_rng(target, i));
                let t = Instant::now();
                if catch_unwind(AssertUnwindSafe(|| c(&input))).is_err() {
                    let _ = tx.send(Err((i, input)));
                    return;
                }
                slowest = slowest.max(t.elapsed().as_secs_f64());
            }
            let _ = tx.send(Ok((cases, slowest)));
        })
        .expect("spawn");
    let mut last = (u64::MAX, Instant::now());
    loop {
        match rx.recv_timeout(Duration::from_millis(200)) {
            Ok(Ok((n, slowest))) => {
                let secs = start.elapsed().as_secs_f64();
                let n = if only.is_some() { 1 } else { n };
                eprintln!(
                    "fuzz {name}: {n} cases in {secs:.2} s ({:.0} cases/s, slowest case {:.2} ms), MAGIC_FUZZ_SEED={}: no panic, no hang",
                    n as f64 / secs.max(1e-9),
                    slowest * 1e3,
                    seed()
                );
                return;
            }
            Ok(Err((i, input))) => {
                let at = save(name, i, &input);
                panic!(
                    "fuzz {name}: case {i} panicked (MAGIC_FUZZ_SEED={} MAGIC_FUZZ_ONLY={i}); input ({} bytes, saved to {at}):\n{}",
                    seed(),
                    input.len(),
                    hex(&input)
                );
            }
            Err(mpsc::RecvTimeoutError::Timeout) => {
                let i = progress.load(Ordering::Relaxed);
                if i != last.0 {
                    last = (i, Instant::now());
                } else if last.1.elapsed() > case_limit {
                    let input = gen(&mut case_rng(target, i));
                    let at = save(name, i, &input);
                    panic!(
                        "fuzz {name}: case {i} still running after {case_limit:?} (MAGIC_FUZZ_SEED={} MAGIC_FUZZ_ONLY={i}); input ({} bytes, saved to {at}):\n{}",
                        seed(),
                        input.len(),
                        hex(&input)
                    );
                }
            }
            Err(mpsc::RecvTimeoutError::Disconnected) => {
                panic!("fuzz {name}: worker ended without a result")
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Models

struct Models {
    /// Valid model files to mutate (int8 C first).
    files: Vec<Vec<u8>>,
    /// Decoded models for the observation targets (bytes leaked: they live for the whole run).
    decoded: Vec<Model<'static>>,
}

fn models() -> &'static Models {
    static M: OnceLock<Models> = OnceLock::new();
    M.get_or_init(|| {
        let calib = synth::generate(synth::Scenario::Clean, 5)
            .problem
            .data
            .train
            .x[..200]
            .to_vec();
        let c = random_mogi_model(Variant::C, 5);
        let files = vec![
            c.quantize_int8(&calib).unwrap().encode().unwrap(),
            c.encode().unwrap(),
            random_mogi_model(Variant::B, 6)
                .quantize_int8(&calib)
                .unwrap()
                .encode()
                .unwrap(),
            random_mogi_model(Variant::A, 7).encode().unwrap(),
        ];
        let decoded = files
            .iter()
            .map(|f| {
                let b: &'static [u8] = Box::leak(f.clone().into_boxed_slice());
                Model::decode(b).expect("valid model")
            })
            .collect();
        Models { files, decoded }
    })
}

/// A mutated model file: one case in 16 random bytes (half behind a valid header), otherwise
/// one of the valid files with 1 to 6 edits, most resealed.
fn mutate_model(r: &mut Rng) -> Vec<u8> {
    let m = models();
    if r.chance(1, 16) {
        return random_file(r);
    }
    // Three cases in four mutate the int8 C model, the rest any of the four.
    let pool = if r.chance(3, 4) { 1 } else { m.files.len() };
    let src = r.below(pool);
    let mut b = m.files[src].clone();
    let mut structural = false;
    for _ in 0..1 + r.below(6) {
        structural |= edit(r, &mut b, &m.files);
    }
    // Most cases get a valid CRC (and usually a consistent length) so decoding goes deeper.
    if r.chance(7, 8) {
        reseal(&mut b, structural && r.chance(7, 8));
    }
    b
}

/// Random bytes, half of them behind a valid header.
fn random_file(r: &mut Rng) -> Vec<u8> {
    let max = if r.chance(1, 2) { 64 } else { 4096 };
    let n = r.below(max);
    let mut b: Vec<u8> = (0..n).map(|_| r.byte()).collect();
    if r.chance(1, 2) {
        let mut h = MAGIC.to_vec();
        h.extend(VERSION.to_le_bytes());
        h.extend((n as u32).to_le_bytes());
        h.extend(b);
        b = h;
        b.extend([0; 4]);
        reseal(&mut b, false);
    }
    b
}

/// One random edit of `b` (bit flip, byte set, truncation, splice from `files`, insertion,
/// deletion, extreme word, header byte); whether it changed the length.
fn edit(r: &mut Rng, b: &mut Vec<u8>, files: &[Vec<u8>]) -> bool {
    let mut structural = false;
    let n = b.len();
    match r.below(10) {
        0 | 1 => {
            let i = r.below(n.max(1));
            if let Some(x) = b.get_mut(i) {
                *x ^= 1 << r.below(8);
            }
        }
        2 | 3 => {
            const SET: [u8; 8] = [0, 1, 0x7F, 0x80, 0xFF, 0xFE, 0x40, 0x3F];
            let i = r.below(n.max(1));
            let v = if r.chance(1, 2) {
                SET[r.below(8)]
            } else {
                r.byte()
            };
            if let Some(x) = b.get_mut(i) {
                *x = v;
            }
        }
        4 => {
            b.truncate(r.below(n + 1));
            structural = true;
        }
        5 => {
            // Splice a chunk of another (or the same) model file over or into this one.
            let other = &files[r.below(files.len())];
            let a = r.below(other.len());
            let len = r.below(64.min(other.len() - a) + 1);
            let chunk = other[a..a + len].to_vec();
            let at = r.below(n + 1);
            if r.chance(1, 2) {
                b.splice(at..at, chunk);
                structural = true;
            } else {
                for (k, c) in chunk.into_iter().enumerate() {
                    if let Some(x) = b.get_mut(at + k) {
                        *x = c;
                    }
                }
            }
        }
        6 => {
            let at = r.below(n + 1);
            let ins: Vec<u8> = (0..1 + r.below(16)).map(|_| r.byte()).collect();
            b.splice(at..at, ins);
            structural = true;
        }
        7 => {
            let at = r.below(n + 1);
            let end = (at + 1 + r.below(16)).min(n);
            b.drain(at..end);
            structural = true;
        }
        8 => {
            // A little-endian word (a length, a count, a float) set to something extreme.
            const WORDS: [u32; 8] = [
                0,
                1,
                0xFFFF_FFFF,
                0x7FFF_FFFF,
                0x8000_0000,
                0x7F80_0000,
                0x7FC0_0000,
                0x0000_0001,
            ];
            let w = if r.chance(1, 2) {
                WORDS[r.below(8)]
            } else {
                r.next() as u32
            };
            let at = r.below(n.max(4) - 3);
            for (k, x) in w.to_le_bytes().into_iter().enumerate() {
                if let Some(y) = b.get_mut(at + k) {
                    *y = x;
                }
            }
        }
        _ => {
            // The header: version or body length.
            if n >= 10 {
                let i = 4 + r.below(6);
                b[i] = if r.chance(1, 2) {
                    r.byte()
                } else {
                    b[i].wrapping_add(1)
                };
            }
        }
    }
    structural
}

/// A few observation vectors for a model, derived from the input bytes.
fn observations(n_obs: usize, seed_from: &[u8]) -> Vec<Vec<f32>> {
    let mut r = Rng::hash(&seed_from[..seed_from.len().min(256)]);
    let mut v = vec![
        vec![0.0; n_obs],
        vec![f32::NAN; n_obs],
        vec![0.0; n_obs.saturating_sub(1)],
    ];
    v.push(
        (0..n_obs)
            .map(|_| ((r.unit() * 2.0 - 1.0) * 50.0) as f32)
            .collect(),
    );
    v.push((0..n_obs).map(|_| r.f32()).collect());
    let mut holes: Vec<f32> = (0..n_obs)
        .map(|_| ((r.unit() * 2.0 - 1.0) * 1.0e4) as f32)
        .collect();
    for x in holes.iter_mut() {
        if r.chance(1, 3) {
            *x = f32::NAN;
        }
    }
    v.push(holes);
    v
}

fn exercise(m: &Model<'_>, input: &[u8]) {
    let mut ws = Workspace::default();
    for obs in observations(m.n_obs(), input) {
        let _ = invert::<f32>(m, &obs, &mut ws);
        let _ = invert::<f64>(m, &obs, &mut ws);
    }
}

// ---------------------------------------------------------------------------------------------
// Targets

#[test]
fn fuzz_model_decode() {
    let n = total_cases() / 2;
    let decoded = Arc::new(AtomicU64::new(0));
    let count = decoded.clone();
    let check: Check = Arc::new(move |bytes: &[u8]| {
        if let Ok(m) = Model::decode(bytes) {
            count.fetch_add(1, Ordering::Relaxed);
            // A model that decodes re-encodes to bytes that decode to the same encoding.
            let mut buf = vec![0u8; bytes.len() + 64];
            let len = m.encode(&mut buf).expect("a decoded model re-encodes");
            let again = Model::decode(&buf[..len]).expect("a re-encoded model decodes");
            let mut buf2 = vec![0u8; len + 64];
            let len2 = again.encode(&mut buf2).expect("re-encodes twice");
            assert_eq!(&buf[..len], &buf2[..len2], "encoding is stable");
            exercise(&m, bytes);
        }
    });
    models();
    run("model_decode", 1, n, Arc::new(mutate_model), check);
    eprintln!(
        "fuzz model_decode: {} of the mutated files decoded and were inverted",
        decoded.load(Ordering::Relaxed)
    );
}

fn gen_observations(r: &mut Rng) -> Vec<u8> {
    let sel = r.byte();
    let len = if r.chance(3, 4) { 36 } else { r.below(100) };
    let mut b = vec![sel];
    let mode = r.below(4);
    for _ in 0..len {
        let x = match mode {
            0 => f32::from_bits(r.next() as u32),
            1 => ((r.unit() * 2.0 - 1.0) * 40.0) as f32,
            _ => r.f32(),
        };
        b.extend(x.to_le_bytes());
    }
    // Sometimes a stray byte: lengths that are not whole f32s.
    if r.chance(1, 16) {
        b.push(r.byte());
    }
    b
}

#[test]
fn fuzz_invert_observations() {
    let n = total_cases() / 4;
    let accepted = Arc::new(AtomicU64::new(0));
    let count = accepted.clone();
    let check: Check = Arc::new(move |bytes: &[u8]| {
        let ms = &models().decoded;
        let Some((&sel, rest)) = bytes.split_first() else {
            return;
        };
        let m = &ms[sel as usize % ms.len()];
        let obs: Vec<f32> = rest
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        let mut ws = Workspace::default();
        let valid = obs.len() == m.n_obs() && obs.iter().all(|x| x.is_nan() || x.abs() <= 1.0e4);
        let r32 = invert::<f32>(m, &obs, &mut ws);
        let r64 = invert::<f64>(m, &obs, &mut ws);
        if let Ok(inv) = &r64 {
            count.fetch_add(1, Ordering::Relaxed);
            assert!(valid, "accepted an invalid observation vector");
            assert!(
                inv.residual_rms.is_finite(),
                "residual {}",
                inv.residual_rms
            );
            assert!(inv.params[..inv.n_params].iter().all(|p| p.is_finite()));
        }
        if let Ok(inv) = &r32 {
            assert!(inv.params[..inv.n_params].iter().all(|p| p.is_finite()));
        }
        assert_eq!(
            r32.is_ok(),
            r64.is_ok(),
            "f32 and f64 accept the same inputs"
        );
    });
    models();
    run("invert", 2, n, Arc::new(gen_observations), check);
    eprintln!(
        "fuzz invert: {} of the observation vectors were accepted and inverted",
        accepted.load(Ordering::Relaxed)
    );
}

fn gen_line(r: &mut Rng) -> Vec<u8> {
    let sel = r.byte();
    let mut b = vec![sel];
    if r.chance(1, 4) {
        b.extend((0..r.below(300)).map(|_| r.byte()));
        return b;
    }
    const ODD: [&str; 24] = [
        "",
        " ",
        "nan",
        "NaN",
        "-nan",
        "inf",
        "-inf",
        "infinity",
        "1e39",
        "-1e39",
        "1e4",
        "10000.0001",
        "+5",
        "-0",
        " 3 ",
        "0x10",
        "1_000",
        "1,5",
        "é",
        "\u{0}",
        "1e-50",
        ".",
        "-",
        "9999.9999999999999",
    ];
    // Mostly the field count the check expects, with a per-line rate of odd fields.
    let expected = if sel < 128 { 36 } else { (sel % 100) as usize };
    let fields = if r.chance(3, 4) {
        expected
    } else {
        r.below(40)
    };
    let odd = [0u64, 1, 10, 50][r.below(4)];
    for k in 0..fields {
        if k > 0 {
            b.push(match r.below(200) {
                0 => b';',
                1 => b'\t',
                2 => b'\n',
                _ => b',',
            });
        }
        let s = if r.chance(odd, 100) {
            match r.below(3) {
                0 => ODD[r.below(ODD.len())].to_string(),
                1 => format!("{:e}", r.f32()),
                _ => format!("{}", r.f32()),
            }
        } else {
            match r.below(10) {
                0 => String::new(),
                1 => " NaN ".to_string(),
                2 => format!("{:e}", ((r.unit() * 2.0 - 1.0) * 1.0e4) as f32),
                _ => format!("{:.3}", (r.unit() * 2.0 - 1.0) * 300.0),
            }
        };
        b.extend(s.as_bytes());
    }
    if r.chance(1, 4) {
        b.extend(b"\r\n");
    }
    b
}

#[test]
fn fuzz_parse_obs() {
    let n = total_cases() - total_cases() / 2 - total_cases() / 4;
    let parsed = Arc::new(AtomicU64::new(0));
    let count = parsed.clone();
    let check: Check = Arc::new(move |bytes: &[u8]| {
        let Some((&sel, rest)) = bytes.split_first() else {
            return;
        };
        let line = String::from_utf8_lossy(rest);
        let mut out = vec![0f32; if sel < 128 { 36 } else { (sel % 100) as usize }];
        if parse_obs(&line, &mut out).is_ok() {
            count.fetch_add(1, Ordering::Relaxed);
            assert!(
                out.iter().all(|x| x.is_nan() || x.abs() <= 1.0e4),
                "parsed beyond 10 m: {out:?}"
            );
            let ms = &models().decoded;
            let m = &ms[sel as usize % ms.len()];
            let _ = invert::<f32>(m, &out, &mut Workspace::default());
        }
    });
    models();
    run("parse_obs", 3, n, Arc::new(gen_line), check);
    eprintln!(
        "fuzz parse_obs: {} of the lines parsed and were inverted",
        parsed.load(Ordering::Relaxed)
    );
}
