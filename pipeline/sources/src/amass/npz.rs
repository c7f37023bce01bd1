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
    Archive(ArchiveFault),
    /// The archive has no array of that name.
    #[error("no array `{key}`")]
    Missing {
        /// The array's name.
        key: String,
    },
    /// The array's entry is damaged: cut short, a bad CRC, an unknown compression.
    #[error("array `{key}`: {fault}")]
    Entry {
        /// The array's name.
        key: String,
        /// What is wrong.
        fault: EntryFault,
    },
    /// The `.npy` header does not parse, or the values are of a type not read here.
    #[error("array `{key}`: {fault}")]
    Npy {
        /// The array's name.
        key: String,
        /// What is wrong.
        fault: NpyFault,
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

/// What is wrong with an archive's end records or central directory.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum ArchiveFault {
    /// No end-of-central-directory signature in the last 64 KiB.
    #[error("no end-of-directory record (the file is cut short or is not a zip)")]
    NoEndRecord,
    /// The zip64 locator's offset field is missing.
    #[error("zip64 locator cut short")]
    Zip64LocatorCutShort,
    /// The zip64 record's offset does not fit an address.
    #[error("zip64 record offset out of range")]
    Zip64OffsetOutOfRange,
    /// The zip64 locator's offset holds no zip64 end record.
    #[error("the zip64 locator points at no zip64 end record")]
    NoZip64EndRecord,
    /// The zip64 end record ends before its count, size and offset fields.
    #[error("zip64 end record cut short")]
    Zip64EndRecordCutShort,
    /// The directory's offset and size reach past the file.
    #[error("the directory lies past the end of the file (cut short?)")]
    DirectoryPastEnd,
    /// The entry count is more than the directory's bytes can hold.
    #[error("the directory lists more entries than it has room for")]
    TooManyEntries,
    /// A directory record lacks its signature.
    #[error("a directory record is damaged")]
    RecordDamaged,
    /// A directory record's name or extra field runs past the directory.
    #[error("a directory record is cut short")]
    RecordCutShort,
}

/// What is wrong with one array's entry in the archive.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum EntryFault {
    /// No local header signature where the directory points.
    #[error("its local header is missing or damaged")]
    LocalHeader,
    /// The entry's compressed bytes reach past the file.
    #[error("its {compressed} bytes run past the end of the file (cut short?)")]
    PastEnd {
        /// The compressed size the directory gives.
        compressed: u64,
    },
    /// A stored entry whose compressed and uncompressed sizes differ.
    #[error("stored sizes disagree")]
    StoredSizes,
    /// The deflate stream is damaged.
    #[error("does not inflate: {0}")]
    Inflate(
        /// flate2's message (kept as text: the error is cloned, and `std::io::Error` is not
        /// `Clone`).
        String,
    ),
    /// The inflated bytes are not as many as the directory says.
    #[error("inflates to {found} bytes, not the {expected} the directory gives")]
    InflatedSize {
        /// Bytes inflated (at most one past `expected`).
        found: u64,
        /// Bytes the directory gives.
        expected: u64,
    },
    /// A compression method other than stored (0) and deflate (8).
    #[error("compression method {0} (only stored and deflate, as NumPy writes)")]
    Method(u16),
    /// The bytes do not match the directory's CRC-32.
    #[error("CRC mismatch: the bytes are damaged")]
    Crc,
}

/// What is wrong with an `.npy` file's header or value type.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NpyFault {
    /// The bytes do not start with `\x93NUMPY`.
    #[error("not a NumPy .npy array (no magic string)")]
    NoMagic,
    /// A format version other than 1, 2 and 3.
    #[error("unknown .npy version")]
    UnknownVersion,
    /// The header is longer than the bytes.
    #[error("the header is cut short")]
    HeaderCutShort,
    /// The header is not UTF-8 or lacks `descr`, `fortran_order` or a readable `shape`.
    #[error("the header does not parse")]
    HeaderUnparsed,
    /// A multi-dimensional array in Fortran order.
    #[error("stored in Fortran order; expected C order")]
    FortranOrder,
    /// The shape's count of values (or of bytes) overflows 64 bits.
    #[error("shape {shape:?} overflows")]
    ShapeOverflows {
        /// The shape the header gives.
        shape: Vec<u64>,
    },
    /// A value type not read here.
    #[error(
        "values of type `{descr}`; expected floats (`<f4`, `<f8`), integers or a string{}",
        pickled_note(descr)
    )]
    Dtype {
        /// The header's `descr`, as written in the file.
        descr: String,
    },
}

