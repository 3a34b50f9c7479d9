//! The problem description of host-side models: `magic_core::Problem` borrows its arrays (a
//! decoded model borrows them from the file); an owned model keeps `'static` interned copies.

use magic_core::model_file::Problem;
use magic_core::quant::LeF32;
use std::sync::{Mutex, OnceLock};

/// A `'static` copy of `bytes`, shared by every caller with the same contents.
///
/// [`Problem`] borrows its tables (a decoded model borrows them from the file); host-side owned
/// models ([`crate::OwnedModel`]) hold a `Problem<'static>`, so their table bytes live for the
/// whole process. Interning keeps that to one copy per distinct table (≈ 81 KiB for the S2
/// bands), however many models are trained, loaded or exported.
pub fn intern(bytes: Vec<u8>) -> &'static [u8] {
    static POOL: OnceLock<Mutex<Vec<&'static [u8]>>> = OnceLock::new();
    let mut pool = POOL
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    if let Some(b) = pool.iter().find(|b| ***b == bytes[..]) {
        return b;
    }
    let b: &'static [u8] = Box::leak(bytes.into_boxed_slice());
    pool.push(b);
    b
}

/// A `'static` copy of a problem description (RTM table bytes interned).
pub fn owned_problem(p: &Problem<'_>) -> Problem<'static> {
    match p {
        Problem::Mogi { stations, names } => Problem::Mogi {
            stations: magic_core::mogi::Stations(intern(stations.0.to_vec())),
            names: magic_core::model_file::Names(
                std::str::from_utf8(intern(names.0.as_bytes().to_vec())).unwrap_or_default(),
            ),
        },
        Problem::Rtm {
            geometry,
            fixed,
            bands,
            spectral,
            weights,
            lidf_beta,
        } => Problem::Rtm {
            geometry: *geometry,
            fixed: *fixed,
            bands: *bands,
            spectral: LeF32(intern(spectral.0.to_vec())),
            weights: LeF32(intern(weights.0.to_vec())),
            lidf_beta: LeF32(intern(lidf_beta.0.to_vec())),
        },
    }
}

/// Number of bytes a problem's borrowed arrays take (for sizing the encode buffer).
pub fn problem_bytes(p: &Problem<'_>) -> usize {
    match p {
        Problem::Mogi { .. } => 0,
        Problem::Rtm {
            spectral,
            weights,
            lidf_beta,
            ..
        } => spectral.0.len() + weights.0.len() + lidf_beta.0.len(),
    }
}
