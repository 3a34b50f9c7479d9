//! The exported model: what the host trainer writes and the board reads.
//!
//! ```text
//! "MAGC" | version: u16 LE | body length: u32 LE | body (postcard) | CRC-32 (ISO-HDLC) LE
//! ```
//!
//! The CRC covers everything before it. The body is a [`Model`] serialised with postcard; decoding
//! borrows every array (weights, station positions, station names) straight from the byte slice
//! (no allocation, no copy: a model in flash stays in flash), and [`Model::decode`] validates the
//! decoded structure against the sizes this build was compiled for, so a corrupt, truncated or
//! foreign file is an [`Error`], never a panic or an out-of-bounds read.
//!
//! Format versions: 3 added the RTM problem; 4 stores a Mogi network's stations as borrowed
//! little-endian `f64` bytes ([`Stations`]) and its names as one borrowed comma-separated string
//! ([`Names`]) instead of fixed-capacity vectors, which makes the decoded [`Model`] small enough
//! to decode within a microcontroller's stack budget; 5 stores int8 weights in blocks of four
//! rows ([`crate::quant::blocked_index`]) after 0–3 bytes of padding that align them to four bytes
//! in the file (the `SMLAD` kernel's layout), and leaves out the per-row arrays an int8 layer's
//! place in its chain does not use (weight scales of requantised layers, multipliers and shifts
//! of dequantised ones); 6 feeds a variant-C model's correction F without its dated terms
//! (steps and drifts), which are added after it ([`crate::invert::model_correction`]).
//! A version-5 file is read where that changes nothing (not variant C, or no dated term) and
//! refused where it would change its reconstructions.

mod validate;

use crate::effects::{Effect, MAX_EFFECTS};
use crate::mogi::Stations;
use crate::nn::{Layer, MAX_LAYERS};
use crate::quant::LeF32;
use crate::rtm::bands::Packed;
use crate::rtm::{Fixed, Geometry, N_BANDS};
use crate::Error;
use serde::{Deserialize, Serialize};

/// The first four bytes of every model file.
pub const MAGIC: [u8; 4] = *b"MAGC";
/// The format version this build reads and writes.
pub const VERSION: u16 = 6;

/// The oldest format version this build reads, where it means what it meant then.
pub const OLDEST_VERSION: u16 = 5;
/// Largest station network the compiled core accepts.
pub const MAX_STATIONS: usize = 32;
/// Largest number of physical variables (source parameters plus effect parameters).
pub const MAX_PARAMS: usize = 16;
/// Largest number of observed channels.
pub const MAX_OBS: usize = 3 * MAX_STATIONS;

/// Longest station name (bytes).
pub const MAX_NAME: usize = 8;

const HEADER: usize = 10;
// Bare-metal builds compute the CRC bit by bit (no 1 KiB table in flash; it runs once, at start-up);
// hosts use the byte table.
#[cfg(target_os = "none")]
const CRC: crc::Crc<u32, crc::NoTable> = crc::Crc::<u32, crc::NoTable>::new(&crc::CRC_32_ISO_HDLC);
#[cfg(not(target_os = "none"))]
const CRC: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// Which forward models a build links. [`Model::decode_for`], [`crate::invert::invert_at_for`] and
/// [`crate::invert::forward_for`] take it as a type parameter, so that a build that only inverts
/// GNSS networks ([`MogiOnly`], the firmware) carries no INFORM code; an RTM model given to it is
/// [`Error::WrongProblem`]. [`AnyProblem`] (what [`Model::decode`] and
/// [`crate::invert::invert_at`] use) links both.
pub trait Problems {
    /// Whether the RTM forward model (INFORM over the model's table rows) is linked.
    const RTM: bool;
}

/// Every problem kind: Mogi and RTM.
#[derive(Clone, Copy, Debug)]
pub enum AnyProblem {}

impl Problems for AnyProblem {
    const RTM: bool = true;
}

/// Mogi networks only (the firmware): RTM models are rejected with [`Error::WrongProblem`].
#[derive(Clone, Copy, Debug)]
pub enum MogiOnly {}

impl Problems for MogiOnly {
    const RTM: bool = false;
}

/// Station names borrowed from a model file: one string, the names separated by commas (each 1 to
/// [`MAX_NAME`] bytes, validated on decoding).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Names<'a>(#[serde(borrow)] pub &'a str);

