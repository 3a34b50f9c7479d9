//! Helpers shared by the cross-crate integration tests in `tests/tests/`.

use magic_core::Variant;
use magic_train::gnss::synth;
use magic_train::{MogiPhysics, Net, OwnedModel, Physics};
use rand::rngs::StdRng;
use rand::SeedableRng;
use std::path::PathBuf;
use std::sync::Arc;

/// The shared data folder: `$MAGIC_DATA`, else `shared/data` beside the workspace. Panics with a
/// clear message when absent: the reference outputs are part of what the tests check.
pub fn shared_data() -> PathBuf {
    let dir = match std::env::var_os("MAGIC_DATA") {
        Some(d) => PathBuf::from(d),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data"),
    };
    assert!(
        dir.join("oracle").is_dir(),
        "shared data not found at {} (set MAGIC_DATA to the folder holding gnss/, oracle/, rtm/, s2/)",
        dir.display()
    );
    dir
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
        cmd.args(["build", "--quiet", "-p", "magic-train", "--bin", "magic"]);
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
