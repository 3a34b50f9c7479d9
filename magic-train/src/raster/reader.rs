//! Reading a TIFF by windows of rows, whatever its layout.
//!
//! The `tiff` crate decodes one chunk (strip or tile) at a time, for every layout it supports:
//! striped or tiled, deflate, LZW, zstd or uncompressed, classic or BigTIFF. Its `read_image`
//! returns only the first plane of a band-interleaved file, so [`Raster`] never calls it: it
//! computes which chunks of which planes cover the rows asked for, decodes them with
//! `read_chunk`, and keeps the decoded chunks of the current chunk row until the window moves
//! past them. Memory is bounded by one row of chunks (the tile height × the image width × the
//! bands), not by the image.
//!
//! Every size the file declares is checked before it is used (the crate panics on a chunk index
//! past the end), and any error names the file.

use super::geo::GeoRef;
use anyhow::{anyhow, bail, Context, Result};
use std::collections::HashMap;
use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};
use tiff::decoder::{ChunkType, Decoder, DecodingResult, Limits};
use tiff::tags::{PlanarConfiguration, SampleFormat, Tag};
use tiff::ColorType;

/// Largest chunk (strip or tile) decoded, in bytes: a limit for the decoder's buffers, far above
/// any real strip or tile (Sentinel-2 COGs: 1 024² × 2 bytes).
pub const MAX_CHUNK_BYTES: usize = 256 << 20;

/// Largest width or height accepted (a Sentinel-2 tile is 10 980).
pub const MAX_SIDE: u32 = 1 << 20;

/// The sample types read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SampleKind {
    /// Unsigned integers (8, 16 or 32 bits): digital numbers.
    Unsigned(u8),
    /// Signed integers (8, 16 or 32 bits): digital numbers.
    Signed(u8),
    /// IEEE floats (32 or 64 bits): reflectance.
    Float(u8),
}

impl SampleKind {
    /// Whether the samples are integers (digital numbers).
    pub fn is_integer(self) -> bool {
        !matches!(self, SampleKind::Float(_))
    }
}

impl std::fmt::Display for SampleKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SampleKind::Unsigned(b) => write!(f, "{b}-bit unsigned integer"),
            SampleKind::Signed(b) => write!(f, "{b}-bit signed integer"),
            SampleKind::Float(b) => write!(f, "{b}-bit float"),
        }
    }
}

/// One TIFF file open for reading by rows.
pub struct Raster {
    path: PathBuf,
    dec: Decoder<BufReader<File>>,
    /// Columns, rows.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Samples per pixel.
    pub bands: u16,
    /// Sample type.
    pub kind: SampleKind,
    /// One plane per band.
    pub planar: bool,
    /// Tiled (else striped).
    pub tiled: bool,
    /// Chunk width and height.
    pub chunk: (u32, u32),
    /// The no-data value of the GDAL_NODATA tag, if any.
    pub nodata: Option<f64>,
    /// The georeferencing tags.
    pub geo: GeoRef,
    across: u32,
    per_plane: u32,
    /// Decoded chunks of the current chunk row(s), by chunk index.
    cache: HashMap<u32, DecodingResult>,
}

/// Largest number of bands (samples per pixel) accepted.
pub const MAX_BANDS: u16 = 1024;

/// A `tiff` error with the file named (the decoder's message cut to a readable length: some
/// list every sample's bit depth).
fn err(path: &Path, what: &str, e: impl std::fmt::Display) -> anyhow::Error {
    let mut m = e.to_string();
    if m.len() > 300 {
        let cut = (0..=300)
            .rev()
            .find(|&i| m.is_char_boundary(i))
            .unwrap_or(0);
        m.truncate(cut);
        m.push('…');
    }
    anyhow!("{}: {what}: {m}", path.display())
}

