//! The one error type of the core: a plain enum, `Copy`, with a human-readable `Display`.

use core::fmt;

/// Everything that can go wrong in the core. No function of this crate panics on input; each
/// fallible step returns one of these.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Error {
    /// An input value was NaN or infinite where a finite number was needed.
    NonFinite {
        /// Which input.
        what: &'static str,
        /// Index of the offending element.
        index: usize,
    },
    /// A value lies outside the range the operation accepts.
    OutOfRange {
        /// Which value.
        what: &'static str,
    },
    /// A slice, table or layer has the wrong length.
    SizeMismatch {
        /// What was measured.
        what: &'static str,
        /// The length required.
        expected: usize,
        /// The length found.
        found: usize,
    },
    /// The bytes do not start with the model-file magic `MAGC`.
    BadMagic,
    /// The model file's format version is not the one this build reads.
    UnsupportedVersion {
        /// Version in the file.
        found: u16,
        /// Version this build reads.
        supported: u16,
    },
    /// The model was made for another problem (e.g. an RTM model given to the Mogi firmware).
    WrongProblem,
    /// The CRC-32 stored in the file does not match its contents (corruption, flipped bits).
    CrcMismatch {
        /// CRC stored at the end of the file.
        stored: u32,
        /// CRC computed over the contents.
        computed: u32,
    },
    /// The bytes end before the structure does.
    Truncated,
    /// The contents could not be decoded (the serialised structure is malformed).
    Decode,
    /// A count lies outside what the compiled core accepts (e.g. more observation channels than
    /// [`crate::model_file::MAX_OBS`], an empty network).
    CountOutOfRange {
        /// What was counted.
        what: &'static str,
        /// The count found.
        found: usize,
        /// The smallest count accepted.
        min: u16,
        /// The largest count accepted.
        max: u16,
    },
    /// Layer `layer` (from 0) of a model's encoder or decoder is unusable.
    InvalidLayer {
        /// The network it belongs to.
        net: Net,
        /// Its index in the network, from 0.
        layer: u8,
        /// What is wrong with it.
        fault: LayerFault,
    },
    /// The bound `[min, max]` of physical variable `index` (from 0, in the model's variable
    /// order: the source's, then the effects') is unusable.
    InvalidBound {
        /// Index of the variable.
        index: u8,
        /// What is wrong with it.
        fault: BoundFault,
    },
    /// A declared effect does not fit the model.
    InvalidEffect {
        /// The effect's family (`Effect::family`: `seasonal`, `band_offset`, …).
        family: &'static str,
        /// What is wrong with it.
        fault: EffectFault,
    },
    /// The model decodes but is inconsistent in a way no other variant names (checks that the
    /// validated decoding makes unreachable, kept as guards).
    InvalidModel(&'static str),
    /// A buffer the caller provided is too small.
    BufferTooSmall {
        /// Bytes or elements needed.
        needed: usize,
    },
    /// Too few channels were observed to determine the unknowns.
    TooFewObservations {
        /// Channels observed.
        observed: usize,
        /// Channels needed at least.
        needed: usize,
    },
}

/// The two networks of a model.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Net {
    /// The encoder E (observations to variables, or to the latent code of variant A).
    Encoder,
    /// The correction C of variant C, or the decoder of variant A (the model's `decoder`).
    Decoder,
}

