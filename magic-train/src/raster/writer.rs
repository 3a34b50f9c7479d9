//! A streaming TIFF writer: strips written as rows arrive, the directory at the end.
//!
//! The `tiff` crate's encoder writes strips one at a time (`write_strip`) but compresses only in
//! `write_data`, which takes the whole image; its sample count comes from a compile-time colour
//! type and it writes pixel-interleaved images only. A map of 20 float bands of a 10 980² tile
//! (9.6 GB uncompressed) must be written window by window, so this module writes the (simple)
//! TIFF structure itself (TIFF 6.0, BigTIFF): little-endian, one image, strips of
//! [`TiffSpec::rows_per_strip`] rows, band-interleaved (one plane per band, `PlanarConfiguration
//! = 2`) or pixel-interleaved, uncompressed or deflate (`Compression = 8`, each strip compressed
//! on its own, in parallel), with any extra tags (GeoTIFF keys, GDAL metadata and no-data). The
//! strip offsets and byte counts are kept in memory (16 bytes per strip) and written with the
//! directory after the last strip; the header's pointer to the directory is patched last.

use anyhow::{bail, Context, Result};
use rayon::prelude::*;
use std::io::{Seek, SeekFrom, Write};

/// TIFF field types used here.
#[derive(Clone, Debug, PartialEq)]
pub enum TagValue {
    /// ASCII text (a NUL is appended).
    Ascii(String),
    /// 16-bit unsigned integers.
    Short(Vec<u16>),
    /// 32-bit unsigned integers.
    Long(Vec<u32>),
    /// 64-bit IEEE floats.
    Double(Vec<f64>),
}

