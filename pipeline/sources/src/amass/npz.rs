//! NumPy `.npz` archives (a zip of `.npy` files, stored or deflated, as `np.savez` and
//! `np.savez_compressed` write them) read without trusting what they claim: every size in the
//! zip directory and every shape in an `.npy` header is checked against the bytes actually there
//! before anything is allocated for it.

use std::borrow::Cow;
use std::io::Read;

/// Why an archive or one of its arrays cannot be read. `key` is the array's name without `.npy`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NpzError {
    /// The bytes are not a zip archive, or its directory is cut short or inconsistent.
    #[error("not a readable .npz (zip) archive: {0}")]
    Archive(String),
    /// The archive has no array of that name.
    #[error("no array `{key}`")]
    Missing {
        /// The array's name.
        key: String,
    },
    /// The array's entry is damaged: cut short, a bad CRC, an unknown compression.
    #[error("array `{key}`: {message}")]
    Entry {
        /// The array's name.
        key: String,
        /// What is wrong.
        message: String,
    },
    /// The `.npy` header does not parse, or the values are of a type not read here.
    #[error("array `{key}`: {message}")]
    Npy {
        /// The array's name.
        key: String,
        /// What is wrong.
        message: String,
    },
    /// The header promises more values than the entry holds.
    #[error(
        "array `{key}`: shape {shape:?} needs {expected} bytes of values but the entry holds {found}"
    )]
    Truncated {
        /// The array's name.
        key: String,
        /// The shape the header gives.
        shape: Vec<u64>,
        /// Bytes the shape needs.
        expected: u64,
        /// Bytes there.
        found: u64,
    },
}

/// One array's entry in the archive's central directory.
#[derive(Debug, Clone)]
struct Entry {
    name: String,
    method: u16,
    crc: u32,
    compressed: u64,
    uncompressed: u64,
    local_offset: u64,
}

/// An open `.npz` archive over the bytes of its file.
#[derive(Debug)]
pub struct Npz<'a> {
    bytes: &'a [u8],
    entries: Vec<Entry>,
}

/// An array's values as stored, widened: floats to `f64`, integers to `i64`.
#[derive(Debug, Clone, PartialEq)]
pub enum Values {
    /// `f4` or `f8` values.
    Float(Vec<f64>),
    /// Signed or unsigned integers of 1 to 8 bytes (unsigned 8-byte values above `i64::MAX`
    /// become -1, the way SMPL's `kintree_table` marks the root).
    Int(Vec<i64>),
    /// A unicode (`U`) string.
    Text(String),
    /// A byte (`S`) string, decoded as UTF-8 (lossily).
    Bytes(String),
}

/// A decoded `.npy` array: its shape and values in C order.
#[derive(Debug, Clone, PartialEq)]
pub struct Array {
    /// The shape (`[]` for a scalar).
    pub shape: Vec<usize>,
    /// The values.
    pub values: Values,
}

impl Array {
    /// The values as floats (integers converted), or `None` for strings.
    pub fn floats(&self) -> Option<Cow<'_, [f64]>> {
        match &self.values {
            Values::Float(v) => Some(Cow::Borrowed(v)),
            Values::Int(v) => Some(Cow::Owned(v.iter().map(|&x| x as f64).collect())),
            _ => None,
        }
    }

    /// The dtype's kind as a word for messages.
    pub fn kind(&self) -> &'static str {
        match self.values {
            Values::Float(_) => "float",
            Values::Int(_) => "integer",
            Values::Text(_) => "str",
            Values::Bytes(_) => "bytes",
        }
    }
}

// Offsets come from the file: `at` may be anything, so the end is computed checked.
fn u16_at(b: &[u8], at: usize) -> Option<u16> {
    Some(u16::from_le_bytes(
        b.get(at..at.checked_add(2)?)?.try_into().ok()?,
    ))
}
fn u32_at(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(
        b.get(at..at.checked_add(4)?)?.try_into().ok()?,
    ))
}
fn u64_at(b: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(
        b.get(at..at.checked_add(8)?)?.try_into().ok()?,
    ))
}

const EOCD: u32 = 0x0605_4b50;
const ZIP64_LOCATOR: u32 = 0x0706_4b50;
const ZIP64_EOCD: u32 = 0x0606_4b50;
const CENTRAL: u32 = 0x0201_4b50;
const LOCAL: u32 = 0x0403_4b50;