/// What is wrong with a layer ([`Error::InvalidLayer`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LayerFault {
    /// Rows or columns are zero or above [`crate::nn::MAX_WIDTH`].
    Size,
    /// One of its arrays has the wrong number of bytes.
    Bytes {
        /// Which array.
        array: LayerArray,
        /// Bytes required.
        expected: usize,
        /// Bytes found.
        found: usize,
    },
    /// Its input count is not the previous layer's output count (or the network's input).
    Inputs {
        /// Inputs required.
        expected: u16,
        /// Inputs found.
        found: u16,
    },
    /// An f32 weight or bias is not finite.
    NonFiniteWeight,
    /// The int8 weights' alignment padding is longer than 3 bytes.
    Padding,
    /// The int8 input or output activation scale is not positive and finite.
    ActivationScale,
    /// An int8 weight scale is not positive and finite.
    WeightScale,
    /// An int8 weight is −128 (the symmetric range is ±127).
    WeightMinus128,
    /// A requantisation shift lies outside −30..=30.
    Shift,
    /// A requantisation multiplier is negative.
    NegativeMultiplier,
    /// An int8 layer's output scale differs from the next int8 layer's input scale.
    ScaleChain,
    /// A sigmoid between two int8 layers (not supported).
    SigmoidBetweenInt8,
    /// The encoder's last layer of variant B or C is not an f32 sigmoid layer.
    Head,
}

/// The arrays of a layer ([`LayerFault::Bytes`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LayerArray {
    /// Weights.
    Weights,
    /// Biases.
    Bias,
    /// int8 weight scales.
    Scales,
    /// int8 requantisation multipliers.
    Multipliers,
    /// int8 requantisation shifts.
    Shifts,
}

/// What is wrong with a bound ([`Error::InvalidBound`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BoundFault {
    /// Not finite, or the minimum is not below the maximum.
    Empty,
    /// The minimum must be positive (a source depth; INFORM's variables).
    NotPositive,
}

/// What is wrong with a declared effect ([`Error::InvalidEffect`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EffectFault {
    /// A forest-spectra effect (illumination, band offsets) in a GNSS model.
    NotGnss,
    /// A GNSS effect in a forest-spectra model, which declares only illumination and band
    /// offsets.
    NotRtm,
    /// Illumination in a model of the reference geometry, which hands INFORM cosines where
    /// angles are expected.
    NeedsPhysicalGeometry,
    /// Its parameters are not finite, out of range, or sized for another network or band set.
    Parameters,
}

/// `Ok` when a length is the one required, else [`Error::SizeMismatch`].
pub(crate) fn check_len(what: &'static str, expected: usize, found: usize) -> Result<(), Error> {
    if found == expected {
        Ok(())
    } else {
        Err(Error::SizeMismatch {
            what,
            expected,
            found,
        })
    }
}

/// Where [`Error::describe`] writes a message: text pieces and numbers, so that a target
/// without `core::fmt` (the firmware keeps its flash small) prints the same words as `Display`.
pub trait MessageSink {
    /// Appends text.
    fn text(&mut self, s: &str);
    /// Appends an unsigned integer in decimal.
    fn number(&mut self, n: u32);
    /// Appends a 32-bit value as `0x` and eight hex digits (like `{:#010x}`).
    fn hex(&mut self, n: u32);
}

