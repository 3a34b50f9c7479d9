//! The deployable firmware (UART0, no semihosting) under QEMU, driven through `magic station`'s
//! protocol over QEMU's `-serial tcp:…`:
//!
//! * 10 000 days streamed in give 10 000 answers, with model updates in the middle of the stream
//!   (two good ones, a corrupt one, an oversized one, one of an unsupported format version, one
//!   cut off halfway by the next day, one abandoned until the board's timeout); every answer
//!   names a model, the one that the successful updates say must be running, and is exactly the
//!   measuring (semihosting) firmware's answer with that model and agrees with `magic invert`
//!   (records::invert_rows, f64) with that model;
//! * a system reset (`!reset`, SYSRESETREQ) keeps the last model switched to, whichever slot it
//!   is in, and failed or half-done uploads do not change it; a hung board is reset by the
//!   watchdog, and the station sends the days that were in flight again;
//! * the deployable ELF holds no semihosting trap (`bkpt 0xab`) and no panic is reachable in it;
//! * `magic station` (the CLI path) writes one row per input row;
//! * the deployable firmware built with the feature `sd` answers with the variables' standard
//!   deviations, as `magic invert --sd` writes them.
//!
//! Needs `qemu-system-arm`, the Rust target `thumbv7em-none-eabihf` and `llvm-tools`; without
//! them the tests fail with a message saying how to install them, unless `MAGIC_SKIP_QEMU=1`.

use magic_core::{Flags, Model, Variant};
use magic_train::data::records::{self, ObsRow};
use magic_train::firmware::qemu::{build_firmware, ensure_toolchain, run_firmware};
use magic_train::firmware::qemu_uart::{build_deployable, semihosting_calls, UartQemu};
use magic_train::firmware::station::{
    self, Answer, BoardStatus, Event, Item, Link, Station, Transcript,
};
use magic_train::gnss::synth;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Seconds a semihosting run may take.
const TIMEOUT_S: u64 = 300;
/// Board (f32) against host (f64): largest difference of a variable as a fraction of its
/// range. Measured on these models: below 1e-5 (printed by the stream test); 1e-4 is the
/// margin the semihosting test (firmware_qemu.rs) holds the board to as well.
const HOST_TOLERANCE: f64 = 1e-4;
/// The board's standard deviations (f64 in software from its f32 inversion) against the host's,
/// relative: the bound of the measuring firmware's test (firmware_qemu.rs, measured 2.5e-6 there).
const BOARD_SD_MAX_REL_ERROR: f64 = 2.5e-5;
/// Days in the stream.
const DAYS: usize = 10_000;

fn toolchain_ready() -> bool {
    match ensure_toolchain() {
        Ok(()) => true,
        Err(e) if std::env::var("MAGIC_SKIP_QEMU").as_deref() == Ok("1") => {
            eprintln!("notice: skipping the firmware test (MAGIC_SKIP_QEMU=1): {e}");
            false
        }
        Err(e) => panic!("{e:#}\n(set MAGIC_SKIP_QEMU=1 to skip the QEMU tests)"),
    }
}