impl Raster {
    /// Opens `path` and checks that its layout can be read: one image of at least one row and
    /// column, 8/16/32-bit integer or 32/64-bit float samples, every chunk present.
    pub fn open(path: &Path) -> Result<Raster> {
        let f = File::open(path).with_context(|| format!("{}: cannot open", path.display()))?;
        let mut limits = Limits::default();
        limits.decoding_buffer_size = MAX_CHUNK_BYTES;
        limits.intermediate_buffer_size = MAX_CHUNK_BYTES;
        let mut dec = Decoder::new(BufReader::new(f))
            .map_err(|e| err(path, "not a readable TIFF", e))?
            .with_limits(limits);
        let (width, height) = dec
            .dimensions()
            .map_err(|e| err(path, "no image size", e))?;
        if width == 0 || height == 0 || width > MAX_SIDE || height > MAX_SIDE {
            bail!(
                "{}: image of {width}×{height} pixels (expected 1 to {MAX_SIDE} on each side)",
                path.display()
            );
        }
        let (bits, bands, kind) = sample_layout(&mut dec, path)?;
        let planar = match dec
            .find_tag_unsigned::<u16>(Tag::PlanarConfiguration)
            .map_err(|e| err(path, "bad PlanarConfiguration tag", e))?
            .and_then(PlanarConfiguration::from_u16)
        {
            Some(PlanarConfiguration::Planar) => bands > 1,
            _ => false,
        };
        let (tiled, chunk) = chunk_layout(&mut dec, path, (width, height), bits, bands, planar)?;
        let across = width.div_ceil(chunk.0);
        let per_plane = across * height.div_ceil(chunk.1);
        let planes = if planar { bands as u32 } else { 1 };
        check_chunk_tables(&mut dec, path, tiled, per_plane as u64 * planes as u64)?;
        let nodata = gdal_nodata(&mut dec, path)?;
        let geo = GeoRef::read(&mut dec).map_err(|e| err(path, "bad GeoTIFF tags", e))?;
        Ok(Raster {
            path: path.to_path_buf(),
            dec,
            width,
            height,
            bands,
            kind,
            planar,
            tiled,
            chunk,
            nodata,
            geo,
            across,
            per_plane,
            cache: HashMap::new(),
        })
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Reads band `band` (0-based sample index) over rows `y0..y0 + rows` and columns
    /// `x0..x0 + out.len() / rows`, as raw sample values in f64, row after row, into `out`.
    /// Chunks above `y0` are dropped from the cache (call with increasing `y0`).
    pub fn read_band(
        &mut self,
        band: u16,
        x0: u32,
        y0: u32,
        rows: u32,
        out: &mut [f64],
    ) -> Result<()> {
        let cols = (out.len() as u32).checked_div(rows).unwrap_or(0);
        if band >= self.bands
            || rows == 0
            || cols == 0
            || out.len() != (rows * cols) as usize
            || x0.checked_add(cols).is_none_or(|e| e > self.width)
            || y0.checked_add(rows).is_none_or(|e| e > self.height)
        {
            bail!(
                "{}: window x {x0} + {cols}, y {y0} + {rows}, band {} outside the {}×{} image of {} bands",
                self.path.display(),
                band + 1,
                self.width,
                self.height,
                self.bands
            );
        }
        let (cw, ch) = self.chunk;
        let first_row = y0 / ch;
        self.cache
            .retain(|&i, _| (i % self.per_plane) / self.across >= first_row);
        let plane = if self.planar { band as u32 } else { 0 };
        let stride = if self.planar { 1 } else { self.bands as usize };
        let sample = if self.planar { 0 } else { band as usize };
        for cy in first_row..=(y0 + rows - 1) / ch {
            for cx in x0 / cw..=(x0 + cols - 1) / cw {
                let idx = plane * self.per_plane + cy * self.across + cx;
                if !self.cache.contains_key(&idx) {
                    let d = self.dec.read_chunk(idx).map_err(|e| {
                        err(
                            &self.path,
                            &format!(
                                "cannot decode {} {idx} (the file is truncated or corrupt)",
                                if self.tiled { "tile" } else { "strip" }
                            ),
                            e,
                        )
                    })?;
                    self.cache.insert(idx, d);
                }
                let data = &self.cache[&idx];
                // The chunk's own width (tiles at the right edge may be cut).
                let (tx0, ty0) = (cx * cw, cy * ch);
                let data_w = if self.tiled {
                    cw.min(self.width - tx0)
                } else {
                    self.width
                };
                let data_h = ch.min(self.height - ty0);
                let need = data_w as usize * data_h as usize * stride;
                let len = result_len(data);
                if len < need {
                    bail!(
                        "{}: chunk {idx} decoded to {len} samples, {need} expected",
                        self.path.display()
                    );
                }
                let row_w = data_w;
                let (ry0, ry1) = (y0.max(ty0), (y0 + rows).min(ty0 + data_h));
                let (rx0, rx1) = (x0.max(tx0), (x0 + cols).min(tx0 + data_w));
                for y in ry0..ry1 {
                    let src = ((y - ty0) * row_w + (rx0 - tx0)) as usize * stride + sample;
                    let dst = ((y - y0) * cols + (rx0 - x0)) as usize;
                    copy(data, src, stride, &mut out[dst..dst + (rx1 - rx0) as usize]);
                }
            }
        }
        Ok(())
    }
}

/// The file's samples: bits per sample, samples per pixel (bands) and their type, checked to be
/// one stack of bands of one supported type.
fn sample_layout(dec: &mut Decoder<BufReader<File>>, path: &Path) -> Result<(u8, u16, SampleKind)> {
    let color = dec
        .colortype()
        .map_err(|e| err(path, "unsupported pixel layout", e))?;
    let (bits, bands) = match color {
        ColorType::Gray(b) => (b, 1),
        ColorType::Multiband {
            bit_depth,
            num_samples,
        } => (bit_depth, num_samples),
        ColorType::RGB(b) => (b, 3),
        ColorType::RGBA(b) => (b, 4),
        other => bail!(
            "{}: colour type {other:?} is not a stack of bands (expected grey or multi-band samples)",
            path.display()
        ),
    };
    // One SampleFormat per sample (or one for all); mixed formats are not a stack of bands.
    let formats = dec
        .find_tag_unsigned_vec::<u16>(Tag::SampleFormat)
        .map_err(|e| err(path, "bad SampleFormat tag", e))?
        .unwrap_or_else(|| vec![1]);
    if bands == 0 || bands > MAX_BANDS {
        bail!(
            "{}: {bands} samples per pixel (expected 1 to {MAX_BANDS} bands)",
            path.display()
        );
    }
    let format = formats.first().copied().unwrap_or(1);
    if formats.iter().any(|&f| f != format) {
        bail!(
            "{}: samples of different formats ({formats:?}); expected one sample type for every band",
            path.display()
        );
    }
    let kind = match (SampleFormat::from_u16(format), bits) {
        (Some(SampleFormat::Uint), 8 | 16 | 32) => SampleKind::Unsigned(bits),
        (Some(SampleFormat::Int), 8 | 16 | 32) => SampleKind::Signed(bits),
        (Some(SampleFormat::IEEEFP), 32 | 64) => SampleKind::Float(bits),
        _ => bail!(
            "{}: unsupported sample type (SampleFormat {format}, {bits} bits): expected 8-, 16- or 32-bit integers or 32- or 64-bit floats",
            path.display()
        ),
    };
    Ok((bits, bands, kind))
}

/// Whether the image is tiled, and its chunk (tile or strip) width and height, checked against
/// [`MAX_SIDE`] and [`MAX_CHUNK_BYTES`].
fn chunk_layout(
    dec: &mut Decoder<BufReader<File>>,
    path: &Path,
    (width, height): (u32, u32),
    bits: u8,
    bands: u16,
    planar: bool,
) -> Result<(bool, (u32, u32))> {
    let tiled = dec.get_chunk_type() == ChunkType::Tile;
    let chunk = if tiled {
        let tw = dec
            .get_tag_u32(Tag::TileWidth)
            .map_err(|e| err(path, "bad TileWidth", e))?;
        let th = dec
            .get_tag_u32(Tag::TileLength)
            .map_err(|e| err(path, "bad TileLength", e))?;
        (tw, th)
    } else {
        let rps = dec
            .find_tag_unsigned::<u32>(Tag::RowsPerStrip)
            .map_err(|e| err(path, "bad RowsPerStrip", e))?
            .unwrap_or(height);
        (width, rps.min(height))
    };
    if chunk.0 == 0 || chunk.1 == 0 || chunk.0 > MAX_SIDE || chunk.1 > MAX_SIDE {
        bail!(
            "{}: chunks of {}×{} pixels (expected 1 to {MAX_SIDE} on each side)",
            path.display(),
            chunk.0,
            chunk.1
        );
    }
    let chunk_bytes =
        chunk.0 as u64 * chunk.1 as u64 * (bits as u64 / 8) * if planar { 1 } else { bands as u64 };
    if chunk_bytes > MAX_CHUNK_BYTES as u64 {
        bail!(
            "{}: one {} holds {chunk_bytes} bytes (at most {MAX_CHUNK_BYTES} are decoded at once)",
            path.display(),
            if tiled { "tile" } else { "strip" }
        );
    }
    Ok((tiled, chunk))
}

/// Checks that the offset and byte-count tables list at least the `expected` chunks (the
/// decoder panics on a chunk index past their end).
fn check_chunk_tables(
    dec: &mut Decoder<BufReader<File>>,
    path: &Path,
    tiled: bool,
    expected: u64,
) -> Result<()> {
    let offsets = if tiled {
        Tag::TileOffsets
    } else {
        Tag::StripOffsets
    };
    let counts = if tiled {
        Tag::TileByteCounts
    } else {
        Tag::StripByteCounts
    };
    for t in [offsets, counts] {
        let n = dec
            .get_tag_u64_vec(t)
            .map_err(|e| err(path, &format!("bad {t:?} tag"), e))?
            .len() as u64;
        if n < expected {
            bail!(
                "{}: {n} entries in {t:?} for {expected} {}s: the file is truncated or corrupt",
                path.display(),
                if tiled { "tile" } else { "strip" }
            );
        }
    }
    Ok(())
}

/// The no-data value of the GDAL_NODATA tag (a number or `nan`), if the file has one.
fn gdal_nodata(dec: &mut Decoder<BufReader<File>>, path: &Path) -> Result<Option<f64>> {
    Ok(match dec.find_tag(Tag::GdalNodata) {
        Ok(Some(tiff::decoder::ifd::Value::Ascii(s))) => {
            let s = s.trim_matches(char::from(0)).trim();
            match s.parse::<f64>() {
                Ok(v) => Some(v),
                Err(_) if s.eq_ignore_ascii_case("nan") => Some(f64::NAN),
                Err(_) => bail!("{}: GDAL_NODATA `{s}` is not a number", path.display()),
            }
        }
        _ => None,
    })
}

fn result_len(d: &DecodingResult) -> usize {
    match d {
        DecodingResult::U8(v) => v.len(),
        DecodingResult::U16(v) => v.len(),
        DecodingResult::U32(v) => v.len(),
        DecodingResult::U64(v) => v.len(),
        DecodingResult::F16(v) => v.len(),
        DecodingResult::F32(v) => v.len(),
        DecodingResult::F64(v) => v.len(),
        DecodingResult::I8(v) => v.len(),
        DecodingResult::I16(v) => v.len(),
        DecodingResult::I32(v) => v.len(),
        DecodingResult::I64(v) => v.len(),
    }
}

/// Copies `out.len()` samples starting at `src`, every `stride`-th, as f64.
fn copy(d: &DecodingResult, src: usize, stride: usize, out: &mut [f64]) {
    macro_rules! take {
        ($v:expr) => {
            for (o, x) in out.iter_mut().zip($v.iter().skip(src).step_by(stride)) {
                *o = *x as f64;
            }
        };
    }
    match d {
        DecodingResult::U8(v) => take!(v),
        DecodingResult::U16(v) => take!(v),
        DecodingResult::U32(v) => take!(v),
        DecodingResult::U64(v) => take!(v),
        DecodingResult::F16(v) => {
            for (o, x) in out.iter_mut().zip(v.iter().skip(src).step_by(stride)) {
                *o = f64::from(x.to_f32());
            }
        }
        DecodingResult::F32(v) => take!(v),
        DecodingResult::F64(v) => take!(v),
        DecodingResult::I8(v) => take!(v),
        DecodingResult::I16(v) => take!(v),
        DecodingResult::I32(v) => take!(v),
        DecodingResult::I64(v) => take!(v),
    }
}