/// Sizes beyond `u32` are printed saturated (no model or buffer of this crate comes near).
fn n32(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

impl Error {
    /// Writes the human-readable message, the one `Display` prints, piece by piece.
    ///
    /// ```
    /// use magic_core::{Error, MessageSink};
    /// struct S(String);
    /// impl MessageSink for S {
    ///     fn text(&mut self, s: &str) { self.0.push_str(s) }
    ///     fn number(&mut self, n: u32) { self.0.push_str(&n.to_string()) }
    ///     fn hex(&mut self, n: u32) { self.0.push_str(&format!("{n:#010x}")) }
    /// }
    /// let e = Error::SizeMismatch { what: "observations", expected: 36, found: 35 };
    /// let mut s = S(String::new());
    /// e.describe(&mut s);
    /// assert_eq!(s.0, "observations: expected 36, found 35");
    /// assert_eq!(s.0, e.to_string());
    /// ```
    pub fn describe<S: MessageSink + ?Sized>(&self, s: &mut S) {
        match *self {
            Error::NonFinite { what, index } => {
                indexed(s, what, n32(index), "] is not a finite number")
            }
            Error::OutOfRange { what } => pair(s, what, " is out of range"),
            Error::SizeMismatch {
                what,
                expected,
                found,
            } => {
                s.text(what);
                expected_found(s, n32(expected), n32(found));
            }
            Error::UnsupportedVersion { found, supported } => {
                around(
                    s,
                    "model format version ",
                    found.into(),
                    " is not supported",
                );
                around(s, " (this build reads ", supported.into(), ")");
            }
            Error::CrcMismatch { stored, computed } => {
                s.text("model file is corrupt: CRC stored ");
                s.hex(stored);
                s.text(", computed ");
                s.hex(computed);
            }
            Error::CountOutOfRange {
                what,
                found,
                min,
                max,
            } => {
                s.text(what);
                around(s, ": ", n32(found), " is outside ");
                around(s, "", min.into(), "..=");
                s.number(max.into());
            }
            Error::InvalidLayer { net, layer, fault } => {
                let net = match net {
                    Net::Encoder => "invalid model: encoder",
                    Net::Decoder => "invalid model: decoder",
                };
                indexed(s, net, layer.into(), "]: ");
                fault.describe(s);
            }
            Error::InvalidBound { index, fault } => {
                let rule = match fault {
                    BoundFault::Empty => "] not finite with min < max",
                    BoundFault::NotPositive => "] needs a positive minimum",
                };
                indexed(s, "invalid model: bound", index.into(), rule);
            }
            Error::InvalidEffect { family, fault } => {
                let why = match fault {
                    EffectFault::NotGnss => ": belongs to RTM models",
                    EffectFault::NotRtm => ": not an RTM effect",
                    EffectFault::NeedsPhysicalGeometry => ": needs the physical geometry",
                    EffectFault::Parameters => ": bad parameters",
                };
                pair(s, "invalid model: effect ", family);
                s.text(why);
            }
            Error::InvalidModel(why) => pair(s, "invalid model: ", why),
            Error::BufferTooSmall { needed } => {
                around(s, "buffer too small: ", n32(needed), " needed")
            }
            Error::TooFewObservations { observed, needed } => {
                around(s, "too few observed channels: ", n32(observed), " observed");
                around(s, ", at least ", n32(needed), " needed");
            }
            Error::BadMagic | Error::WrongProblem | Error::Truncated | Error::Decode => {
                s.text(self.fixed_text())
            }
        }
    }

    /// The message of a variant without values.
    fn fixed_text(&self) -> &'static str {
        match self {
            Error::BadMagic => "not a magic model file (bad magic bytes)",
            Error::WrongProblem => "model is for a different problem kind",
            Error::Truncated => "model file is truncated",
            Error::Decode => "model file contents are malformed",
            _ => "",
        }
    }
}

impl LayerFault {
    /// Writes the message (the part after the layer) piece by piece.
    pub fn describe<S: MessageSink + ?Sized>(&self, s: &mut S) {
        match *self {
            LayerFault::Bytes {
                array,
                expected,
                found,
            } => {
                s.text(match array {
                    LayerArray::Weights => "weight bytes",
                    LayerArray::Bias => "bias bytes",
                    LayerArray::Scales => "scale bytes",
                    LayerArray::Multipliers => "multiplier bytes",
                    LayerArray::Shifts => "shift bytes",
                });
                expected_found(s, n32(expected), n32(found));
            }
            LayerFault::Inputs { expected, found } => {
                s.text("inputs");
                expected_found(s, expected.into(), found.into());
            }
            _ => s.text(self.fixed_text()),
        }
    }

    /// The message of a fault without values.
    fn fixed_text(&self) -> &'static str {
        match self {
            LayerFault::Size => "size zero or above 256",
            LayerFault::NonFiniteWeight => "f32 weight not finite",
            LayerFault::Padding => "int8 padding over 3 bytes",
            LayerFault::ActivationScale => "activation scale not positive",
            LayerFault::WeightScale => "weight scale not positive",
            LayerFault::WeightMinus128 => "int8 weight -128",
            LayerFault::Shift => "shift outside -30..=30",
            LayerFault::NegativeMultiplier => "negative multiplier",
            LayerFault::ScaleChain => "output scale is not the next input scale",
            LayerFault::SigmoidBetweenInt8 => "sigmoid between int8 layers",
            LayerFault::Head => "head must be f32 sigmoid",
            _ => "",
        }
    }
}