impl<'a> Npz<'a> {
    /// Reads the archive's directory.
    pub fn new(bytes: &'a [u8]) -> Result<Npz<'a>, NpzError> {
        let bad = |m: &str| NpzError::Archive(m.to_string());
        // The end record is in the last 22 + 65,535 bytes (its comment is at most that long).
        let floor = bytes.len().saturating_sub(22 + 0xffff);
        let eocd = (floor..bytes.len().saturating_sub(21))
            .rev()
            .find(|&i| u32_at(bytes, i) == Some(EOCD))
            .ok_or_else(|| {
                bad("no end-of-directory record (the file is cut short or is not a zip)")
            })?;
        let mut count = u64::from(u16_at(bytes, eocd + 10).unwrap_or(0));
        let mut dir_size = u64::from(u32_at(bytes, eocd + 12).unwrap_or(0));
        let mut dir_offset = u64::from(u32_at(bytes, eocd + 16).unwrap_or(0));
        if eocd >= 20 && u32_at(bytes, eocd - 20) == Some(ZIP64_LOCATOR) {
            let at = u64_at(bytes, eocd - 12).ok_or_else(|| bad("zip64 locator cut short"))?;
            let at = usize::try_from(at).map_err(|_| bad("zip64 record offset out of range"))?;
            if u32_at(bytes, at) != Some(ZIP64_EOCD) {
                return Err(bad("the zip64 locator points at no zip64 end record"));
            }
            count = u64_at(bytes, at + 32).ok_or_else(|| bad("zip64 end record cut short"))?;
            dir_size = u64_at(bytes, at + 40).ok_or_else(|| bad("zip64 end record cut short"))?;
            dir_offset = u64_at(bytes, at + 48).ok_or_else(|| bad("zip64 end record cut short"))?;
        }
        let start = usize::try_from(dir_offset).unwrap_or(usize::MAX);
        let end = start.saturating_add(usize::try_from(dir_size).unwrap_or(usize::MAX));
        let directory = bytes
            .get(start..end)
            .ok_or_else(|| bad("the directory lies past the end of the file (cut short?)"))?;
        // Each directory record takes 46 bytes at least: a count beyond that is a lie.
        if count > (directory.len() / 46) as u64 {
            return Err(bad("the directory lists more entries than it has room for"));
        }
        let mut entries = Vec::with_capacity(count as usize);
        let mut at = 0usize;
        for _ in 0..count {
            if u32_at(directory, at) != Some(CENTRAL) {
                return Err(bad("a directory record is damaged"));
            }
            let field = |off: usize| u32_at(directory, at + off).unwrap_or(0);
            let half = |off: usize| usize::from(u16_at(directory, at + off).unwrap_or(0));
            let method = u16_at(directory, at + 10).unwrap_or(0);
            let crc = field(16);
            let mut compressed = u64::from(field(20));
            let mut uncompressed = u64::from(field(24));
            let (name_len, extra_len, comment_len) = (half(28), half(30), half(32));
            let mut local_offset = u64::from(field(42));
            let name_at = at + 46;
            let name = directory
                .get(name_at..name_at + name_len)
                .ok_or_else(|| bad("a directory record is cut short"))?;
            let extra = directory
                .get(name_at + name_len..name_at + name_len + extra_len)
                .ok_or_else(|| bad("a directory record is cut short"))?;
            // The zip64 extra field holds, in order, the sizes and offset whose 32-bit fields
            // are saturated.
            let mut e = 0;
            while e + 4 <= extra.len() {
                let id = u16_at(extra, e).unwrap_or(0);
                let len = usize::from(u16_at(extra, e + 2).unwrap_or(0));
                if id == 1 {
                    let mut v = e + 4;
                    for slot in [&mut uncompressed, &mut compressed, &mut local_offset] {
                        if *slot == u64::from(u32::MAX)
                            && let Some(x) = u64_at(extra, v)
                        {
                            *slot = x;
                            v += 8;
                        }
                    }
                }
                e += 4 + len;
            }
            entries.push(Entry {
                name: String::from_utf8_lossy(name).into_owned(),
                method,
                crc,
                compressed,
                uncompressed,
                local_offset,
            });
            at = name_at + name_len + extra_len + comment_len;
        }
        Ok(Npz { bytes, entries })
    }

    /// The arrays' names (entry names without `.npy`), in archive order.
    pub fn keys(&self) -> impl Iterator<Item = &str> {
        self.entries
            .iter()
            .map(|e| e.name.strip_suffix(".npy").unwrap_or(&e.name))
    }

    /// True when the archive has an array `key`.
    pub fn has(&self, key: &str) -> bool {
        self.keys().any(|k| k == key)
    }

    /// The raw bytes of array `key`'s `.npy` file, inflated and checked against its CRC.
    fn entry_bytes(&self, key: &str) -> Result<Cow<'a, [u8]>, NpzError> {
        let entry = self
            .entries
            .iter()
            .find(|e| e.name.strip_suffix(".npy").unwrap_or(&e.name) == key)
            .ok_or_else(|| NpzError::Missing {
                key: key.to_string(),
            })?;
        let damaged = |message: String| NpzError::Entry {
            key: key.to_string(),
            message,
        };
        let local = usize::try_from(entry.local_offset).unwrap_or(usize::MAX);
        if u32_at(self.bytes, local) != Some(LOCAL) {
            return Err(damaged("its local header is missing or damaged".into()));
        }
        let name_len = usize::from(u16_at(self.bytes, local + 26).unwrap_or(0));
        let extra_len = usize::from(u16_at(self.bytes, local + 28).unwrap_or(0));
        let data_at = local + 30 + name_len + extra_len;
        let data_end = usize::try_from(entry.compressed)
            .ok()
            .and_then(|n| data_at.checked_add(n));
        let data = data_end
            .and_then(|end| self.bytes.get(data_at..end))
            .ok_or_else(|| {
                damaged(format!(
                    "its {} bytes run past the end of the file (cut short?)",
                    entry.compressed
                ))
            })?;
        let raw: Cow<'a, [u8]> = match entry.method {
            0 => {
                if entry.uncompressed != entry.compressed {
                    return Err(damaged("stored sizes disagree".into()));
                }
                Cow::Borrowed(data)
            }
            8 => {
                // Grown as bytes come out, never sized by the declared length; one byte past it
                // tells a lying size.
                let mut out = Vec::new();
                flate2::read::DeflateDecoder::new(data)
                    .take(entry.uncompressed.saturating_add(1))
                    .read_to_end(&mut out)
                    .map_err(|e| damaged(format!("does not inflate: {e}")))?;
                if out.len() as u64 != entry.uncompressed {
                    return Err(damaged(format!(
                        "inflates to {} bytes, not the {} the directory gives",
                        out.len(),
                        entry.uncompressed
                    )));
                }
                Cow::Owned(out)
            }
            other => {
                return Err(damaged(format!(
                    "compression method {other} (only stored and deflate, as NumPy writes)"
                )));
            }
        };
        if crc32fast::hash(&raw) != entry.crc {
            return Err(damaged("CRC mismatch: the bytes are damaged".into()));
        }
        Ok(raw)
    }

    /// Array `key`, decoded.
    pub fn array(&self, key: &str) -> Result<Array, NpzError> {
        let raw = self.entry_bytes(key)?;
        parse_npy(key, &raw)
    }
}