impl<'a> Names<'a> {
    /// The names in order (none for an empty string).
    pub fn iter(&self) -> impl Iterator<Item = &'a str> {
        let s = self.0;
        s.split(',').filter(move |_| !s.is_empty())
    }
    /// Number of names (commas + 1, none for an empty string).
    pub fn len(&self) -> usize {
        if self.0.is_empty() {
            0
        } else {
            1 + self.0.bytes().filter(|&b| b == b',').count()
        }
    }

    /// Whether every name is 1 to [`MAX_NAME`] bytes long, or there are none (checked on bytes:
    /// no `str` searching, which keeps the firmware's decoding free of panic paths).
    pub fn well_formed(&self) -> bool {
        self.0.is_empty()
            || self
                .0
                .as_bytes()
                .split(|&b| b == b',')
                .all(|n| !n.is_empty() && n.len() <= MAX_NAME)
    }
    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
}

/// Which of the paper's models this is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Variant {
    /// Plain autoencoder: encoder → latent → decoder (no physics).
    A,
    /// Encoder → physical variables → forward model F.
    B,
    /// Encoder → physical variables → F → correction C (paper eq. 5).
    C,
}

/// The physical problem and its fixed description.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Problem<'a> {
    /// Mogi source under a GNSS network; observations are uₑ ×S, uₙ ×S, uᵥ ×S in mm.
    Mogi {
        /// Station positions, in the order of the observation channels.
        #[serde(borrow)]
        stations: Stations<'a>,
        /// Station names (e.g. `AV08`), in the same order; the data columns are `ux_<NAME>` etc.
        #[serde(borrow)]
        names: Names<'a>,
    },
    /// INFORM forest reflectance in Sentinel-2 bands; observations are the observed bands'
    /// reflectances, in band order. Self-contained: the table rows the observed bands need are
    /// carried in f32 (see [`crate::rtm::bands`]), about 81 KiB for the 11 bands of the S2 data.
    Rtm {
        /// Geometry mode of INFORM.
        #[serde(with = "GeometryDef")]
        geometry: Geometry,
        /// The inputs that are not learned (angles, pigments, soil, leaf angles, stem density).
        #[serde(with = "FixedDef")]
        fixed: Fixed,
        /// Bit `b` set when Sentinel-2 band `b` (order of [`crate::rtm::S2_BANDS`]) is observed.
        bands: u16,
        /// Spectral rows ([`crate::rtm::bands::ROW_WIDTH`] values each).
        #[serde(borrow)]
        spectral: LeF32<'a>,
        /// Resampling weights, one row per spectral row, one column per observed band.
        #[serde(borrow)]
        weights: LeF32<'a>,
        /// Beta leaf-angle table, 13 angles × distributions, angle-major.
        #[serde(borrow)]
        lidf_beta: LeF32<'a>,
    },
}

/// Serde mirror of [`Geometry`].
#[derive(Serialize, Deserialize)]
#[serde(remote = "Geometry")]
enum GeometryDef {
    Reference,
    Physical,
}

/// Serde mirror of [`Fixed`].
#[derive(Serialize, Deserialize)]
#[serde(remote = "Fixed")]
struct FixedDef {
    car: f64,
    anth: f64,
    cbrown: f64,
    cp: f64,
    cbc: f64,
    type_lidf: f64,
    lidf: f64,
    hspot: f64,
    psoil: f64,
    tts: f64,
    tto: f64,
    psi: f64,
    sd: f64,
}

impl<'a> Problem<'a> {
    /// A short name for messages.
    pub fn name(&self) -> &'static str {
        match self {
            Problem::Mogi { .. } => "mogi",
            Problem::Rtm { .. } => "rtm",
        }
    }

    /// The forward model of an RTM problem over its packed rows.
    pub fn packed(&self) -> Result<Packed<LeF32<'a>>, Error> {
        match *self {
            Problem::Rtm {
                bands,
                spectral,
                weights,
                lidf_beta,
                ..
            } => Packed::new(spectral, weights, lidf_beta, bands.count_ones() as usize),
            _ => Err(Error::WrongProblem),
        }
    }

    /// Indices (into [`crate::rtm::S2_BANDS`]) of the observed bands of an RTM problem, in
    /// order; `n` of the returned array are valid.
    pub fn band_indices(&self) -> ([usize; N_BANDS], usize) {
        let mut out = [0usize; N_BANDS];
        let mut n = 0;
        if let Problem::Rtm { bands, .. } = self {
            for (b, slot) in (0..N_BANDS)
                .filter(|b| bands & (1 << b) != 0)
                .zip(out.iter_mut())
            {
                *slot = b;
                n += 1;
            }
        }
        (out, n)
    }
}

pub use crate::effects::ILLUMINATION_NEEDS_PHYSICAL;

