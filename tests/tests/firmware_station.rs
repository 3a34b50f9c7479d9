//! `magic station` against the deployable firmware (UART0, no semihosting) under QEMU:
//!
//! * the CLI path writes one row per input row, a host-rejected row with its file, line and
//!   column;
//! * the deployable firmware built with the feature `sd` answers with the variables' standard
//!   deviations, as `magic invert --sd` writes them;
//! * `magic qemu` refuses an f32 model before building, saying to export it.
//!
//! Needs what `firmware_uart.rs` needs (QEMU, the target, `llvm-tools`), unless
//! `MAGIC_SKIP_QEMU=1`.

mod uart_common;

use magic_core::{Model, Variant};
use magic_tests::TempDir;
use magic_train::data::records;
use magic_train::firmware::qemu::build_firmware;
use magic_train::firmware::qemu_uart::{build_deployable, UartQemu};
use magic_train::firmware::station;
use std::time::Duration;
use uart_common::{agrees, connect, days, model, toolchain_ready};

/// The board's standard deviations (f64 in software from its f32 inversion) against the host's,
/// relative: the bound of the measuring firmware's test (firmware_qemu.rs, measured 2.5e-6 there).
const BOARD_SD_MAX_REL_ERROR: f64 = 2.5e-5;

#[test]
fn station_command_writes_one_row_per_input_row() {
    if !toolchain_ready() {
        return;
    }
    let bytes = model(41);
    let m = Model::decode(&bytes).unwrap();
    let tmp = TempDir::new("uart");
    let dir = &tmp.0;
    let model_path = dir.join("cli.magic");
    std::fs::write(&model_path, &bytes).unwrap();
    // 40 days, the sixth with a value that is not a number (file line 7, its fourth field).
    let (full, _) = days(&m, dir, "cli-all.csv");
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
    let tmp = TempDir::new("uart");
    let dir = &tmp.0;
    let model_path = dir.join("sd.magic");
    std::fs::write(&model_path, &bytes).unwrap();
    let (full, _) = days(&m, dir, "sd-all.csv");
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
    let tmp = TempDir::new("uart");
    let path = tmp.join("trained-f32.magic");
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