/// The parts of an `.npy` header read here.
struct Header {
    descr: String,
    fortran: bool,
    shape: Vec<u64>,
}

fn parse_header(text: &str) -> Option<Header> {
    let value_of = |name: &str| -> Option<&str> {
        let at = text
            .find(&format!("'{name}'"))
            .or_else(|| text.find(&format!("\"{name}\"")))?;
        let rest = &text[at + name.len() + 2..];
        Some(rest.trim_start().strip_prefix(':')?.trim_start())
    };
    let descr = value_of("descr")?;
    let quote = descr.chars().next().filter(|c| *c == '\'' || *c == '"')?;
    let descr = descr[1..].split(quote).next()?.to_string();
    let fortran = value_of("fortran_order")?.starts_with("True");
    let shape = value_of("shape")?.strip_prefix('(')?;
    let shape = &shape[..shape.find(')')?];
    let shape = shape
        .split(',')
        .map(str::trim)
        .filter(|d| !d.is_empty())
        .map(|d| d.trim_end_matches(['L', 'l']).parse::<u64>().ok())
        .collect::<Option<Vec<u64>>>()?;
    Some(Header {
        descr,
        fortran,
        shape,
    })
}

/// Decodes the bytes of one `.npy` file (array `key`).
pub fn parse_npy(key: &str, bytes: &[u8]) -> Result<Array, NpzError> {
    let npy = |message: String| NpzError::Npy {
        key: key.to_string(),
        message,
    };
    let (header, data) = npy_header(bytes).map_err(|m| npy(m.into()))?;
    if header.fortran && header.shape.iter().filter(|&&d| d > 1).count() > 1 {
        return Err(npy("stored in Fortran order; expected C order".into()));
    }
    let count = header
        .shape
        .iter()
        .try_fold(1u64, |n, &d| n.checked_mul(d))
        .ok_or_else(|| npy(format!("shape {:?} overflows", header.shape)))?;
    let descr = header.descr.as_str();
    let dtype = Dtype::of(descr);
    let unreadable = || {
        npy(format!(
            "values of type `{descr}`; expected floats (`<f4`, `<f8`), integers or a string{}",
            if descr.contains('O') {
                " (this one is a pickled Python object)"
            } else {
                ""
            }
        ))
    };
    let (kind, width) = (dtype.kind, dtype.width);
    // A string's characters are its width; its count is one value.
    let (unit, values) = match kind {
        'U' => (4, count.saturating_mul(width)),
        'S' => (1, count.saturating_mul(width)),
        'f' if width == 4 || width == 8 => (width, count),
        'i' | 'u' if (1..=8).contains(&width) && width.is_power_of_two() => (width, count),
        'b' if width == 1 => (1, count),
        _ => return Err(unreadable()),
    };
    let expected = values
        .checked_mul(unit)
        .ok_or_else(|| npy(format!("shape {:?} overflows", header.shape)))?;
    if expected > data.len() as u64 {
        return Err(NpzError::Truncated {
            key: key.to_string(),
            shape: header.shape,
            expected,
            found: data.len() as u64,
        });
    }
    let values = dtype.decode(&data[..expected as usize]);
    let shape = header
        .shape
        .iter()
        .map(|&d| usize::try_from(d).unwrap_or(usize::MAX))
        .collect();
    Ok(Array { shape, values })
}