// The shapes the messages share, written once each: the firmware links every message, and
// typed errors cost it flash per call site of the sink (measured: about 1 KB for these variants).

/// `a`, then `b`.
fn pair<S: MessageSink + ?Sized>(s: &mut S, a: &str, b: &str) {
    s.text(a);
    s.text(b);
}

/// `before`, the number `n`, then `after`.
#[inline(never)]
fn around<S: MessageSink + ?Sized>(s: &mut S, before: &str, n: u32, after: &str) {
    s.text(before);
    s.number(n);
    s.text(after);
}

/// `what[i` then `rest` (which closes the bracket).
fn indexed<S: MessageSink + ?Sized>(s: &mut S, what: &str, i: u32, rest: &str) {
    s.text(what);
    around(s, "[", i, rest);
}

/// `: expected E, found F`.
#[inline(never)]
fn expected_found<S: MessageSink + ?Sized>(s: &mut S, expected: u32, found: u32) {
    around(s, ": expected ", expected, ", found ");
    s.number(found);
}

/// `Display` through a `describe` function: one text for every target.
pub(crate) struct FmtSink<'a, 'b> {
    f: &'a mut fmt::Formatter<'b>,
    result: fmt::Result,
}

impl<'a, 'b> FmtSink<'a, 'b> {
    /// Runs `describe` into the formatter.
    pub(crate) fn display(
        f: &'a mut fmt::Formatter<'b>,
        describe: impl FnOnce(&mut Self),
    ) -> fmt::Result {
        let mut sink = FmtSink { f, result: Ok(()) };
        describe(&mut sink);
        sink.result
    }
}

impl MessageSink for FmtSink<'_, '_> {
    fn text(&mut self, s: &str) {
        if self.result.is_ok() {
            self.result = self.f.write_str(s);
        }
    }
    fn number(&mut self, n: u32) {
        if self.result.is_ok() {
            self.result = write!(self.f, "{n}");
        }
    }
    fn hex(&mut self, n: u32) {
        if self.result.is_ok() {
            self.result = write!(self.f, "{n:#010x}");
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        FmtSink::display(f, |s| self.describe(s))
    }
}

#[cfg(feature = "std")]
extern crate std;

#[cfg(feature = "std")]
impl std::error::Error for Error {}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::{BoundFault, EffectFault, Error, LayerArray, LayerFault, Net};
    use std::string::ToString;

