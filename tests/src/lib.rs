//! Helpers shared by the cross-crate integration tests in `tests/tests/`.

use magic_core::Variant;
use magic_train::gnss::synth;
use magic_train::{MogiPhysics, Net, OwnedModel, Physics};
use rand::rngs::StdRng;
use rand::SeedableRng;
use std::path::PathBuf;
use std::sync::{Arc, OnceLock};

/// The shared data folder: `$MAGIC_DATA`, else `shared/data` beside the workspace. Panics with a
/// clear message when absent: the reference outputs are part of what the tests check.
pub fn shared_data() -> PathBuf {
    data_with(&["oracle"])
}

/// [`shared_data`], checked to hold every path of `needed` (relative to it, e.g.
/// `rtm/prospect_d_coefficients.csv`). A missing folder or file is a test failure that says what
/// to set, never a skipped check.
pub fn data_with(needed: &[&str]) -> PathBuf {
    let dir = match std::env::var_os("MAGIC_DATA") {
        Some(d) => PathBuf::from(d),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data"),
    };
    for rel in needed {
        assert!(
            dir.join(rel).exists(),
            "shared data incomplete: {} not found (set MAGIC_DATA to the folder holding gnss/, \
             oracle/, rtm/, s2/)",
            dir.join(rel).display()
        );
    }
    dir
}

/// Whether the firmware tests can run here (Rust target `thumbv7em-none-eabihf`,
/// `qemu-system-arm`): when the tools are missing, a test failure saying how to install them,
/// unless `MAGIC_SKIP_QEMU=1` asks explicitly to skip (then a notice, and `false`).
pub fn toolchain_ready() -> bool {
    match magic_train::firmware::qemu::ensure_toolchain() {
        Ok(()) => true,
        Err(e) if std::env::var("MAGIC_SKIP_QEMU").as_deref() == Ok("1") => {
            eprintln!("notice: skipping the firmware test (MAGIC_SKIP_QEMU=1): {e}");
            false
        }
        Err(e) => panic!("{e:#}\n(set MAGIC_SKIP_QEMU=1 to skip the QEMU tests)"),
    }
}

/// CRC-32/ISO-HDLC, the model file's checksum, written here from its definition (reflected
/// polynomial 0xEDB88320, initial value and final XOR 0xFFFFFFFF) so that the tests do not hold
/// the core's CRC to itself.
pub fn crc32(data: &[u8]) -> u32 {
    static TABLE: OnceLock<[u32; 256]> = OnceLock::new();
    let t = TABLE.get_or_init(|| {
        std::array::from_fn(|i| {
            (0..8).fold(i as u32, |c, _| {
                if c & 1 != 0 {
                    (c >> 1) ^ 0xEDB8_8320
                } else {
                    c >> 1
                }
            })
        })
    });
    !data.iter().fold(0xFFFF_FFFFu32, |c, &b| {
        t[((c ^ b as u32) & 0xFF) as usize] ^ (c >> 8)
    })
}

/// Recomputes the CRC of an edited model file (and, with `fix_len`, the header's body length)
/// so that decoding gets past both to the structural checks behind them.
pub fn reseal(b: &mut [u8], fix_len: bool) {
    if b.len() < 14 {
        return;
    }
    if fix_len {
        let body = (b.len() - 14) as u32;
        b[6..10].copy_from_slice(&body.to_le_bytes());
    }
    let n = b.len();
    let crc = crc32(&b[..n - 4]);
    b[n - 4..].copy_from_slice(&crc.to_le_bytes());
}

/// An untrained (seeded, randomly initialised) Mogi model of `variant` on the Akutan network,
/// with standardisation from the synthetic dataset, as an owned f32 model.
pub fn random_mogi_model(variant: Variant, seed: u64) -> OwnedModel {
    let s = synth::generate(synth::Scenario::Clean, seed);
    let (d, network) = (&s.problem.data, &s.problem.network);
    let mut rng = StdRng::seed_from_u64(seed);
    let phys: Arc<dyn Physics> = Arc::new(MogiPhysics::new(network.stations.clone(), vec![]));
    let net = Net::new(
        variant,
        d,
        (variant != Variant::A).then_some(phys),
        magic_core::mogi::PAPER_BOUNDS.to_vec(),
        4,
        &mut rng,
    )
    .expect("network");
    OwnedModel::from_net(&net, network.spec().expect("problem"), vec![]).expect("model")
}

/// The `magic` command of this build: `cargo build -p magic-train --bin magic` in the profile the
/// tests were built with (a no-op when it is up to date), once per test binary.
pub fn magic_bin() -> PathBuf {
    static BIN: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    BIN.get_or_init(|| {
        let exe = std::env::current_exe().expect("the test's own path");
        // target/<profile>/deps/<test> → target/<profile>
        let dir = exe
            .parent()
            .and_then(|d| d.parent())
            .expect("tests run from target/<profile>/deps")
            .to_path_buf();
        let profile = dir
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or("release")
            .to_string();
        let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
        let mut cmd = std::process::Command::new(cargo);
        // The workspace's bins and tests: features unified (dev-dependencies included) as in
        // `cargo test --workspace` (scripts/test-all.sh), so the binary reuses the tests'
        // dependencies instead of building them again with magic-train's features alone.
        cmd.args(["build", "--quiet", "--workspace", "--bins", "--tests"]);
        match profile.as_str() {
            "debug" => {}
            "release" => {
                cmd.arg("--release");
            }
            other => {
                cmd.args(["--profile", other]);
            }
        }
        let status = cmd
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .status()
            .expect("cargo runs");
        assert!(status.success(), "building the magic command failed");
        let bin = dir.join(format!("magic{}", std::env::consts::EXE_SUFFIX));
        assert!(bin.is_file(), "{} not found after building", bin.display());
        bin
    })
    .clone()
}

/// SplitMix64 (Steele, Lea and Flood): the next value of the generator whose state is `state`.
/// Tiny, fast and deterministic: the fuzz tests' case generator.
pub fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A temporary folder, removed on drop (also when the test fails).
pub struct TempDir(pub PathBuf);

impl TempDir {
    /// A new empty folder whose name holds `tag`, the process id and the time.
    pub fn new(tag: &str) -> TempDir {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos());
        let p = std::env::temp_dir().join(format!("magic-{tag}-{}-{nanos}", std::process::id()));
        std::fs::create_dir_all(&p).expect("temp dir");
        TempDir(p)
    }

    /// A path inside the folder.
    pub fn join(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

#[cfg(test)]
mod tests {
    /// The check value of CRC-32/ISO-HDLC (the CRC catalogue's "123456789").
    #[test]
    fn crc32_check_value() {
        assert_eq!(super::crc32(b"123456789"), 0xCBF4_3926);
    }
}