/// The parsed header of a `.npy` file and the data after it, or what is wrong.
fn npy_header(bytes: &[u8]) -> Result<(Header, &[u8]), &'static str> {
    let rest = bytes
        .strip_prefix(b"\x93NUMPY")
        .ok_or("not a NumPy .npy array (no magic string)")?;
    let (header_len, rest) = match rest {
        [1, _, a, b, rest @ ..] => (usize::from(u16::from_le_bytes([*a, *b])), rest),
        [2 | 3, _, a, b, c, d, rest @ ..] => (u32::from_le_bytes([*a, *b, *c, *d]) as usize, rest),
        _ => return Err("unknown .npy version"),
    };
    let header = rest.get(..header_len).ok_or("the header is cut short")?;
    let data = &rest[header_len..];
    let header = std::str::from_utf8(header)
        .ok()
        .and_then(parse_header)
        .ok_or("the header does not parse")?;
    Ok((header, data))
}

/// A `.npy` value type (`descr`): byte order, kind letter and width in bytes (characters for
/// a string).
struct Dtype {
    big_endian: bool,
    kind: char,
    width: u64,
}

impl Dtype {
    fn of(descr: &str) -> Dtype {
        let (order, rest) = match descr.as_bytes().first() {
            Some(b'<' | b'|' | b'=') => ('<', &descr[1..]),
            Some(b'>') => ('>', &descr[1..]),
            _ => ('<', descr),
        };
        let kind = rest.chars().next().unwrap_or('?');
        let width: u64 = rest.get(1..).and_then(|w| w.parse().ok()).unwrap_or(0);
        Dtype {
            big_endian: order == '>',
            kind,
            width,
        }
    }

    /// One value's bytes as an unsigned number in the file's byte order.
    fn word(&self, chunk: &[u8]) -> u64 {
        let mut b = [0u8; 8];
        if self.big_endian {
            for (i, x) in chunk.iter().rev().enumerate() {
                b[i] = *x;
            }
        } else {
            b[..chunk.len()].copy_from_slice(chunk);
        }
        u64::from_le_bytes(b)
    }