/// A decoded model. Weight arrays borrow from the bytes it was decoded from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Model<'a> {
    /// Paper variant.
    pub variant: Variant,
    /// Problem and geometry.
    #[serde(borrow)]
    pub problem: Problem<'a>,
    /// Observation mean (physical units) used to standardise: z = (x − mean) / scale.
    #[serde(borrow)]
    pub obs_mean: LeF32<'a>,
    /// Observation scale (physical units).
    #[serde(borrow)]
    pub obs_scale: LeF32<'a>,
    /// Physical variable bounds `[min, max]` (empty for variant A).
    pub bounds: heapless::Vec<[f32; 2], MAX_PARAMS>,
    /// Encoder layers; for B and C the last has a sigmoid and one output per variable.
    #[serde(borrow)]
    pub encoder: heapless::Vec<Layer<'a>, MAX_LAYERS>,
    /// Correction C (variant C) or decoder (variant A); empty for B.
    #[serde(borrow)]
    pub decoder: heapless::Vec<Layer<'a>, MAX_LAYERS>,
    /// Residual RMS (standardised units) above which an inversion is flagged; 0 disables.
    pub residual_threshold: f32,
    /// Declared effects added to F (their latent variables follow the source's in `bounds`).
    #[serde(borrow)]
    pub effects: heapless::Vec<Effect<'a>, MAX_EFFECTS>,
}

impl<'a> Model<'a> {
    /// Number of observed channels.
    pub fn n_obs(&self) -> usize {
        self.obs_mean.len()
    }

    /// Whether the model is a variant C with dated terms ([`Effect::is_dated`]), which are added
    /// after its correction ([`crate::invert::model_correction`]).
    pub fn dated_after_correction(&self) -> bool {
        self.variant == Variant::C && self.effects.iter().any(|e| e.is_dated())
    }

    /// Number of physical variables the encoder outputs (latent size for variant A).
    pub fn n_params(&self) -> usize {
        self.encoder.last().map_or(0, |l| l.rows as usize)
    }

    /// Whether inversions need the observation's date (a time-dependent effect is declared).
    pub fn needs_time(&self) -> bool {
        self.effects.iter().any(|e| e.needs_time())
    }