/// Said of a `descr` with an object (`O`) type: NumPy pickles those.
fn pickled_note(descr: &str) -> &'static str {
    if descr.contains('O') {
        " (this one is a pickled Python object)"
    } else {
        ""
    }
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
        let bad = NpzError::Archive;
        // The end record is in the last 22 + 65,535 bytes (its comment is at most that long).
        let floor = bytes.len().saturating_sub(22 + 0xffff);
        let eocd = (floor..bytes.len().saturating_sub(21))
            .rev()
            .find(|&i| u32_at(bytes, i) == Some(EOCD))
            .ok_or(bad(ArchiveFault::NoEndRecord))?;
        let mut count = u64::from(u16_at(bytes, eocd + 10).unwrap_or(0));
        let mut dir_size = u64::from(u32_at(bytes, eocd + 12).unwrap_or(0));
        let mut dir_offset = u64::from(u32_at(bytes, eocd + 16).unwrap_or(0));
        if eocd >= 20 && u32_at(bytes, eocd - 20) == Some(ZIP64_LOCATOR) {
            let at = u64_at(bytes, eocd - 12).ok_or(bad(ArchiveFault::Zip64LocatorCutShort))?;
            let at = usize::try_from(at).map_err(|_| bad(ArchiveFault::Zip64OffsetOutOfRange))?;
            if u32_at(bytes, at) != Some(ZIP64_EOCD) {
                return Err(bad(ArchiveFault::NoZip64EndRecord));
            }
            let cut = || bad(ArchiveFault::Zip64EndRecordCutShort);
            count = u64_at(bytes, at + 32).ok_or_else(cut)?;
            dir_size = u64_at(bytes, at + 40).ok_or_else(cut)?;
            dir_offset = u64_at(bytes, at + 48).ok_or_else(cut)?;
        }
        let start = usize::try_from(dir_offset).unwrap_or(usize::MAX);
        let end = start.saturating_add(usize::try_from(dir_size).unwrap_or(usize::MAX));
        let directory = bytes
            .get(start..end)
            .ok_or(bad(ArchiveFault::DirectoryPastEnd))?;
        // Each directory record takes 46 bytes at least: a count beyond that is a lie.
        if count > (directory.len() / 46) as u64 {
            return Err(bad(ArchiveFault::TooManyEntries));
        }
        let mut entries = Vec::with_capacity(count as usize);
        let mut at = 0usize;
        for _ in 0..count {
            if u32_at(directory, at) != Some(CENTRAL) {
                return Err(bad(ArchiveFault::RecordDamaged));
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
                .ok_or(bad(ArchiveFault::RecordCutShort))?;
            let extra = directory
                .get(name_at + name_len..name_at + name_len + extra_len)
                .ok_or(bad(ArchiveFault::RecordCutShort))?;
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
        let damaged = |fault: EntryFault| NpzError::Entry {
            key: key.to_string(),
            fault,
        };
        let local = usize::try_from(entry.local_offset).unwrap_or(usize::MAX);
        if u32_at(self.bytes, local) != Some(LOCAL) {
            return Err(damaged(EntryFault::LocalHeader));
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
                damaged(EntryFault::PastEnd {
                    compressed: entry.compressed,
                })
            })?;
        let raw: Cow<'a, [u8]> = match entry.method {
            0 => {
                if entry.uncompressed != entry.compressed {
                    return Err(damaged(EntryFault::StoredSizes));
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
                    .map_err(|e| damaged(EntryFault::Inflate(e.to_string())))?;
                if out.len() as u64 != entry.uncompressed {
                    return Err(damaged(EntryFault::InflatedSize {
                        found: out.len() as u64,
                        expected: entry.uncompressed,
                    }));
                }
                Cow::Owned(out)
            }
            other => {
                return Err(damaged(EntryFault::Method(other)));
            }
        };
        if crc32fast::hash(&raw) != entry.crc {
            return Err(damaged(EntryFault::Crc));
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
    let npy = |fault: NpyFault| NpzError::Npy {
        key: key.to_string(),
        fault,
    };
    let (header, data) = npy_header(bytes).map_err(npy)?;
    if header.fortran && header.shape.iter().filter(|&&d| d > 1).count() > 1 {
        return Err(npy(NpyFault::FortranOrder));
    }
    let overflows = || {
        npy(NpyFault::ShapeOverflows {
            shape: header.shape.clone(),
        })
    };
    let count = header
        .shape
        .iter()
        .try_fold(1u64, |n, &d| n.checked_mul(d))
        .ok_or_else(overflows)?;
    let dtype = Dtype::of(&header.descr);
    let unreadable = || {
        npy(NpyFault::Dtype {
            descr: header.descr.clone(),
        })
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
    let expected = values.checked_mul(unit).ok_or_else(overflows)?;
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
fn npy_header(bytes: &[u8]) -> Result<(Header, &[u8]), NpyFault> {
    let rest = bytes.strip_prefix(b"\x93NUMPY").ok_or(NpyFault::NoMagic)?;
    let (header_len, rest) = match rest {
        [1, _, a, b, rest @ ..] => (usize::from(u16::from_le_bytes([*a, *b])), rest),
        [2 | 3, _, a, b, c, d, rest @ ..] => (u32::from_le_bytes([*a, *b, *c, *d]) as usize, rest),
        _ => return Err(NpyFault::UnknownVersion),
    };
    let header = rest.get(..header_len).ok_or(NpyFault::HeaderCutShort)?;
    let data = &rest[header_len..];
    let header = std::str::from_utf8(header)
        .ok()
        .and_then(parse_header)
        .ok_or(NpyFault::HeaderUnparsed)?;
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
pub(crate) mod tests {
    use super::*;

    /// The bytes of a `.npy` file of `descr`, `shape` (Python tuple text) and raw `data`.
    pub(crate) fn npy(descr: &str, shape: &str, data: &[u8]) -> Vec<u8> {
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
        assert!(
            matches!(
                err,
                NpzError::Npy {
                    fault: NpyFault::ShapeOverflows { .. },
                    ..
                }
            ),
            "{err}"
        );
        let err = parse_npy("poses", &npy("|O", "(2,)", &[0u8; 16])).unwrap_err();
        assert!(err.to_string().contains("pickled"), "{err}");
        assert!(
            matches!(err, NpzError::Npy { fault: NpyFault::Dtype { ref descr }, .. } if descr == "|O"),
            "{err}"
        );
    }

    /// The little-endian bytes of `values`: a `<f8` array's data.
    pub(crate) fn f8(values: &[f64]) -> Vec<u8> {
        values.iter().flat_map(|v| v.to_le_bytes()).collect()
    }

    /// An `.npz` of `(key, npy bytes)` `arrays`, each of `changes` replacing the array of its
    /// key or added after them.
    pub(crate) fn npz(mut arrays: Vec<(String, Vec<u8>)>, changes: &[(&str, Vec<u8>)]) -> Vec<u8> {
        for (key, bytes) in changes {
            match arrays.iter_mut().find(|(k, _)| k == key) {
                Some(a) => a.1 = bytes.clone(),
                None => arrays.push((key.to_string(), bytes.clone())),
            }
        }
        let named: Vec<(String, Vec<u8>)> = arrays
            .into_iter()
            .map(|(k, b)| (format!("{k}.npy"), b))
            .collect();
        let entries: Vec<(&str, Vec<u8>)> =
            named.iter().map(|(k, b)| (k.as_str(), b.clone())).collect();
        zip(&entries)
    }

    /// A stored (uncompressed) zip of `(name, bytes)` entries, as `np.savez` writes one.
    pub(crate) fn zip(entries: &[(&str, Vec<u8>)]) -> Vec<u8> {
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
        assert!(
            matches!(
                err,
                NpzError::Entry {
                    fault: EntryFault::LocalHeader,
                    ..
                }
            ),
            "{err}"
        );
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

    /// The texts of every archive and entry fault, as `rejects.jsonl` shows them: they must not
    /// change.
    #[test]
    fn every_archive_fault_reads_as_it_always_has() {
        let poses: Vec<u8> = (0..12).flat_map(|i| (i as f64).to_le_bytes()).collect();
        let good = npy("<f8", "(2, 6)", &poses);
        let archive = zip(&[("poses.npy", good.clone())]);
        let text = |bytes: &[u8], key: &str| match Npz::new(bytes) {
            Ok(npz) => npz.array(key).unwrap_err().to_string(),
            Err(e) => e.to_string(),
        };
        let with = |at: usize, value: &[u8]| {
            let mut b = archive.clone();
            b[at..at + value.len()].copy_from_slice(value);
            b
        };
        let eocd = archive.len() - 22;
        let dir = eocd - (46 + "poses.npy".len());
        let mut cases: Vec<(Vec<u8>, &str)> = vec![
            (
                vec![0u8; 30],
                "not a readable .npz (zip) archive: no end-of-directory record (the file is cut short or is not a zip)",
            ),
            (
                with(eocd + 16, &9999u32.to_le_bytes()),
                "not a readable .npz (zip) archive: the directory lies past the end of the file (cut short?)",
            ),
            (
                with(eocd + 10, &9u16.to_le_bytes()),
                "not a readable .npz (zip) archive: the directory lists more entries than it has room for",
            ),
            (
                with(dir, b"PK\x09\x09"),
                "not a readable .npz (zip) archive: a directory record is damaged",
            ),
            (
                with(dir + 28, &200u16.to_le_bytes()),
                "not a readable .npz (zip) archive: a directory record is cut short",
            ),
            (
                with(dir + 42, &5u32.to_le_bytes()),
                "array `poses`: its local header is missing or damaged",
            ),
            (
                with(dir + 20, &9999u32.to_le_bytes()),
                "array `poses`: its 9999 bytes run past the end of the file (cut short?)",
            ),
            (
                with(dir + 24, &7u32.to_le_bytes()),
                "array `poses`: stored sizes disagree",
            ),
            (
                with(dir + 10, &12u16.to_le_bytes()),
                "array `poses`: compression method 12 (only stored and deflate, as NumPy writes)",
            ),
            (
                with(dir + 16, &7u32.to_le_bytes()),
                "array `poses`: CRC mismatch: the bytes are damaged",
            ),
            (
                with(dir + 10, &8u16.to_le_bytes()),
                "array `poses`: inflates to 6 bytes, not the 224 the directory gives",
            ),
        ];
        let mut bad_block = with(dir + 10, &8u16.to_le_bytes());
        bad_block[30 + "poses.npy".len()] = 0x07;
        cases.push((
            bad_block,
            "array `poses`: does not inflate: corrupt deflate stream",
        ));
        // A zip64 locator before the end record, pointing at `target`.
        let zip64 = |target: Option<u64>| {
            let mut b = archive[..eocd].to_vec();
            let at = b.len() as u64;
            b.extend(ZIP64_EOCD.to_le_bytes());
            b.extend(ZIP64_LOCATOR.to_le_bytes());
            b.extend([0u8; 4]);
            b.extend(target.unwrap_or(at).to_le_bytes());
            b.extend([0u8; 4]);
            b.extend(&archive[eocd..]);
            b
        };
        cases.push((
            zip64(Some(0)),
            "not a readable .npz (zip) archive: the zip64 locator points at no zip64 end record",
        ));
        cases.push((
            zip64(None),
            "not a readable .npz (zip) archive: zip64 end record cut short",
        ));
        for (bytes, want) in cases {
            assert_eq!(text(&bytes, "poses"), want);
        }
        assert_eq!(text(&archive, "trans"), "no array `trans`");
    }

    /// The texts of every `.npy` fault: they must not change.
    #[test]
    fn every_npy_fault_reads_as_it_always_has() {
        let poses: Vec<u8> = (0..12).flat_map(|i| (i as f64).to_le_bytes()).collect();
        let good = npy("<f8", "(2, 6)", &poses);
        let npy_text = |bytes: &[u8]| parse_npy("poses", bytes).unwrap_err().to_string();
        let mut fortran = npy("<f8", "(2, 6)", &poses);
        let at = fortran.windows(5).position(|w| w == b"False").unwrap();
        fortran[at..at + 5].copy_from_slice(b"True ");
        let cases: Vec<(Vec<u8>, &str)> = vec![
            (
                b"NUMPY".to_vec(),
                "array `poses`: not a NumPy .npy array (no magic string)",
            ),
            (
                b"\x93NUMPY\x07\x00".to_vec(),
                "array `poses`: unknown .npy version",
            ),
            (
                good[..20].to_vec(),
                "array `poses`: the header is cut short",
            ),
            (
                npy("<f8", "(2, x)", &poses),
                "array `poses`: the header does not parse",
            ),
            (
                fortran,
                "array `poses`: stored in Fortran order; expected C order",
            ),
            (
                npy("<f8", "(4294967296, 4294967296, 2)", &poses),
                "array `poses`: shape [4294967296, 4294967296, 2] overflows",
            ),
            (
                npy("<f8", "(4294967296, 4294967296)", &poses),
                "array `poses`: shape [4294967296, 4294967296] overflows",
            ),
            (
                npy("<c16", "(2,)", &poses),
                "array `poses`: values of type `<c16`; expected floats (`<f4`, `<f8`), integers or a string",
            ),
            (
                npy("|O", "(2,)", &poses),
                "array `poses`: values of type `|O`; expected floats (`<f4`, `<f8`), integers or a string (this one is a pickled Python object)",
            ),
            (
                npy("<f8", "(3, 6)", &poses),
                "array `poses`: shape [3, 6] needs 144 bytes of values but the entry holds 96",
            ),
        ];
        for (bytes, want) in cases {
            assert_eq!(npy_text(&bytes), want);
        }
    }
}
