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
//! * the deployable ELF holds no semihosting trap (`bkpt 0xab`) and no panic is reachable in it.
//!
//! `magic station`'s CLI path and the build with standard deviations: `firmware_station.rs`.
//!
//! Needs `qemu-system-arm`, the Rust target `thumbv7em-none-eabihf` and `llvm-tools`; without
//! them the tests fail with a message saying how to install them, unless `MAGIC_SKIP_QEMU=1`.

mod uart_common;

use magic_core::Model;
use magic_tests::TempDir;
use magic_train::data::records::{self, ObsRow};
use magic_train::firmware::qemu::{build_firmware, run_firmware};
use magic_train::firmware::qemu_uart::{build_deployable, semihosting_calls, UartQemu};
use magic_train::firmware::station::{self, Answer, BoardStatus, Event, Item, Station, Transcript};
use std::collections::BTreeMap;
use std::path::Path;
use std::time::{Duration, Instant};
use uart_common::{agrees, connect, days, model, toolchain_ready, DAYS};

/// Seconds a semihosting run may take.
const TIMEOUT_S: u64 = 300;

/// The model with its format version set to `v`, CRC made valid again.
fn with_version(bytes: &[u8], v: u16) -> Vec<u8> {
    let mut b = bytes.to_vec();
    b[4..6].copy_from_slice(&v.to_le_bytes());
    let n = b.len();
    let crc = magic_tests::crc32(&b[..n - 4]);
    b[n - 4..].copy_from_slice(&crc.to_le_bytes());
    b
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
        "model,error,model: model format version 4 is not supported (this build reads 6)"
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

/// Against the measuring (semihosting) firmware with the same model (its file written into
/// `dir`): the same text.
fn check_against_measuring(
    dir: &Path,
    u: &Updates,
    wire: &[String],
    by_model: &[Vec<usize>],
    results: &[String],
) {
    for (m, bytes) in [&u.a, &u.b, &u.c].iter().enumerate() {
        let path = dir.join(format!("model-{m}.magic"));
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
    let tmp = TempDir::new("uart");
    let (_, rows) = days(&models[0], &tmp.0, "days.csv");
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
    check_against_measuring(&tmp.0, &u, &wire, &by_model, &results);
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
    let tmp = TempDir::new("uart");
    let day = {
        let m = Model::decode(&a).unwrap();
        let (_, rows) = days(&m, &tmp.0, "reset-days.csv");
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
    let tmp = TempDir::new("uart");
    let path = tmp.join("measuring.magic");
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