    /// The values of `data`, exactly the bytes of a readable type's values (checked by
    /// [`parse_npy`]).
    fn decode(&self, data: &[u8]) -> Values {
        let width = self.width;
        match self.kind {
            'f' if width == 8 => Values::Float(
                data.chunks_exact(8)
                    .map(|c| f64::from_bits(self.word(c)))
                    .collect(),
            ),
            'f' => Values::Float(
                data.chunks_exact(4)
                    .map(|c| f64::from(f32::from_bits(self.word(c) as u32)))
                    .collect(),
            ),
            'i' => {
                let bits = 64 - 8 * width as u32;
                Values::Int(
                    data.chunks_exact(width as usize)
                        .map(|c| ((self.word(c) << bits) as i64) >> bits)
                        .collect(),
                )
            }
            'u' | 'b' => Values::Int(
                data.chunks_exact(width as usize)
                    .map(|c| i64::try_from(self.word(c)).unwrap_or(-1))
                    .collect(),
            ),
            'U' => {
                let text: String = data
                    .chunks_exact(4)
                    .map(|c| self.word(c) as u32)
                    .take_while(|&c| c != 0)
                    .map(|c| char::from_u32(c).unwrap_or(char::REPLACEMENT_CHARACTER))
                    .collect();
                Values::Text(text)
            }
            _ => {
                let end = data.iter().position(|&b| b == 0).unwrap_or(data.len());
                Values::Bytes(String::from_utf8_lossy(&data[..end]).into_owned())
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn npy(descr: &str, shape: &str, data: &[u8]) -> Vec<u8> {
        let mut header =
            format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}");
        while (10 + header.len() + 1) % 64 != 0 {
            header.push(' ');
        }
        header.push('\n');
        let mut out = b"\x93NUMPY\x01\x00".to_vec();
        out.extend((header.len() as u16).to_le_bytes());
        out.extend(header.as_bytes());
        out.extend(data);
        out
    }

    #[test]
    fn values_decode_as_stored() {
        let floats: Vec<u8> = [1.5f32, -2.0]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let a = parse_npy("x", &npy("<f4", "(2,)", &floats)).unwrap();
        assert_eq!(a.values, Values::Float(vec![1.5, -2.0]));
        let ints: Vec<u8> = [u32::MAX, 0, 3]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let a = parse_npy("k", &npy("<u4", "(1, 3)", &ints)).unwrap();
        assert_eq!(a.values, Values::Int(vec![u32::MAX as i64, 0, 3]));
        assert_eq!(a.shape, vec![1, 3]);
        let ints: Vec<u8> = [-1i64, 7].iter().flat_map(|v| v.to_le_bytes()).collect();
        let a = parse_npy("k", &npy("<i8", "(2,)", &ints)).unwrap();
        assert_eq!(a.values, Values::Int(vec![-1, 7]));
        let text: Vec<u8> = "male\0\0"
            .chars()
            .flat_map(|c| (c as u32).to_le_bytes())
            .collect();
        let a = parse_npy("gender", &npy("<U6", "()", &text)).unwrap();
        assert_eq!(a.values, Values::Text("male".into()));
        let a = parse_npy("gender", &npy("|S6", "()", b"female")).unwrap();
        assert_eq!(a.values, Values::Bytes("female".into()));
    }

    #[test]
    fn a_shape_beyond_the_bytes_is_refused_before_allocation() {
        let err = parse_npy("poses", &npy("<f8", "(1000000000000, 156)", &[0u8; 16])).unwrap_err();
        assert!(matches!(err, NpzError::Truncated { .. }), "{err}");
        let err = parse_npy(
            "poses",
            &npy("<f8", "(18446744073709551615, 3)", &[0u8; 16]),
        )
        .unwrap_err();
        assert!(err.to_string().contains("overflows"), "{err}");
        let err = parse_npy("poses", &npy("|O", "(2,)", &[0u8; 16])).unwrap_err();
        assert!(err.to_string().contains("pickled"), "{err}");
    }

    /// A stored (uncompressed) zip of `(name, bytes)` entries, as `np.savez` writes one.
    fn zip(entries: &[(&str, Vec<u8>)]) -> Vec<u8> {
        let mut out = Vec::new();
        let mut directory = Vec::new();
        for (name, data) in entries {
            let offset = out.len() as u32;
            let crc = crc32fast::hash(data);
            let mut header = Vec::new();
            header.extend(LOCAL.to_le_bytes());
            header.extend([20, 0, 0, 0, 0, 0, 0, 0, 0, 0]);
            header.extend(crc.to_le_bytes());
            header.extend((data.len() as u32).to_le_bytes());
            header.extend((data.len() as u32).to_le_bytes());
            header.extend((name.len() as u16).to_le_bytes());
            header.extend(0u16.to_le_bytes());
            out.extend(&header);
            out.extend(name.as_bytes());
            out.extend(data);
            directory.extend(CENTRAL.to_le_bytes());
            directory.extend([20, 0, 20, 0, 0, 0, 0, 0, 0, 0, 0, 0]);
            directory.extend(crc.to_le_bytes());
            directory.extend((data.len() as u32).to_le_bytes());
            directory.extend((data.len() as u32).to_le_bytes());
            directory.extend((name.len() as u16).to_le_bytes());
            directory.extend([0u8; 12]);
            directory.extend(offset.to_le_bytes());
            directory.extend(name.as_bytes());
        }
        let at = out.len() as u32;
        out.extend(&directory);
        out.extend(EOCD.to_le_bytes());
        out.extend([0u8; 4]);
        out.extend((entries.len() as u16).to_le_bytes());
        out.extend((entries.len() as u16).to_le_bytes());
        out.extend((directory.len() as u32).to_le_bytes());
        out.extend(at.to_le_bytes());
        out.extend([0u8; 2]);
        out
    }

    #[test]
    fn an_archive_reads_and_every_damaged_byte_is_an_error_not_a_panic() {
        let poses: Vec<u8> = (0..12).flat_map(|i| (i as f64).to_le_bytes()).collect();
        let archive = zip(&[
            ("poses.npy", npy("<f8", "(2, 6)", &poses)),
            ("gender.npy", npy("|S4", "()", b"male")),
        ]);
        let npz = Npz::new(&archive).unwrap();
        assert_eq!(npz.keys().collect::<Vec<_>>(), ["poses", "gender"]);
        let a = npz.array("poses").unwrap();
        assert_eq!(a.shape, [2, 6]);
        assert_eq!(a.floats().unwrap()[11], 11.0);
        assert!(matches!(npz.array("trans"), Err(NpzError::Missing { .. })));
        // Every byte flipped, and every length cut: an error or a value, never a panic.
        for i in 0..archive.len() {
            for flip in [0x01u8, 0x80, 0xff] {
                let mut damaged = archive.clone();
                damaged[i] ^= flip;
                if let Ok(npz) = Npz::new(&damaged) {
                    let _ = npz.array("poses");
                    let _ = npz.array("gender");
                }
            }
            if let Ok(npz) = Npz::new(&archive[..i]) {
                let _ = npz.array("poses");
            }
        }
        // A value byte flipped is caught by the CRC, naming the key.
        let mut damaged = archive.clone();
        let at = archive.len() / 4;
        damaged[at] ^= 0x01;
        let err = Npz::new(&damaged).unwrap().array("poses").unwrap_err();
        assert!(err.to_string().contains("`poses`"), "{err}");
        // A local header offset at the end of the address space, given in a zip64 extra field.
        let one = zip(&[("poses.npy", npy("<f8", "(2, 6)", &poses))]);
        let dir = one.len() - 22 - (46 + "poses.npy".len());
        let mut far = one[..dir].to_vec();
        let mut record = one[dir..one.len() - 22].to_vec();
        record[30..32].copy_from_slice(&12u16.to_le_bytes());
        record[42..46].copy_from_slice(&u32::MAX.to_le_bytes());
        record.extend(1u16.to_le_bytes());
        record.extend(8u16.to_le_bytes());
        record.extend(u64::MAX.to_le_bytes());
        far.extend(&record);
        let mut end = one[one.len() - 22..].to_vec();
        end[12..16].copy_from_slice(&(record.len() as u32).to_le_bytes());
        far.extend(end);
        let npz = Npz::new(&far).unwrap();
        let err = npz.array("poses").unwrap_err();
        assert!(err.to_string().contains("local header"), "{err}");
    }

    #[test]
    fn garbage_is_an_archive_error_not_a_panic() {
        for bytes in [&b""[..], b"PK\x05\x06", &[0xffu8; 100], b"\x93NUMPY"] {
            assert!(Npz::new(bytes).is_err());
        }
        // An end record pointing past the file.
        let mut eocd = vec![0u8; 22];
        eocd[..4].copy_from_slice(&EOCD.to_le_bytes());
        eocd[10..12].copy_from_slice(&5u16.to_le_bytes());
        eocd[12..16].copy_from_slice(&1000u32.to_le_bytes());
        assert!(Npz::new(&eocd).is_err());
    }
}
