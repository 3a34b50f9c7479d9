//! The command line's promise on bad input, through the real `magic` binary: every input row of
//! `magic invert` and `magic forward mogi` gives exactly one output row, whatever is wrong with it
//! (too few or too many fields, text, infinities, values beyond 10 m), and each error names the
//! file's own line and character column — with LF and with CRLF line ends, blank lines between
//! the rows counted as the lines they are.

use magic_core::mogi::{self, Station};
use magic_core::Variant;
use magic_tests::{magic_bin, random_mogi_model, TempDir};
use magic_train::gnss::synth;
use std::path::Path;
use std::process::{Command, Output};

/// What a row of the input is, and the 1-based field where its error is expected (0: none;
/// `usize::MAX`: one past the end of the line).
struct Row {
    text: String,
    bad_field: usize,
}

/// 1-based character column where field `k` (1-based) of a comma-separated `line` starts, or
/// one past the end when the line has fewer fields.
fn column(line: &str, k: usize) -> usize {
    let mut field = 1;
    if k == 1 {
        return 1;
    }
    for (i, ch) in line.chars().enumerate() {
        if ch == ',' {
            field += 1;
            if field == k {
                return i + 2;
            }
        }
    }
    line.chars().count() + 1
}

fn network() -> Vec<Station> {
    synth::AKUTAN
        .iter()
        .map(|s| Station {
            x_km: s.1,
            y_km: s.2,
            z_km: s.3,
        })
        .collect()
}

/// The observation rows: `date` first (so that every row, however short, carries it), then the
/// 36 channels in mm.
fn observation_rows() -> (String, Vec<Row>) {
    let names: Vec<&str> = synth::AKUTAN.iter().map(|s| s.0).collect();
    let mut header = vec!["date".to_string()];
    for comp in ["ux", "uy", "uz"] {
        header.extend(names.iter().map(|n| format!("{comp}_{n}")));
    }
    let stations = network();
    let good = |i: usize| -> Vec<String> {
        let mut u = vec![0.0; 36];
        mogi::field(&stations, &[0.5, -0.3, 6.0, 0.5 + 0.1 * i as f64], &mut u).unwrap();
        let mut f = vec![format!("2010.01.{:02}", i + 1)];
        f.extend(u.iter().map(|v| format!("{v:.4}")));
        f
    };
    let with = |i: usize, field: usize, v: &str| {
        let mut f = good(i);
        f[field - 1] = v.to_string();
        f.join(",")
    };
    let row = |text: String, bad_field: usize| Row { text, bad_field };
    let rows = vec![
        row(good(0).join(","), 0),
        row(good(1)[..11].join(","), usize::MAX), // too few fields
        row(with(2, 4, ""), 0),                   // an empty cell: a missing channel
        row(format!("{},3.5,7", good(3).join(",")), 38), // too many fields
        row(with(4, 6, "abc"), 6),                // not a number
        row(good(5).join(","), 0),
        row(with(6, 9, "inf"), 9),                // infinite
        row(with(7, 13, "-Infinity"), 13),        // infinite
        row(with(8, 20, "1e400"), 20),            // overflows to infinity
        row(with(9, 30, "12000"), 30),            // 12 m: beyond the core's 10 m
        row(with(10, 37, "1e300"), 37),           // huge
        row(with(11, 2, "NaN"), 0),               // missing
        row(good(12)[..1].join(","), usize::MAX), // a date alone
        row(good(13).join(","), 0),
    ];
    (header.join(","), rows)
}

/// Writes the rows with `eol` line ends and a blank line after the third row; returns the file's
/// 1-based line of every row.
fn write_rows(path: &Path, header: &str, rows: &[Row], eol: &str) -> Vec<usize> {
    let mut text = format!("{header}{eol}");
    let mut line = 2;
    let mut lines = Vec::new();
    for (i, r) in rows.iter().enumerate() {
        text.push_str(&r.text);
        text.push_str(eol);
        lines.push(line);
        line += 1;
        if i == 2 {
            text.push_str(eol);
            line += 1;
        }
    }
    std::fs::write(path, text).unwrap();
    lines
}

fn run(args: &[&str], paths: &[&Path]) -> std::process::Output {
    let mut cmd = Command::new(magic_bin());
    cmd.args(args);
    for p in paths {
        cmd.arg(p);
    }
    cmd.output().expect("magic runs")
}