    /// Stations of a Mogi model.
    pub fn stations(&self) -> Result<Stations<'a>, Error> {
        match self.problem {
            Problem::Mogi { stations, .. } => Ok(stations),
            _ => Err(Error::WrongProblem),
        }
    }

    /// Decodes and validates a model file.
    ///
    /// ```
    /// use magic_core::model_file::Model;
    /// use magic_core::Error;
    /// assert_eq!(Model::decode(b"not a model"), Err(Error::BadMagic));
    /// assert_eq!(Model::decode(b"MAG"), Err(Error::Truncated));
    /// ```
    pub fn decode(bytes: &'a [u8]) -> Result<Model<'a>, Error> {
        Self::decode_for::<AnyProblem>(bytes)
    }

    /// [`Model::decode`] for a build that links only the forward models of `P` (see [`Problems`]):
    /// a model of another kind is [`Error::WrongProblem`].
    pub fn decode_for<P: Problems>(bytes: &'a [u8]) -> Result<Model<'a>, Error> {
        let mut model = Model::empty();
        model.decode_in_place::<P>(bytes)?;
        Ok(model)
    }

    /// A model with no layers, no stations and empty arrays (not valid): the starting point of
    /// [`Model::decode_in_place`].
    pub const fn empty() -> Model<'a> {
        Model {
            variant: Variant::A,
            problem: Problem::Mogi {
                stations: Stations(&[]),
                names: Names(""),
            },
            obs_mean: LeF32(&[]),
            obs_scale: LeF32(&[]),
            bounds: heapless::Vec::new(),
            encoder: heapless::Vec::new(),
            decoder: heapless::Vec::new(),
            residual_threshold: 0.0,
            effects: heapless::Vec::new(),
        }
    }

    /// [`Model::decode_for`] into `self` (e.g. a static on a microcontroller): the fields are
    /// decoded one by one and the layers, bounds and effects one element at a time straight into
    /// place, so that decoding needs a few hundred bytes of stack instead of several copies of the
    /// whole [`Model`]. The format is exactly the derived (postcard) one, which host tests check.
    /// On error `self` holds no valid model.
    pub fn decode_in_place<P: Problems>(&mut self, bytes: &'a [u8]) -> Result<(), Error> {
        let (version, body) = Self::checked_body(bytes)?;
        self.decode_body(body).map_err(|_| Error::Decode)?;
        if version < VERSION && self.dated_after_correction() {
            // Written when C saw the dated terms too: this build would reconstruct otherwise.
            return Err(Error::UnsupportedVersion {
                found: version,
                supported: VERSION,
            });
        }
        self.validate_for::<P>()
    }

    /// The postcard body of a model file after checking its magic, version, length and CRC.
    fn checked_body(bytes: &'a [u8]) -> Result<(u16, &'a [u8]), Error> {
        let n = bytes.len().min(4);
        if bytes.get(..n) != MAGIC.get(..n) {
            return Err(Error::BadMagic);
        }
        let Some(&[_, _, _, _, v0, v1, l0, l1, l2, l3]) = bytes.first_chunk::<HEADER>() else {
            return Err(Error::Truncated);
        };
        if bytes.len() < HEADER + 4 {
            return Err(Error::Truncated);
        }
        let version = u16::from_le_bytes([v0, v1]);
        if !(OLDEST_VERSION..=VERSION).contains(&version) {
            return Err(Error::UnsupportedVersion {
                found: version,
                supported: VERSION,
            });
        }
        let body_len = u32::from_le_bytes([l0, l1, l2, l3]) as usize;
        let end = HEADER.checked_add(body_len).ok_or(Error::Truncated)?;
        let total = end.checked_add(4).ok_or(Error::Truncated)?;
        if bytes.len() < total {
            return Err(Error::Truncated);
        }
        if bytes.len() > total {
            return Err(Error::SizeMismatch {
                what: "model file bytes",
                expected: total,
                found: bytes.len(),
            });
        }
        let (Some(content), Some(&[c0, c1, c2, c3])) = (bytes.get(..end), bytes.get(end..total))
        else {
            return Err(Error::Truncated);
        };
        let stored = u32::from_le_bytes([c0, c1, c2, c3]);
        let computed = CRC.checksum(content);
        if stored != computed {
            return Err(Error::CrcMismatch { stored, computed });
        }
        Ok((version, content.get(HEADER..).ok_or(Error::Truncated)?))
    }

    /// Decodes the fields of the body in the order of the struct (postcard's derived format:
    /// fields in order, sequences as a varint length then the elements).
    fn decode_body(&mut self, body: &'a [u8]) -> Result<(), postcard::Error> {
        use serde::Deserialize;
        let mut de = postcard::Deserializer::from_bytes(body);
        self.variant = Variant::deserialize(&mut de)?;
        self.problem = Problem::deserialize(&mut de)?;
        self.obs_mean = LeF32::deserialize(&mut de)?;
        self.obs_scale = LeF32::deserialize(&mut de)?;
        decode_seq(&mut de, &mut self.bounds)?;
        decode_seq(&mut de, &mut self.encoder)?;
        decode_seq(&mut de, &mut self.decoder)?;
        self.residual_threshold = f32::deserialize(&mut de)?;
        decode_seq(&mut de, &mut self.effects)?;
        if !de.finalize()?.is_empty() {
            return Err(postcard::Error::DeserializeBadEncoding);
        }
        Ok(())
    }

    /// The geometry mode of an RTM model.
    pub fn rtm_geometry(&self) -> Result<Geometry, Error> {
        match self.problem {
            Problem::Rtm { geometry, .. } => Ok(geometry),
            _ => Err(Error::WrongProblem),
        }
    }

    /// Serialises into `buf`, returning the number of bytes written.
    pub fn encode(&self, buf: &mut [u8]) -> Result<usize, Error> {
        if buf.len() < HEADER + 4 {
            return Err(Error::BufferTooSmall { needed: HEADER + 4 });
        }
        let cap = buf.len();
        let body_len = postcard::to_slice(self, &mut buf[HEADER..])
            .map_err(|_| Error::BufferTooSmall { needed: cap + 1 })?
            .len();
        let end = HEADER + body_len;
        if buf.len() < end + 4 {
            return Err(Error::BufferTooSmall { needed: end + 4 });
        }
        buf[..4].copy_from_slice(&MAGIC);
        buf[4..6].copy_from_slice(&VERSION.to_le_bytes());
        buf[6..10].copy_from_slice(&(body_len as u32).to_le_bytes());
        let crc = CRC.checksum(&buf[..end]);
        buf[end..end + 4].copy_from_slice(&crc.to_le_bytes());
        Ok(end + 4)
    }
}