fn temp_dir() -> PathBuf {
    let dir = std::env::temp_dir().join(format!("magic-uart-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// An int8 variant-C model on the Akutan network (random weights, standardisation and
/// calibration from the synthetic dataset of `seed`), as model-file bytes.
fn model(seed: u64) -> Vec<u8> {
    let owned = magic_tests::random_mogi_model(Variant::C, seed);
    let s = synth::generate(synth::Scenario::Clean, seed);
    let calib: Vec<Vec<f32>> = s
        .problem
        .data
        .train
        .x
        .iter()
        .filter(|r| r.iter().all(|v| v.is_finite()))
        .take(256)
        .cloned()
        .collect();
    owned.quantize_int8(&calib).unwrap().encode().unwrap()
}

/// The model with its format version set to `v`, CRC made valid again.
fn with_version(bytes: &[u8], v: u16) -> Vec<u8> {
    let mut b = bytes.to_vec();
    b[4..6].copy_from_slice(&v.to_le_bytes());
    let n = b.len();
    let crc = magic_tests::crc32(&b[..n - 4]);
    b[n - 4..].copy_from_slice(&crc.to_le_bytes());
    b
}

/// `DAYS` observation rows in mm (the synthetic dataset's days, cycled, at 0.1 mm: finer than GNSS
/// daily noise of about 1 mm, and short lines for the slow emulated UART), written as a
/// CSV with the network's columns and read back as `magic invert` reads it.
fn days(model: &Model<'_>, name: &str) -> (PathBuf, Vec<ObsRow>) {
    let s = synth::generate(synth::Scenario::Clean, 1);
    let d = &s.problem.data;
    let all: Vec<&Vec<f32>> = d
        .train
        .x
        .iter()
        .chain(&d.valid.x)
        .chain(&d.test.x)
        .collect();
    let mut text = d.columns.join(",");
    text.push('\n');
    for i in 0..DAYS {
        let row = all[i % all.len()];
        let cells: Vec<String> = row
            .iter()
            .enumerate()
            .map(|(c, &z)| {
                if z.is_nan() {
                    String::new()
                } else {
                    format!("{:.1}", z as f64 * d.scale[c] + d.mean[c])
                }
            })
            .collect();
        text.push_str(&cells.join(","));
        text.push('\n');
    }
    let path = temp_dir().join(name);
    std::fs::write(&path, text).unwrap();
    let rows = records::read_obs(&path, model, false).unwrap();
    assert_eq!(rows.len(), DAYS);
    (path, rows)
}

/// Lines that reach the board and are refused by it (as by `magic_core::line::parse_obs`).
fn malformed(good: &str, k: usize) -> String {
    let fields: Vec<&str> = good.split(',').collect();
    match k % 5 {
        0 => fields[..fields.len() - 1].join(","), // a field short
        1 => format!("{good},1.0"),                // a field too many
        2 => {
            let mut f = fields.clone();
            f[3] = "abc";
            f.join(",")
        }
        3 => {
            let mut f = fields.clone();
            f[7] = "inf";
            f.join(",")
        }
        _ => {
            let mut f = fields.clone();
            f[9] = "12345.0";
            f.join(",")
        }
    }
}

/// What the host answers for a day line: `magic invert`'s row for the CSV rows, core's error
/// for the lines the board must refuse.
fn host_line(model: &Model<'_>, line: &str) -> String {
    let mut obs = vec![0f32; model.n_obs()];
    let mut ws = magic_core::Workspace::default();
    let mut s = String::new();
    match magic_core::line::parse_obs(line, &mut obs) {
        Err(e) => magic_core::line::write_error(&mut s, &e).unwrap(),
        Ok(()) => match magic_core::invert::<f64>(model, &obs, &mut ws) {
            Ok(inv) => magic_core::line::write_result(&mut s, &inv).unwrap(),
            Err(e) => {
                magic_core::line::write_error(&mut s, &magic_core::line::LineError::Invert(e))
                    .unwrap()
            }
        },
    }
    s
}

/// Checks a board result against the host's: same error text, or every variable within
/// [`HOST_TOLERANCE`] of its range with the same flags (but the residual threshold's) and
/// stations. Returns the largest difference.
fn agrees(model: &Model<'_>, board: &str, host: &str, what: &str) -> f64 {
    if host.starts_with("error,") || board.starts_with("error,") {
        assert_eq!(board, host, "{what}");
        return 0.0;
    }
    let b: Vec<&str> = board.split(',').collect();
    let h: Vec<&str> = host.split(',').collect();
    let n = model.n_params();
    assert_eq!(b.len(), h.len(), "{what}: {board} vs {host}");
    let mut worst = 0f64;
    for j in 0..n {
        let (x, y): (f64, f64) = (b[j].parse().unwrap(), h[j].parse().unwrap());
        let [lo, hi] = model.bounds[j];
        let rel = (x - y).abs() / (hi - lo) as f64;
        assert!(
            rel <= HOST_TOLERANCE,
            "{what}: variable {j}: board {x}, host {y}"
        );
        worst = worst.max(rel);
    }
    let flags = |v: &str| v.parse::<u8>().unwrap() & !Flags::HIGH_RESIDUAL;
    assert_eq!(flags(b[n + 1]), flags(h[n + 1]), "{what}: flags");
    assert_eq!(b[n + 2], h[n + 2], "{what}: stations used");
    worst
}

fn connect(qemu: &mut UartQemu) -> Station {
    let stream = qemu
        .connect(Duration::from_secs(20))
        .expect("connecting to QEMU");
    Station::connect(Link::tcp(stream, &qemu.address()).unwrap()).expect("board status")
}

fn lines_of(items: Vec<String>) -> Vec<Item> {
    items.into_iter().map(Item::Line).collect()
}

fn board_answer(a: &Option<Answer>) -> &str {
    match a {
        Some(Answer::Board(l)) => l,
        other => panic!("no answer from the board: {other:?}"),
    }
}

/// The models of the stream test: three good ones and the failed updates made from the third.
struct Updates {
    a: Vec<u8>,
    b: Vec<u8>,
    c: Vec<u8>,
    /// C with a flipped byte.
    corrupt: Vec<u8>,
    /// C in another format version.
    old_version: Vec<u8>,
    /// C's upload lines.
    c_lines: Vec<String>,
    /// The ids of A, B and C.
    ids: Vec<u32>,
}

impl Updates {
    fn new() -> Updates {
        let (a, b, c) = (model(11), model(12), model(13));
        let ids: Vec<u32> = [&a, &b, &c]
            .iter()
            .map(|m| station::model_id(m).unwrap())
            .collect();
        // Failed updates: a flipped byte, too large for a slot, another format version.
        let mut corrupt = c.clone();
        corrupt[c.len() / 2] ^= 0x10;
        let old_version = with_version(&c, 4);
        let c_lines = station::upload_lines(&c);
        Updates {
            a,
            b,
            c,
            corrupt,
            old_version,
            c_lines,
            ids,
        }
    }
}

/// The stream's script: the lines sent, the item of each day, which model must answer each
/// day, and the item where each update starts.
struct Script {
    items: Vec<Item>,
    day_item: Vec<usize>,
    expect: Vec<usize>,
    marks: BTreeMap<&'static str, usize>,
}

/// The day lines of `rows` with ten of them malformed; returns them and the malformed ones.
fn wire_with_bad_days(rows: &[ObsRow]) -> (Vec<String>, Vec<usize>) {
    let mut wire: Vec<String> = station::day_lines(rows, false)
        .into_iter()
        .map(|l| l.expect("every synthetic row is valid"))
        .collect();
    let mut bad = Vec::new();
    for k in 0..10 {
        let i = 500 + 1000 * k;
        wire[i] = malformed(&wire[i], k);
        bad.push(i);
    }
    (wire, bad)
}

/// The days with the updates in the middle of the stream.
fn script(wire: &[String], u: &Updates) -> Script {
    let mut items = Vec::new();
    let mut day_item = vec![0usize; DAYS];
    let mut expect = vec![0usize; DAYS];
    let mut marks = BTreeMap::new();
    let mut add_days = |items: &mut Vec<Item>, range: std::ops::Range<usize>, m: usize| {
        for i in range {
            day_item[i] = items.len();
            expect[i] = m;
            items.push(Item::Day(wire[i].clone()));
        }
    };
    let mut mark = |items: &Vec<Item>, name: &'static str| {
        marks.insert(name, items.len());
    };
    let c_lines = &u.c_lines;
    mark(&items, "upload A");
    items.extend(lines_of(station::upload_lines(&u.a)));
    add_days(&mut items, 0..2500, 0);
    mark(&items, "upload B");
    items.extend(lines_of(station::upload_lines(&u.b)));
    add_days(&mut items, 2500..4000, 1);
    mark(&items, "corrupt");
    items.extend(lines_of(station::upload_lines(&u.corrupt)));
    add_days(&mut items, 4000..5000, 1);
    mark(&items, "too large");
    items.push(Item::Line(format!("!model 30000 {:08x}", u.ids[2])));
    mark(&items, "version");
    items.extend(lines_of(station::upload_lines(&u.old_version)));
    add_days(&mut items, 5000..6000, 1);
    mark(&items, "cut off");
    items.extend(lines_of(c_lines[..c_lines.len() / 2].to_vec()));
    add_days(&mut items, 6000..7000, 1);
    mark(&items, "timed out");
    items.extend(lines_of(c_lines[..c_lines.len() / 3].to_vec()));
    items.push(Item::Pause(Duration::from_secs(3)));
    add_days(&mut items, 7000..8000, 1);
    mark(&items, "upload C");
    items.extend(lines_of(c_lines.clone()));
    add_days(&mut items, 8000..DAYS, 2);
    Script {
        items,
        day_item,
        expect,
        marks,
    }
}

/// The updates were answered as they must be, and the abandoned ones reported unasked when the
/// next day came and after the timeout.
fn check_updates(t: &Transcript, sc: &Script, u: &Updates) {
    let (a, b, c, ids) = (&u.a, &u.b, &u.c, &u.ids);
    let answer = |name: &str, k: usize| board_answer(&t.answers[sc.marks[name] + k]).to_string();
    let n_lines = |m: &[u8]| station::upload_lines(m).len();
    assert_eq!(answer("upload A", 0), format!("model,ready,{}", a.len()));
    assert_eq!(
        answer("upload A", n_lines(a) - 1),
        format!("model,ok,{:08x}", ids[0])
    );
    assert_eq!(
        answer("upload B", n_lines(b) - 1),
        format!("model,ok,{:08x}", ids[1])
    );
    let corrupt_answer = answer("corrupt", n_lines(&u.corrupt) - 1);
    assert!(
        corrupt_answer.starts_with("model,error,model: model file is corrupt: CRC stored"),
        "{corrupt_answer}"
    );
    assert_eq!(
        answer("too large", 0),
        "model,error,too large: 30000 bytes, a slot holds 24576"
    );
    assert_eq!(
        answer("version", n_lines(&u.old_version) - 1),
        "model,error,model: model format version 4 is not supported (this build reads 5)"
    );
    assert_eq!(
        answer("upload C", n_lines(c) - 1),
        format!("model,ok,{:08x}", ids[2])
    );
    // The abandoned ones: unasked lines, when the next day came and after the timeout.
    let abandoned: Vec<(usize, String)> = t
        .events
        .iter()
        .map(|(at, e)| match e {
            Event::UploadAbandoned(l) => (*at, l.clone()),
            other => panic!("unexpected event {other:?}"),
        })
        .collect();
    let half = u.c_lines.len() / 2 - 1;
    let third = u.c_lines.len() / 3 - 1;
    assert_eq!(
        abandoned,
        vec![
            (
                sc.day_item[6000],
                format!(
                    "!model,error,interrupted by a line that is not model data after {} of {} bytes",
                    half * station::UPLOAD_BYTES_PER_LINE,
                    c.len()
                )
            ),
            (
                sc.day_item[7000],
                format!(
                    "!model,error,timed out after {} of {} bytes",
                    third * station::UPLOAD_BYTES_PER_LINE,
                    c.len()
                )
            ),
        ]
    );
}

/// Every day has one answer, naming the model that must be running; returns the days answered
/// by each model and each day's result (the answer without the model id).
fn answers_by_model(t: &Transcript, sc: &Script, ids: &[u32]) -> (Vec<Vec<usize>>, Vec<String>) {
    let mut by_model: Vec<Vec<usize>> = vec![Vec::new(); 3];
    let mut results = vec![String::new(); DAYS];
    for (i, result) in results.iter_mut().enumerate() {
        let line = board_answer(&t.answers[sc.day_item[i]]);
        let (id, rest) = station::split_answer(line).unwrap_or_else(|| panic!("day {i}: {line}"));
        let m = ids
            .iter()
            .position(|&x| x == id)
            .unwrap_or_else(|| panic!("day {i}: {line}"));
        assert_eq!(
            m, sc.expect[i],
            "day {i} answered by the wrong model: {line}"
        );
        by_model[m].push(i);
        *result = rest.to_string();
    }
    (by_model, results)
}

/// Against the measuring (semihosting) firmware with the same model: the same text.
fn check_against_measuring(
    u: &Updates,
    wire: &[String],
    by_model: &[Vec<usize>],
    results: &[String],
) {
    for (m, bytes) in [&u.a, &u.b, &u.c].iter().enumerate() {
        let path = temp_dir().join(format!("model-{m}.magic"));
        std::fs::write(&path, bytes).unwrap();
        let fw = build_firmware(&path).expect("building the measuring firmware");
        let input: String = by_model[m]
            .iter()
            .map(|&i| format!("{}\n", wire[i]))
            .collect();
        let run = run_firmware(&fw, &input, TIMEOUT_S).expect("running the measuring firmware");
        assert!(
            run.success,
            "measuring firmware failed: {:?}",
            run.results.last()
        );
        assert_eq!(run.results.len(), by_model[m].len());
        for (&i, sh) in by_model[m].iter().zip(&run.results) {
            assert_eq!(
                &results[i], sh,
                "day {i}: UART and semihosting builds differ"
            );
        }
        if m == 0 {
            eprintln!(
                "measuring build, model A: {:?} instructions per inversion",
                run.instructions_per_inversion
            );
        }
    }
}

/// Against `magic invert` (the host, f64) with the model each answer names; returns the
/// largest difference.
fn check_against_host(
    models: &[Model<'_>],
    rows: &[ObsRow],
    (wire, bad): (&[String], &[usize]),
    by_model: &[Vec<usize>],
    results: &[String],
) -> f64 {
    let mut worst = 0f64;
    for (m, model) in models.iter().enumerate() {
        let host = records::invert_rows(model, rows);
        for &i in &by_model[m] {
            let h = if bad.contains(&i) {
                host_line(model, &wire[i])
            } else {
                host[i].clone()
            };
            worst = worst.max(agrees(model, &results[i], &h, &format!("day {i}")));
        }
    }
    worst
}

#[test]
fn ten_thousand_days_with_model_updates_in_the_stream() {
    if !toolchain_ready() {
        return;
    }
    let u = Updates::new();
    let models: Vec<Model<'_>> = [&u.a, &u.b, &u.c]
        .iter()
        .map(|m| Model::decode(m).unwrap())
        .collect();
    let (_, rows) = days(&models[0], "days.csv");
    let (wire, bad) = wire_with_bad_days(&rows);
    // The script, and which model must answer each day.
    let sc = script(&wire, &u);

    // The board.
    let elf = build_deployable(&[]).expect("building the deployable firmware");
    let mut qemu = UartQemu::start(&elf).expect("starting QEMU");
    let mut st = connect(&mut qemu);
    assert_eq!(st.status.model, None, "a fresh board has no model");
    assert_eq!(st.status.reset, "power-on");
    let start = Instant::now();
    let t = st.run(&sc.items).expect("streaming");
    let elapsed = start.elapsed().as_secs_f64();
    let sent: usize = sc
        .items
        .iter()
        .map(|i| match i {
            Item::Day(s) | Item::Line(s) => s.len() + 1,
            Item::Pause(_) => 0,
        })
        .sum();
    eprintln!(
        "{} lines ({} days, {:.1} MB) in {elapsed:.1} s (3 s of it a pause): {:.0} days/s",
        sc.items.len(),
        DAYS,
        sent as f64 / 1e6,
        DAYS as f64 / elapsed
    );

    check_updates(&t, &sc, &u);
    let (by_model, results) = answers_by_model(&t, &sc, &u.ids);
    for &i in &bad {
        assert!(results[i].starts_with("error,"), "day {i}: {}", results[i]);
    }
    check_against_measuring(&u, &wire, &by_model, &results);
    let worst = check_against_host(&models, &rows, (&wire, &bad), &by_model, &results);
    eprintln!(
        "days per model: A {}, B {}, C {}; largest difference from the host {worst:.2e} of a variable's range",
        by_model[0].len(),
        by_model[1].len(),
        by_model[2].len()
    );
}

/// The model that answers each of the `days`, by id.
fn answered_by(st: &mut Station, days: &[String]) -> Vec<u32> {
    let items: Vec<Item> = days.iter().cloned().map(Item::Day).collect();
    let t = st.run(&items).unwrap();
    t.answers
        .iter()
        .map(|a| station::split_answer(board_answer(a)).unwrap().0)
        .collect()
}

/// The board runs `model` from `slot`, and last started for `reset`.
fn check_status(s: &BoardStatus, model: &[u8], slot: usize, reset: &str) {
    assert_eq!(s.model, Some(station::model_id(model).unwrap()), "{s:?}");
    assert_eq!(s.slot, Some(slot), "{s:?}");
    assert_eq!(s.reset, reset, "{s:?}");
}

/// Malformed commands and upload lines: an error answer each, `c` still running.
fn check_malformed_commands(st: &mut Station, c: &[u8], days: &[String]) {
    let id = |m: &[u8]| station::model_id(m).unwrap();
    let c_id = format!("{:08x}", id(c));
    let cases = [
        (
            "!model 18899".to_string(),
            "model,error,usage: !model <size in bytes> <CRC-32, 8 hex digits>".to_string(),
        ),
        (
            "!model 10 0badc0de".into(),
            "model,error,a model file has at least 14 bytes, not 10".into(),
        ),
        (
            ":00ff".into(),
            "model,error,model data without !model".into(),
        ),
        (
            format!("!model {} {c_id}", c.len()),
            format!("model,ready,{}", c.len()),
        ),
        (
            ":0ff".into(),
            "model,error,model data is not an even number of hex digits".into(),
        ),
        ("!frobnicate".into(), "error,unknown command".into()),
        (
            "1".repeat(1500),
            format!("{c_id},error,line longer than 1024 bytes"),
        ),
    ];
    let items: Vec<Item> = cases.iter().map(|(l, _)| Item::Line(l.clone())).collect();
    let t = st.run(&items).unwrap();
    for ((line, want), got) in cases.iter().zip(&t.answers) {
        assert_eq!(
            board_answer(got),
            want,
            "answer to {}",
            &line[..line.len().min(40)]
        );
    }
    assert!(t.events.is_empty(), "{:?}", t.events);
    assert!(answered_by(st, days).iter().all(|&x| x == id(c)));
}

/// A hung board: the watchdog resets it (NMI after 1 s without feeding, reset after 2 s); the
/// days sent behind the hanging command are sent again and answered, by `c` from slot 0.
fn check_watchdog_restart(st: &mut Station, c: &[u8], days: &[String]) {
    let mut items = vec![Item::Line("!hang".into())];
    items.extend(days.iter().cloned().map(Item::Day));
    let start = Instant::now();
    let t = st.run(&items).expect("a hang and a restart");
    let recovery = start.elapsed().as_secs_f64();
    assert_eq!(board_answer(&t.answers[0]), "hang");
    for a in &t.answers[1..] {
        assert_eq!(
            station::split_answer(board_answer(a)).unwrap().0,
            station::model_id(c).unwrap()
        );
    }
    assert_eq!(t.events.len(), 1, "{:?}", t.events);
    match &t.events[0] {
        (1, Event::Restarted(Some(s))) => check_status(s, c, 0, "watchdog"),
        other => panic!("expected a watchdog restart, got {other:?}"),
    }
    eprintln!("hung board back and answering after {recovery:.1} s");
}

/// Memory within the budget of memory-uart.x.
fn check_memory(st: &mut Station) {
    let s = st.run(&[Item::Line("!status".into())]).unwrap();
    let status = BoardStatus::parse(board_answer(&s.answers[0])).unwrap();
    let field = |k: &str| -> usize {
        status
            .fields
            .iter()
            .find(|f| f.0 == k)
            .unwrap()
            .1
            .parse()
            .unwrap()
    };
    eprintln!("board status: {:?}", status.fields);
    assert!(field("flash") <= 36 * 1024, "program image within 36 KiB");
    assert_eq!(field("slot_bytes"), 24 * 1024);
    assert!(field("statics") + field("stack_available") <= 20 * 1024);
    assert!(field("stack_available") >= 8 * 1024);
    assert!(
        field("stack") < field("stack_available"),
        "stack high-water mark"
    );
}

#[test]
fn resets_keep_the_last_model_and_the_watchdog_resets_a_hung_board() {
    if !toolchain_ready() {
        return;
    }
    let (a, b, c) = (model(21), model(22), model(23));
    let id = |m: &[u8]| station::model_id(m).unwrap();
    let elf = build_deployable(&["hang-command"]).expect("building the deployable firmware");
    let mut qemu = UartQemu::start(&elf).expect("starting QEMU");
    let mut st = connect(&mut qemu);
    let day = {
        let m = Model::decode(&a).unwrap();
        let (_, rows) = days(&m, "reset-days.csv");
        station::day_lines(&rows[..8], false)
            .into_iter()
            .map(|l| l.unwrap())
            .collect::<Vec<_>>()
    };

    // A into slot 0, B into slot 1, C into slot 0 again: each survives a reset.
    for (m, slot) in [(&a, 0), (&b, 1), (&c, 0)] {
        st.upload(m).expect("upload");
        let s = st.reset().expect("reset");
        check_status(&s, m, slot, "command");
        assert!(answered_by(&mut st, &day).iter().all(|&x| x == id(m)));
    }
    // A refused upload and a half-done one leave C in use, before and after a reset.
    let mut corrupt = a.clone();
    corrupt[100] ^= 1;
    assert!(st.upload(&corrupt).is_err());
    let half = station::upload_lines(&b);
    let t = st.run(&lines_of(half[..half.len() / 2].to_vec())).unwrap();
    assert!(t
        .answers
        .iter()
        .all(|a| board_answer(a).starts_with("model,")));
    let s = st.reset().expect("reset");
    check_status(&s, &c, 0, "command");
    assert!(answered_by(&mut st, &day).iter().all(|&x| x == id(&c)));

    check_malformed_commands(&mut st, &c, &day);
    check_watchdog_restart(&mut st, &c, &day);
    // Memory within the budget, after all of the above.
    check_memory(&mut st);
}

#[test]
fn the_deployable_firmware_makes_no_semihosting_call_and_cannot_panic() {
    if !toolchain_ready() {
        return;
    }
    let uart = build_deployable(&[]).expect("building the deployable firmware");
    let calls = semihosting_calls(&uart).expect("disassembling");
    assert!(
        calls.is_empty(),
        "semihosting in the deployable firmware: {calls:#?}"
    );
    // The check finds them where they are: in the measuring build.
    let path = temp_dir().join("measuring.magic");
    std::fs::write(&path, model(31)).unwrap();
    let measuring = build_firmware(&path).expect("building the measuring firmware");
    let found = semihosting_calls(&measuring).expect("disassembling");
    assert!(
        !found.is_empty(),
        "no bkpt 0xab found in the measuring build"
    );
    eprintln!(
        "measuring build: {} semihosting traces, e.g. {}",
        found.len(),
        found[0]
    );

    // Links only if no panic is reachable; one reachable panic makes the same build fail.
    build_deployable(&["panic-never"]).expect(
        "the deployable firmware must link with the panic-never handler (a panic is reachable: \
         the linker names the undefined symbol magic_firmware_panic_is_reachable)",
    );
    assert!(
        build_deployable(&["panic-never", "panic-canary"]).is_err(),
        "a deployable firmware with a reachable panic linked with the panic-never handler"
    );
}

#[test]
fn station_command_writes_one_row_per_input_row() {
    if !toolchain_ready() {
        return;
    }
    let bytes = model(41);
    let m = Model::decode(&bytes).unwrap();
    let dir = temp_dir();
    let model_path = dir.join("cli.magic");
    std::fs::write(&model_path, &bytes).unwrap();
    // 40 days, the sixth with a value that is not a number (file line 7, its fourth field).
    let (full, _) = days(&m, "cli-all.csv");
    let text = std::fs::read_to_string(full).unwrap();
    let mut lines: Vec<String> = text.lines().take(41).map(String::from).collect();
    let mut f: Vec<&str> = lines[6].split(',').collect();
    f[3] = "x";
    // The error names the character column where the field starts.
    let column = f[..3].iter().map(|c| c.chars().count() + 1).sum::<usize>() + 1;
    lines[6] = f.join(",");
    let input = dir.join("cli.csv");
    std::fs::write(&input, lines.join("\n") + "\n").unwrap();

    let elf = build_deployable(&[]).expect("building the deployable firmware");
    let mut qemu = UartQemu::start(&elf).expect("starting QEMU");
    // (Once QEMU listens; the board starts with this first connection.)
    drop(
        qemu.connect(Duration::from_secs(20))
            .expect("connecting to QEMU"),
    );
    let output = dir.join("cli-out.csv");
    let mut opts = station::Options {
        port: qemu.address(),
        model: Some(model_path),
        days: Some(input.clone()),
        output: Some(output.clone()),
        standardized: false,
    };
    let err = station::run_cli(&opts).expect_err("one row is bad");
    assert!(err.to_string().contains("1 of 40 rows"), "{err}");
    let out = station::read_output(&output).unwrap();
    assert_eq!(out.len(), 40, "one row per input row");
    let host = records::invert_rows(&m, &records::read_obs(&input, &m, false).unwrap());
    for (i, ((id, result), h)) in out.iter().zip(&host).enumerate() {
        if i == 5 {
            assert_eq!(*id, None);
            assert!(result.contains(&format!("cli.csv:7:{column}:")), "{result}");
            continue;
        }
        assert_eq!(*id, station::model_id(&bytes), "row {i}");
        agrees(&m, result, h, &format!("row {i}"));
    }
    // Again: the board runs the model already (no upload), the same rows come back.
    opts.days = None;
    station::run_cli(&opts).expect("status only");
}

/// The deployable firmware built with the feature `sd` (`uart,sd`, memory-uart-sd.x) says so in
/// its status, and `magic station` writes the variables' standard deviations after `magic
/// invert`'s columns, as `magic invert --sd` does, within [`BOARD_SD_MAX_REL_ERROR`] of the
/// host's; the build links with the panic-never handler too.
#[test]
fn deployable_firmware_with_standard_deviations() {
    if !toolchain_ready() {
        return;
    }
    let bytes = model(43);
    let m = Model::decode(&bytes).unwrap();
    let dir = temp_dir();
    let model_path = dir.join("sd.magic");
    std::fs::write(&model_path, &bytes).unwrap();
    let (full, _) = days(&m, "sd-all.csv");
    let text = std::fs::read_to_string(full).unwrap();
    let input = dir.join("sd.csv");
    std::fs::write(
        &input,
        text.lines().take(31).collect::<Vec<_>>().join("\n") + "\n",
    )
    .unwrap();

    let elf = build_deployable(&["sd"]).expect("building the deployable firmware with `sd`");
    let mut qemu = UartQemu::start(&elf).expect("starting QEMU");
    assert!(connect(&mut qemu).status.sd, "the status says sd=yes");
    let output = dir.join("sd-out.csv");
    station::run_cli(&station::Options {
        port: qemu.address(),
        model: Some(model_path),
        days: Some(input.clone()),
        output: Some(output.clone()),
        standardized: false,
    })
    .expect("30 good rows");
    let header = std::fs::read_to_string(&output).unwrap();
    let sd_names = records::sd_columns(&m);
    assert!(
        header
            .lines()
            .next()
            .unwrap()
            .ends_with(&sd_names.join(",")),
        "{header}"
    );
    let out = station::read_output(&output).unwrap();
    let host = records::invert_rows_sd(&m, &records::read_obs(&input, &m, false).unwrap()).unwrap();
    assert_eq!(out.len(), 30, "one row per input row");
    let (n, k) = (m.n_params(), sd_names.len());
    let mut worst = 0f64;
    for (i, ((id, board), h)) in out.iter().zip(&host).enumerate() {
        assert_eq!(*id, station::model_id(&bytes), "row {i}");
        agrees(&m, board, h, &format!("row {i}"));
        let (b, h): (Vec<&str>, Vec<&str>) = (board.split(',').collect(), h.split(',').collect());
        assert_eq!(b.len(), n + 3 + k, "row {i}: {board}");
        for j in n + 3..n + 3 + k {
            let (x, y): (f64, f64) = (b[j].parse().unwrap(), h[j].parse().unwrap());
            assert_eq!(
                x.is_finite(),
                y.is_finite(),
                "row {i} field {j}: {x} vs {y}"
            );
            if y.is_finite() {
                let rel = (x - y).abs() / y.abs().max(1e-12);
                assert!(
                    rel <= BOARD_SD_MAX_REL_ERROR,
                    "row {i} field {j}: board {x}, host {y}"
                );
                worst = worst.max(rel);
            }
        }
    }
    // The stack's high-water mark after the standard deviations, within the budget.
    let st = connect(&mut qemu).status;
    let field = |k: &str| -> usize {
        let v = st.fields.iter().find(|f| f.0 == k).map(|f| f.1.as_str());
        v.and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("status field {k}: {:?}", st.fields))
    };
    let (stack, available) = (field("stack"), field("stack_available"));
    assert!(stack < available, "stack {stack} of {available} bytes");
    eprintln!(
        "deployable firmware with `sd`: standard deviations within {worst:.2e} of the host's; flash {} bytes, statics {} bytes, stack {stack} of {available} bytes",
        field("flash"),
        field("statics")
    );
    drop(qemu);
    build_deployable(&["sd", "panic-never"])
        .expect("the deployable `sd` firmware must link with the panic-never handler");
}

#[test]
fn magic_qemu_says_to_export_an_f32_model_before_building() {
    let f32_model = magic_tests::random_mogi_model(Variant::C, 51)
        .encode()
        .unwrap();
    let path = temp_dir().join("trained-f32.magic");
    std::fs::write(&path, &f32_model).unwrap();
    // What `magic qemu` and `magic demo` build with: refused before cargo runs.
    let err = build_firmware(&path).expect_err("an f32 model does not fit the firmware");
    let msg = format!("{err:#}");
    assert!(
        msg.contains("f32 model") && msg.contains("magic export"),
        "{msg}"
    );
    assert!(f32_model.len() > magic_train::firmware::qemu::MODEL_ROOM);
    // Its int8 export passes the check.
    let int8 = model(51);
    assert!(magic_train::firmware::qemu::check_int8(&path, &int8).is_ok());
}