#[test]
fn invert_gives_one_row_per_input_row_with_located_errors() {
    let tmp = TempDir::new("cli-rows");
    let model = tmp.join("b.magic");
    let bytes = random_mogi_model(Variant::B, 1).encode().unwrap();
    std::fs::write(&model, bytes).unwrap();
    let (header, rows) = observation_rows();
    for (tag, eol) in [("lf", "\n"), ("crlf", "\r\n")] {
        let input = tmp.join(&format!("obs-{tag}.csv"));
        let output = tmp.join(&format!("res-{tag}.csv"));
        let lines = write_rows(&input, &header, &rows, eol);
        let out = Command::new(magic_bin())
            .args(["invert", "--model"])
            .arg(&model)
            .arg("--input")
            .arg(&input)
            .arg("--output")
            .arg(&output)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "bad rows make the command fail");
        let text = std::fs::read_to_string(&output).expect("results written");
        let got: Vec<&str> = text.lines().collect();
        assert_eq!(
            got.len(),
            rows.len() + 1,
            "{tag}: one result row per input row"
        );
        assert!(got[0].starts_with("date,x_km,"));
        let shown = input.display().to_string();
        for (i, (r, line)) in rows.iter().zip(&lines).enumerate() {
            let res = got[i + 1];
            let date = r.text.split(',').next().unwrap();
            assert!(res.starts_with(&format!("{date},")), "{tag} row {i}: {res}");
            if r.bad_field == 0 {
                let v: Vec<f64> = res.split(',').skip(1).map(|x| x.parse().unwrap()).collect();
                assert_eq!(v.len(), 7, "{tag} row {i}: {res}");
                assert!(v.iter().all(|x| x.is_finite()), "{tag} row {i}: {res}");
            } else {
                let col = column(&r.text, r.bad_field);
                let want = format!("{date},error,{shown}:{line}:{col}: ");
                assert!(res.starts_with(&want), "{tag} row {i}: {res}\nwant {want}");
                let msg = format!("error: {shown}:{line}:{col}: ");
                assert!(stderr.contains(&msg), "{tag}: {msg} not in\n{stderr}");
            }
        }
        let n_bad = rows.iter().filter(|r| r.bad_field != 0).count();
        assert!(
            stderr.contains(&format!("inverted {} rows ({n_bad} errors)", rows.len())),
            "{stderr}"
        );
    }
}

/// `magic <sub> --model … --input … --output …` (with `--sd`).
fn rows_command(sub: &str, model: &Path, input: &Path, output: &Path, sd: bool) -> Output {
    let mut c = Command::new(magic_bin());
    c.args([sub, "--model"])
        .arg(model)
        .arg("--input")
        .arg(input);
    c.arg("--output").arg(output);
    if sd {
        c.arg("--sd");
    }
    c.output().unwrap()
}