/// Decodes a postcard sequence (varint length, then the elements) into `out`, element by element.
fn decode_seq<'de, T: Deserialize<'de>, const N: usize>(
    de: &mut postcard::Deserializer<'de, postcard::de_flavors::Slice<'de>>,
    out: &mut heapless::Vec<T, N>,
) -> Result<(), postcard::Error> {
    // A sequence's length is a varint, the encoding of a u32 (lengths here are far below 2³²).
    let n = u32::deserialize(&mut *de)? as usize;
    out.clear();
    for _ in 0..n {
        out.push(T::deserialize(&mut *de)?)
            .map_err(|_| postcard::Error::DeserializeBadEncoding)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mogi;

    #[test]
    fn names_split_on_commas() {
        let n = Names("AV08,AKGG,X");
        assert_eq!(n.len(), 3);
        assert!(n.iter().eq(["AV08", "AKGG", "X"]));
        assert_eq!(Names("").len(), 0);
        assert!(Names("").is_empty());
        assert_eq!(Names("A,,B").iter().filter(|s| s.is_empty()).count(), 1);
    }

    #[test]
    fn in_place_decoding_matches_the_derived_format() {
        use crate::nn::{Layer, Weights};
        let mut st = [0u8; 2 * mogi::STATION_BYTES];
        let net = [
            mogi::Station {
                x_km: 1.0,
                y_km: -2.0,
                z_km: 0.1,
            },
            mogi::Station {
                x_km: 3.5,
                y_km: 0.25,
                z_km: 0.3,
            },
        ];
        Stations::encode(&net, &mut st).unwrap();
        let f = |v: &[f32]| -> [u8; 4 * 49] {
            let mut b = [0u8; 4 * 49];
            for (c, x) in b.chunks_exact_mut(4).zip(v.iter().cycle()) {
                c.copy_from_slice(&x.to_le_bytes());
            }
            b
        };
        let (w, ones, coef) = (f(&[0.1, -0.2, 0.3]), f(&[1.0]), f(&[0.5, 0.25]));
        let mut bounds = heapless::Vec::new();
        for b in [[-1.0f32, 1.0], [-1.0, 1.0], [1.0, 9.0], [-2.0, 2.0]] {
            bounds.push(b).unwrap();
        }
        for _ in 0..3 {
            bounds.push([-5.0, 5.0]).unwrap();
        }
        let mut encoder = heapless::Vec::new();
        encoder
            .push(Layer {
                rows: 7,
                cols: 6,
                act: crate::nn::Activation::Sigmoid,
                weights: Weights::F32 {
                    w: LeF32(&w[..4 * 42]),
                    bias: LeF32(&w[..4 * 7]),
                },
            })
            .unwrap();
        let mut effects = heapless::Vec::new();
        effects.push(Effect::CommonMode).unwrap();
        effects
            .push(Effect::Seasonal {
                coef: LeF32(&coef[..4 * 24]),
            })
            .unwrap();
        let model = Model {
            variant: Variant::B,
            problem: Problem::Mogi {
                stations: Stations(&st),
                names: Names("AV08,AKGG"),
            },
            obs_mean: LeF32(&w[..4 * 6]),
            obs_scale: LeF32(&ones[..4 * 6]),
            bounds,
            encoder,
            decoder: heapless::Vec::new(),
            residual_threshold: 2.5,
            effects,
        };
        model.validate().unwrap();
        let mut buf = [0u8; 1024];
        let n = model.encode(&mut buf).unwrap();
        let derived: Model<'_> = postcard::from_bytes(&buf[HEADER..n - 4]).unwrap();
        let decoded = Model::decode(&buf[..n]).unwrap();
        assert_eq!(decoded, derived);
        assert_eq!(decoded, model);
        // Trailing bytes inside the body and truncated bodies are decoding errors.
        let mut longer = [0u8; 1024];
        longer[..n - 4].copy_from_slice(&buf[..n - 4]);
        let mut m = Model::empty();
        assert!(m.decode_body(&buf[HEADER..n - 5]).is_err());
        assert!(m.decode_body(&longer[HEADER..n - 3]).is_err());
    }

    #[test]
    fn a_mogi_only_build_rejects_rtm_models() {
        let one = 1.0f32.to_le_bytes();
        let model = Model {
            variant: Variant::B,
            problem: Problem::Rtm {
                geometry: Geometry::Reference,
                fixed: Fixed::default(),
                bands: 1,
                spectral: LeF32(&[]),
                weights: LeF32(&[]),
                lidf_beta: LeF32(&[]),
            },
            obs_mean: LeF32(&one),
            obs_scale: LeF32(&one),
            bounds: heapless::Vec::new(),
            encoder: heapless::Vec::new(),
            decoder: heapless::Vec::new(),
            residual_threshold: 0.0,
            effects: heapless::Vec::new(),
        };
        assert_eq!(model.validate_for::<MogiOnly>(), Err(Error::WrongProblem));
        assert_ne!(model.validate(), Err(Error::WrongProblem));
    }
}
