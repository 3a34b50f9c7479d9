//! Helpers shared by the cross-crate integration tests in `tests/tests/`.

use magic_core::Variant;
use magic_train::export::OwnedModel;
use magic_train::nets::Net;
use magic_train::physics::{MogiPhysics, Physics};
use magic_train::pipeline::mogi_problem;
use magic_train::synth;
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
    let d = &s.data;
    let mut rng = StdRng::seed_from_u64(seed);
    let phys: Arc<dyn Physics> = Arc::new(MogiPhysics::new(d.stations.clone()));
    let net = Net::new(
        variant,
        d.n_obs(),
        (variant != Variant::A).then_some(phys),
        magic_core::mogi::PAPER_BOUNDS.to_vec(),
        d.mean.clone(),
        d.scale.clone(),
        4,
        &mut rng,
    )
    .expect("network");
    OwnedModel::from_net(
        &net,
        mogi_problem(&d.names, &d.stations).expect("problem"),
        vec![],
    )
    .expect("model")
}