impl TagValue {
    fn type_code(&self) -> u16 {
        match self {
            TagValue::Ascii(_) => 2,
            TagValue::Short(_) => 3,
            TagValue::Long(_) => 4,
            TagValue::Double(_) => 12,
        }
    }
    fn count(&self) -> u64 {
        match self {
            TagValue::Ascii(s) => s.len() as u64 + 1,
            TagValue::Short(v) => v.len() as u64,
            TagValue::Long(v) => v.len() as u64,
            TagValue::Double(v) => v.len() as u64,
        }
    }
    fn bytes(&self) -> Vec<u8> {
        match self {
            TagValue::Ascii(s) => s.bytes().chain([0]).collect(),
            TagValue::Short(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            TagValue::Long(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            TagValue::Double(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
        }
    }
}

/// Sample types the writer produces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sample {
    /// 8-bit unsigned.
    U8,
    /// 16-bit unsigned.
    U16,
    /// 32-bit float.
    F32,
}

impl Sample {
    /// Bytes per sample.
    pub fn size(self) -> usize {
        match self {
            Sample::U8 => 1,
            Sample::U16 => 2,
            Sample::F32 => 4,
        }
    }
    fn format(self) -> u16 {
        match self {
            Sample::U8 | Sample::U16 => 1,
            Sample::F32 => 3,
        }
    }
}

/// What to write.
#[derive(Clone, Debug)]
pub struct TiffSpec {
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Samples per pixel.
    pub bands: u16,
    /// Sample type.
    pub sample: Sample,
    /// One plane per band (`true`, GDAL's `INTERLEAVE=BAND`) or pixel-interleaved.
    pub planar: bool,
    /// Rows per strip.
    pub rows_per_strip: u32,
    /// Deflate each strip.
    pub deflate: bool,
    /// BigTIFF (64-bit offsets); `None`: BigTIFF when the uncompressed image could pass 4 GiB.
    pub big: Option<bool>,
    /// Extra tags (number, value), e.g. the GeoTIFF tags.
    pub tags: Vec<(u16, TagValue)>,
}

impl TiffSpec {
    fn uncompressed_bytes(&self) -> u64 {
        self.width as u64 * self.height as u64 * self.bands as u64 * self.sample.size() as u64
    }
    fn strips_per_plane(&self) -> u32 {
        self.height.div_ceil(self.rows_per_strip.max(1))
    }
}

/// Writes a TIFF strip by strip; see the module documentation.
pub struct StripWriter<W: Write + Seek> {
    out: W,
    spec: TiffSpec,
    big: bool,
    /// Rows written so far (every plane advances together).
    rows_done: u32,
    /// Offset and byte count per strip, in TIFF order (plane-major for band-interleaved).
    offsets: Vec<u64>,
    counts: Vec<u64>,
    pos: u64,
}

impl<W: Write + Seek> StripWriter<W> {
    /// Writes the header and prepares for the strips.
    pub fn new(mut out: W, spec: TiffSpec) -> Result<Self> {
        if spec.width == 0 || spec.height == 0 || spec.bands == 0 || spec.rows_per_strip == 0 {
            bail!(
                "an image of {}×{} pixels, {} bands, {} rows per strip cannot be written",
                spec.width,
                spec.height,
                spec.bands,
                spec.rows_per_strip
            );
        }
        let big = spec
            .big
            .unwrap_or(spec.uncompressed_bytes() > (u32::MAX as u64) - (256 << 20));
        let header: Vec<u8> = if big {
            let mut h = b"II".to_vec();
            h.extend(43u16.to_le_bytes());
            h.extend(8u16.to_le_bytes());
            h.extend(0u16.to_le_bytes());
            h.extend(0u64.to_le_bytes());
            h
        } else {
            let mut h = b"II".to_vec();
            h.extend(42u16.to_le_bytes());
            h.extend(0u32.to_le_bytes());
            h
        };
        out.write_all(&header)?;
        let n =
            spec.strips_per_plane() as usize * if spec.planar { spec.bands as usize } else { 1 };
        Ok(StripWriter {
            out,
            big,
            rows_done: 0,
            offsets: vec![0; n],
            counts: vec![0; n],
            pos: header.len() as u64,
            spec,
        })
    }

    /// Whether the file is a BigTIFF.
    pub fn is_big(&self) -> bool {
        self.big
    }

    /// Writes the next `rows` rows. `data` holds them as little-endian samples: band after band
    /// (`bands × rows × width`) for a band-interleaved file, pixel after pixel for a
    /// pixel-interleaved one. `rows` must be a whole number of strips, or reach the last row.
    pub fn write_rows(&mut self, rows: u32, data: &[u8]) -> Result<()> {
        let s = &self.spec;
        let (w, b, size) = (s.width as usize, s.bands as usize, s.sample.size());
        let rps = s.rows_per_strip;
        if rows == 0 {
            return Ok(());
        }
        let end = self.rows_done.checked_add(rows).filter(|&e| e <= s.height);
        let Some(end) = end else {
            bail!(
                "{} rows written after {} of {}",
                rows,
                self.rows_done,
                s.height
            );
        };
        if !rows.is_multiple_of(rps) && end != s.height {
            bail!("{rows} rows are not a whole number of {rps}-row strips");
        }
        let expected = rows as usize * w * b * size;
        if data.len() != expected {
            bail!(
                "{} bytes given for {rows} rows of {w} pixels × {b} bands ({expected} expected)",
                data.len()
            );
        }
        // The strips of this block: (index in the TIFF, bytes).
        let first = self.rows_done / rps;
        let n_strips = rows.div_ceil(rps);
        let planes = if s.planar { b } else { 1 };
        let per_plane = s.strips_per_plane() as usize;
        let plane_bytes = rows as usize * w * size * if s.planar { 1 } else { b };
        let row_bytes = w * size * if s.planar { 1 } else { b };
        let jobs: Vec<(usize, &[u8])> = (0..planes)
            .flat_map(|p| {
                (0..n_strips).map(move |k| {
                    let r0 = (k * rps) as usize;
                    let r1 = ((k + 1) * rps).min(rows) as usize;
                    let at = p * plane_bytes;
                    (
                        p * per_plane + (first + k) as usize,
                        &data[at + r0 * row_bytes..at + r1 * row_bytes],
                    )
                })
            })
            .collect();
        let deflate = s.deflate;
        let encoded: Vec<(usize, std::borrow::Cow<[u8]>)> = jobs
            .into_par_iter()
            .map(|(i, raw)| {
                let bytes = if deflate {
                    let mut e = flate2::write::ZlibEncoder::new(
                        Vec::with_capacity(raw.len() / 2),
                        flate2::Compression::new(DEFLATE_LEVEL),
                    );
                    e.write_all(raw)?;
                    std::borrow::Cow::Owned(e.finish()?)
                } else {
                    std::borrow::Cow::Borrowed(raw)
                };
                Ok((i, bytes))
            })
            .collect::<std::io::Result<_>>()?;
        for (i, bytes) in encoded {
            self.offsets[i] = self.pos;
            self.counts[i] = bytes.len() as u64;
            self.out.write_all(&bytes)?;
            self.pos += bytes.len() as u64;
        }
        self.rows_done = end;
        Ok(())
    }

    /// Writes the directory and patches the header; returns the writer.
    pub fn finish(mut self) -> Result<W> {
        let s = &self.spec;
        if self.rows_done != s.height {
            bail!("only {} of {} rows were written", self.rows_done, s.height);
        }
        if !self.big && self.pos > u32::MAX as u64 {
            bail!("the image passed 4 GiB in a classic TIFF: write a BigTIFF");
        }
        let tags = self.directory_tags()?;
        let entries = self.write_values(&tags)?;
        self.write_directory(&entries)?;
        self.out.flush()?;
        Ok(self.out)
    }

    /// The directory's tags, sorted by number: the image's own and the spec's extra ones (tag,
    /// value, and for a BigTIFF's strip offsets and byte counts their LONG8 bytes).
    fn directory_tags(&self) -> Result<Vec<DirTag>> {
        let s = &self.spec;
        let b = s.bands as usize;
        let offsets = |v: &[u64]| -> TagValue {
            if self.big {
                TagValue::Double(vec![]) // placeholder, replaced below
            } else {
                TagValue::Long(v.iter().map(|&x| x as u32).collect())
            }
        };
        let mut tags: Vec<DirTag> = vec![
            (256, TagValue::Long(vec![s.width]), None),
            (257, TagValue::Long(vec![s.height]), None),
            (
                258,
                TagValue::Short(vec![8 * s.sample.size() as u16; b]),
                None,
            ),
            (
                259,
                TagValue::Short(vec![if s.deflate { 8 } else { 1 }]),
                None,
            ),
            (262, TagValue::Short(vec![1]), None),
            (273, offsets(&self.offsets), None),
            (277, TagValue::Short(vec![s.bands]), None),
            (278, TagValue::Long(vec![s.rows_per_strip]), None),
            (279, offsets(&self.counts), None),
            (
                284,
                TagValue::Short(vec![if s.planar { 2 } else { 1 }]),
                None,
            ),
            (339, TagValue::Short(vec![s.sample.format(); b]), None),
        ];
        if b > 1 {
            tags.push((338, TagValue::Short(vec![0; b - 1]), None));
        }
        if self.big {
            // LONG8 arrays for the strip offsets and byte counts.
            let long8 = |v: &[u64]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
            for t in tags.iter_mut() {
                if t.0 == 273 {
                    t.2 = Some(long8(&self.offsets));
                } else if t.0 == 279 {
                    t.2 = Some(long8(&self.counts));
                }
            }
        }
        for (tag, v) in &s.tags {
            if tags.iter().any(|t| t.0 == *tag) {
                bail!("tag {tag} given twice");
            }
            tags.push((*tag, v.clone(), None));
        }
        tags.sort_by_key(|t| t.0);
        Ok(tags)
    }

    /// Writes the values that do not fit in their directory entry (word aligned); returns the
    /// entries: tag, type, count and the inline value or the offset of the written one.
    fn write_values(&mut self, tags: &[DirTag]) -> Result<Vec<DirEntry>> {
        let inline = if self.big { 8 } else { 4 };
        let mut entries = Vec::with_capacity(tags.len());
        for (tag, v, raw) in tags {
            let (ty, count, bytes) = match raw {
                Some(r) => (16u16, (r.len() / 8) as u64, r.clone()),
                None => (v.type_code(), v.count(), v.bytes()),
            };
            let field = if bytes.len() <= inline {
                let mut f = bytes.clone();
                f.resize(inline, 0);
                f
            } else {
                if self.pos % 2 == 1 {
                    self.out.write_all(&[0])?;
                    self.pos += 1;
                }
                let at = self.pos;
                self.out.write_all(&bytes)?;
                self.pos += bytes.len() as u64;
                if self.big {
                    at.to_le_bytes().to_vec()
                } else {
                    u32::try_from(at)
                        .context("a classic TIFF cannot hold more than 4 GiB")?
                        .to_le_bytes()
                        .to_vec()
                }
            };
            entries.push((*tag, ty, count, field));
        }
        Ok(entries)
    }

    /// Writes the directory (word aligned) after the values and points the header at it.
    fn write_directory(&mut self, entries: &[DirEntry]) -> Result<()> {
        if self.pos % 2 == 1 {
            self.out.write_all(&[0])?;
            self.pos += 1;
        }
        let ifd = self.pos;
        let mut d = Vec::new();
        if self.big {
            d.extend((entries.len() as u64).to_le_bytes());
        } else {
            d.extend((entries.len() as u16).to_le_bytes());
        }
        for (tag, ty, count, field) in entries {
            d.extend(tag.to_le_bytes());
            d.extend(ty.to_le_bytes());
            if self.big {
                d.extend(count.to_le_bytes());
            } else {
                d.extend((*count as u32).to_le_bytes());
            }
            d.extend(field);
        }
        d.extend(vec![0u8; if self.big { 8 } else { 4 }]);
        self.out.write_all(&d)?;
        if self.big {
            self.out.seek(SeekFrom::Start(8))?;
            self.out.write_all(&ifd.to_le_bytes())?;
        } else {
            let at = u32::try_from(ifd).context("a classic TIFF cannot hold more than 4 GiB")?;
            self.out.seek(SeekFrom::Start(4))?;
            self.out.write_all(&at.to_le_bytes())?;
        }
        Ok(())
    }
}

/// A directory tag: number, value, and the raw LONG8 bytes that replace the value (BigTIFF strip
/// offsets and byte counts).
type DirTag = (u16, TagValue, Option<Vec<u8>>);

/// A directory entry: tag, type, count, and the value's bytes or the offset where it is written.
type DirEntry = (u16, u16, u64, Vec<u8>);

/// zlib level of the deflated strips: the fastest (a map of a 10 980² tile deflates 9.6 GB, and
/// its NaN bands compress to almost nothing at any level).
pub const DEFLATE_LEVEL: u32 = 1;

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Cursor;
    use tiff::decoder::{Decoder, DecodingResult};

    fn image(spec: TiffSpec, data: &[u8], block: u32) -> Vec<u8> {
        let (w, b, size) = (spec.width as usize, spec.bands as usize, spec.sample.size());
        let (h, planar) = (spec.height, spec.planar);
        let mut wr = StripWriter::new(Cursor::new(Vec::new()), spec).unwrap();
        let mut r0 = 0;
        while r0 < h {
            let r1 = (r0 + block).min(h);
            // Gather rows r0..r1 of each plane (band-interleaved) or the pixel rows.
            let mut buf = Vec::new();
            if planar {
                for p in 0..b {
                    let plane = &data[p * h as usize * w * size..];
                    buf.extend(&plane[r0 as usize * w * size..r1 as usize * w * size]);
                }
            } else {
                let row = w * b * size;
                buf.extend(&data[r0 as usize * row..r1 as usize * row]);
            }
            wr.write_rows(r1 - r0, &buf).unwrap();
            r0 = r1;
        }
        wr.finish().unwrap().into_inner()
    }

    #[test]
    fn the_tiff_crate_reads_back_what_is_written() {
        let (w, h, b) = (7u32, 11u32, 3u16);
        let values: Vec<f32> = (0..w * h * b as u32)
            .map(|i| i as f32 * 0.5 - 3.0)
            .collect();
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        for (planar, deflate, big) in [
            (true, true, false),
            (true, false, true),
            (false, true, true),
            (false, false, false),
        ] {
            let spec = TiffSpec {
                width: w,
                height: h,
                bands: b,
                sample: Sample::F32,
                planar,
                rows_per_strip: 4,
                deflate,
                big: Some(big),
                tags: vec![(42113, TagValue::Ascii("nan".into()))],
            };
            let file = image(spec, &bytes, 8);
            let mut d = Decoder::new(Cursor::new(file)).unwrap();
            assert_eq!(d.dimensions().unwrap(), (w, h));
            assert_eq!(
                d.get_tag_ascii_string(tiff::tags::Tag::GdalNodata).unwrap(),
                "nan"
            );
            // Every sample of every band, chunk by chunk.
            let strips = h.div_ceil(4);
            for p in 0..b as u32 {
                for k in 0..strips {
                    let idx = if planar { p * strips + k } else { k };
                    let DecodingResult::F32(v) = d.read_chunk(idx).unwrap() else {
                        panic!("not f32")
                    };
                    for (j, x) in v.iter().enumerate() {
                        let (row, col, band) = if planar {
                            (k * 4 + j as u32 / w, j as u32 % w, p)
                        } else {
                            let px = j as u32 / b as u32;
                            (k * 4 + px / w, px % w, j as u32 % b as u32)
                        };
                        let want = if planar {
                            values[((band * h + row) * w + col) as usize]
                        } else {
                            values[((row * w + col) * b as u32 + band) as usize]
                        };
                        assert_eq!(*x, want, "planar {planar} deflate {deflate} big {big}");
                    }
                }
            }
        }
    }

    #[test]
    fn bad_calls_are_errors() {
        let spec = TiffSpec {
            width: 4,
            height: 4,
            bands: 1,
            sample: Sample::U16,
            planar: true,
            rows_per_strip: 2,
            deflate: false,
            big: None,
            tags: vec![],
        };
        let mut wr = StripWriter::new(Cursor::new(Vec::new()), spec.clone()).unwrap();
        assert!(wr.write_rows(1, &[0; 8]).is_err(), "not a whole strip");
        assert!(wr.write_rows(2, &[0; 15]).is_err(), "wrong length");
        assert!(wr.write_rows(6, &[0; 48]).is_err(), "past the end");
        wr.write_rows(2, &[0; 16]).unwrap();
        assert!(wr.finish().is_err(), "rows missing");
        let zero = TiffSpec { width: 0, ..spec };
        assert!(StripWriter::new(Cursor::new(Vec::new()), zero).is_err());
    }
}