    /// Every message, as users see it.
    #[test]
    fn messages() {
        let cases = [
            (
                Error::NonFinite {
                    what: "observations",
                    index: 7,
                },
                "observations[7] is not a finite number",
            ),
            (Error::OutOfRange { what: "depth" }, "depth is out of range"),
            (
                Error::SizeMismatch {
                    what: "stations",
                    expected: 12,
                    found: 11,
                },
                "stations: expected 12, found 11",
            ),
            (Error::BadMagic, "not a magic model file (bad magic bytes)"),
            (
                Error::UnsupportedVersion {
                    found: 9,
                    supported: 5,
                },
                "model format version 9 is not supported (this build reads 5)",
            ),
            (Error::WrongProblem, "model is for a different problem kind"),
            (
                Error::CrcMismatch {
                    stored: 0xDEAD_BEEF,
                    computed: 0x1F,
                },
                "model file is corrupt: CRC stored 0xdeadbeef, computed 0x0000001f",
            ),
            (Error::Truncated, "model file is truncated"),
            (Error::Decode, "model file contents are malformed"),
            (Error::InvalidModel("no layers"), "invalid model: no layers"),
            (
                Error::CountOutOfRange {
                    what: "observations",
                    found: 97,
                    min: 1,
                    max: 96,
                },
                "observations: 97 is outside 1..=96",
            ),
            (
                Error::InvalidLayer {
                    net: Net::Decoder,
                    layer: 1,
                    fault: LayerFault::Bytes {
                        array: LayerArray::Shifts,
                        expected: 36,
                        found: 35,
                    },
                },
                "invalid model: decoder[1]: shift bytes: expected 36, found 35",
            ),
            (
                Error::InvalidLayer {
                    net: Net::Encoder,
                    layer: 0,
                    fault: LayerFault::Size,
                },
                "invalid model: encoder[0]: size zero or above 256",
            ),
            (
                Error::InvalidLayer {
                    net: Net::Encoder,
                    layer: 2,
                    fault: LayerFault::Shift,
                },
                "invalid model: encoder[2]: shift outside -30..=30",
            ),
            (
                Error::InvalidLayer {
                    net: Net::Encoder,
                    layer: 3,
                    fault: LayerFault::Inputs {
                        expected: 16,
                        found: 32,
                    },
                },
                "invalid model: encoder[3]: inputs: expected 16, found 32",
            ),
            (
                Error::InvalidBound {
                    index: 2,
                    fault: BoundFault::NotPositive,
                },
                "invalid model: bound[2] needs a positive minimum",
            ),
            (
                Error::InvalidEffect {
                    family: "band_offset",
                    fault: EffectFault::Parameters,
                },
                "invalid model: effect band_offset: bad parameters",
            ),
            (
                Error::BufferTooSmall { needed: 300 },
                "buffer too small: 300 needed",
            ),
            (
                Error::TooFewObservations {
                    observed: 3,
                    needed: 4,
                },
                "too few observed channels: 3 observed, at least 4 needed",
            ),
            (
                Error::BufferTooSmall { needed: usize::MAX },
                "buffer too small: 4294967295 needed",
            ),
        ];
        for (e, want) in cases {
            assert_eq!(e.to_string(), want);
        }
    }

    /// Every layer and effect fault has a message of its own.
    #[test]
    fn fault_messages_are_distinct() {
        use std::collections::BTreeSet;
        use std::string::String;
        let layer = [
            LayerFault::Size,
            LayerFault::Bytes {
                array: LayerArray::Bias,
                expected: 4,
                found: 3,
            },
            LayerFault::Inputs {
                expected: 4,
                found: 3,
            },
            LayerFault::NonFiniteWeight,
            LayerFault::Padding,
            LayerFault::ActivationScale,
            LayerFault::WeightScale,
            LayerFault::WeightMinus128,
            LayerFault::Shift,
            LayerFault::NegativeMultiplier,
            LayerFault::ScaleChain,
            LayerFault::SigmoidBetweenInt8,
            LayerFault::Head,
        ];
        let effect = [
            EffectFault::NotGnss,
            EffectFault::NotRtm,
            EffectFault::NeedsPhysicalGeometry,
            EffectFault::Parameters,
        ];
        let bound = [BoundFault::Empty, BoundFault::NotPositive];
        let mut all: std::vec::Vec<String> = layer
            .iter()
            .map(|&fault| {
                Error::InvalidLayer {
                    net: Net::Encoder,
                    layer: 0,
                    fault,
                }
                .to_string()
            })
            .collect();
        all.extend(effect.iter().map(|&fault| {
            Error::InvalidEffect {
                family: "drift",
                fault,
            }
            .to_string()
        }));
        all.extend(
            bound
                .iter()
                .map(|&fault| Error::InvalidBound { index: 1, fault }.to_string()),
        );
        let distinct: BTreeSet<&String> = all.iter().collect();
        assert_eq!(distinct.len(), all.len());
        assert!(all
            .iter()
            .all(|m| m.len() > "invalid model: encoder[0]: ".len()));
    }
}