/// `magic invert --sd`: the same rows, with `<variable>_sd` columns appended that equal the
/// library's standard deviations; error rows stay error rows; variant A models are refused with
/// a message (by `magic qemu --sd` too).
#[test]
fn invert_with_standard_deviations() {
    use magic_core::uncertainty::{standard_deviations, SdWorkspace};
    use magic_core::{invert_at, Model, Workspace};
    let tmp = TempDir::new("cli-rows-sd");
    let model = tmp.join("b.magic");
    let bytes = random_mogi_model(Variant::B, 1).encode().unwrap();
    std::fs::write(&model, &bytes).unwrap();
    let m = Model::decode(&bytes).unwrap();
    let (header, rows) = observation_rows();
    let input = tmp.join("obs.csv");
    write_rows(&input, &header, &rows, "\n");
    let (plain, with_sd) = (tmp.join("plain.csv"), tmp.join("sd.csv"));
    for (out, sd) in [(&plain, false), (&with_sd, true)] {
        let o = rows_command("invert", &model, &input, out, sd);
        assert!(!o.status.success(), "bad rows make the command fail");
    }
    let plain = std::fs::read_to_string(&plain).unwrap();
    let text = std::fs::read_to_string(&with_sd).unwrap();
    let got: Vec<&str> = text.lines().collect();
    assert_eq!(got.len(), rows.len() + 1, "one result row per input row");
    let sd_names = ["x_km_sd", "y_km_sd", "depth_km_sd", "dv_1e6m3_sd"];
    assert_eq!(
        got[0],
        format!("{},{}", plain.lines().next().unwrap(), sd_names.join(","))
    );
    let (mut ws, mut sw) = (Workspace::default(), SdWorkspace::default());
    let mut checked = 0;
    for (r, (res, base)) in rows.iter().zip(got[1..].iter().zip(plain.lines().skip(1))) {
        if r.bad_field != 0 {
            assert_eq!(*res, base, "an error row stays the same error row");
            continue;
        }
        assert!(res.starts_with(base), "{res} does not extend {base}");
        let sd: Vec<f64> = res[base.len() + 1..]
            .split(',')
            .map(|x| x.parse().unwrap())
            .collect();
        assert_eq!(sd.len(), 4, "{res}");
        // The library on the same observations (the CSV's values, NaN where empty).
        let obs: Vec<f32> = r
            .text
            .split(',')
            .skip(1)
            .map(|x| x.parse().unwrap_or(f32::NAN))
            .collect();
        let inv = invert_at::<f64>(&m, &obs, f64::NAN, &mut ws).unwrap();
        let u = standard_deviations(&m, &obs, &inv, f64::NAN, &mut sw).unwrap();
        for (k, v) in sd.iter().enumerate() {
            assert!(*v > 0.0 && v.is_finite(), "{res}");
            assert!(
                (v - u.sd[k]).abs() <= 1e-6 * u.sd[k],
                "{}: CSV {v} vs library {}",
                sd_names[k],
                u.sd[k]
            );
        }
        checked += 1;
    }
    assert!(checked >= 4, "only {checked} good rows");

    let a = tmp.join("a.magic");
    std::fs::write(&a, random_mogi_model(Variant::A, 1).encode().unwrap()).unwrap();
    let o = rows_command("invert", &a, &input, &tmp.join("a.csv"), true);
    let err_a = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err_a.contains("a.magic") && err_a.contains("variant A"),
        "{err_a}"
    );
    // (`magic qemu --sd` on B and C models: tests/tests/firmware_qemu.rs.)
    let o = rows_command("qemu", &a, &input, &tmp.join("q.csv"), true);
    let err_q = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err_q.contains("variant A"), "{err_q}");
}

#[test]
fn forward_gives_one_row_per_input_row_with_located_errors() {
    let tmp = TempDir::new("cli-rows-fwd");
    let header = "sample_id,xcen_km,ycen_km,d_km,dV_1e6m3";
    let rows = [
        ("1,0.5,-0.3,6.0,2.0", 0),
        ("2,0.5,-0.3", usize::MAX),
        ("3,0.5,-0.3,6.0,2.0,9", 6),
        ("4,0.5,x,6.0,2.0", 3),
        ("5,0.5,-0.3,inf,2.0", 4),
        ("6,1e400,-0.3,6.0,2.0", 2),
        ("7,0.1,0.2,5.0,-1.0", 0),
    ];
    let rows: Vec<Row> = rows
        .iter()
        .map(|(t, f)| Row {
            text: t.to_string(),
            bad_field: *f,
        })
        .collect();
    for (tag, eol) in [("lf", "\n"), ("crlf", "\r\n")] {
        let input = tmp.join(&format!("src-{tag}.csv"));
        let output = tmp.join(&format!("disp-{tag}.csv"));
        let lines = write_rows(&input, header, &rows, eol);
        let out = run(
            &["forward", "mogi", "--input"],
            &[&input, Path::new("--output"), &output],
        );
        assert!(!out.status.success());
        let stderr = String::from_utf8_lossy(&out.stderr);
        let text = std::fs::read_to_string(&output).unwrap();
        let got: Vec<&str> = text.lines().collect();
        assert_eq!(
            got.len(),
            rows.len() + 1,
            "{tag}: one output row per input row"
        );
        let shown = input.display().to_string();
        for (i, (r, line)) in rows.iter().zip(&lines).enumerate() {
            let id = r.text.split(',').next().unwrap();
            assert!(got[i + 1].starts_with(&format!("{id},")));
            let nan = got[i + 1].split(',').skip(1).all(|v| v == "NaN");
            assert_eq!(nan, r.bad_field != 0, "{tag} row {i}: {}", got[i + 1]);
            if r.bad_field != 0 {
                let col = column(&r.text, r.bad_field);
                let msg = format!("error: {shown}:{line}:{col}: ");
                assert!(stderr.contains(&msg), "{tag}: {msg} not in\n{stderr}");
            }
        }
    }
}
