//! NumPy `.npy` arrays and `.npz` archives.
//!
//! - [`write_npy_bytes`] / [`read_npy_bytes`] convert one array to and from the
//!   [`.npy` format](https://numpy.org/doc/stable/reference/generated/numpy.lib.format.html)
//!   (version 1.0, little-endian, C order; version 2.0 only for headers above 64 KiB);
//! - [`write_npy`] / [`read_npy`] do the same with a file;
//! - [`write_npz`] / [`read_npz`] handle `.npz` archives, ZIP files holding one `name.npy` entry
//!   per array, as written by `numpy.savez` and read by `numpy.load`.
//!
//! The ZIP container is written by hand: entries are STORED (not compressed) with their CRC-32.
//! Archives or entries of 4 GiB and more use the ZIP64 extensions, which numpy (Python's
//! `zipfile`) reads. [`read_npz`] reads stored and deflate-compressed entries, so files from
//! `numpy.savez_compressed` load as well; it checks every entry's CRC-32.
//!
//! Supported dtypes: `float32`, `float64`, `int32`, `int64`, `uint8` ([`ArrayData`]). The reader
//! also accepts big-endian data, Fortran-ordered arrays (converted to C order) and `bool` arrays
//! (read as [`ArrayData::U8`] holding 0 and 1).

use std::fs::File;
use std::io::{self, BufReader, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

use crate::{IoError, write_all, write_atomic};

/// The elements of an array, in C (row-major) order.
#[derive(Debug, Clone, PartialEq)]
pub enum ArrayData {
    /// `float32`, `'<f4'`.
    F32(Vec<f32>),
    /// `float64`, `'<f8'`.
    F64(Vec<f64>),
    /// `int32`, `'<i4'`.
    I32(Vec<i32>),
    /// `int64`, `'<i8'`.
    I64(Vec<i64>),
    /// `uint8`, `'|u1'`.
    U8(Vec<u8>),
}

impl ArrayData {
    /// The number of elements.
    pub fn len(&self) -> usize {
        match self {
            ArrayData::F32(v) => v.len(),
            ArrayData::F64(v) => v.len(),
            ArrayData::I32(v) => v.len(),
            ArrayData::I64(v) => v.len(),
            ArrayData::U8(v) => v.len(),
        }
    }

    /// Whether there are no elements.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The NumPy type descriptor written to `.npy` headers, e.g. `"<f4"`.
    pub fn descr(&self) -> &'static str {
        match self {
            ArrayData::F32(_) => "<f4",
            ArrayData::F64(_) => "<f8",
            ArrayData::I32(_) => "<i4",
            ArrayData::I64(_) => "<i8",
            ArrayData::U8(_) => "|u1",
        }
    }

    /// The size of one element in bytes.
    pub fn item_size(&self) -> usize {
        match self {
            ArrayData::F32(_) | ArrayData::I32(_) => 4,
            ArrayData::F64(_) | ArrayData::I64(_) => 8,
            ArrayData::U8(_) => 1,
        }
    }

    /// Calls `f` with the little-endian bytes of the elements, a bounded chunk at a time (so that
    /// no copy of the whole array is made).
    fn for_each_le_chunk<E>(&self, mut f: impl FnMut(&[u8]) -> Result<(), E>) -> Result<(), E> {
        const CHUNK_BYTES: usize = 1 << 16;
        macro_rules! chunks {
            ($v:expr, $size:expr) => {{
                let mut buf = Vec::with_capacity(CHUNK_BYTES);
                for chunk in $v.chunks(CHUNK_BYTES / $size) {
                    buf.clear();
                    for x in chunk {
                        buf.extend_from_slice(&x.to_le_bytes());
                    }
                    f(&buf)?;
                }
                Ok(())
            }};
        }
        match self {
            ArrayData::F32(v) => chunks!(v, 4),
            ArrayData::F64(v) => chunks!(v, 8),
            ArrayData::I32(v) => chunks!(v, 4),
            ArrayData::I64(v) => chunks!(v, 8),
            ArrayData::U8(v) => {
                for chunk in v.chunks(CHUNK_BYTES) {
                    f(chunk)?;
                }
                Ok(())
            }
        }
    }
}

macro_rules! impl_from_vec {
    ($($t:ty => $variant:ident),*) => {$(
        impl From<Vec<$t>> for ArrayData {
            fn from(v: Vec<$t>) -> Self {
                ArrayData::$variant(v)
            }
        }
    )*};
}
impl_from_vec!(f32 => F32, f64 => F64, i32 => I32, i64 => I64, u8 => U8);

/// An n-dimensional array as stored in a `.npy` file: a shape and its elements in C order.
///
/// The fields are public; [`NpyArray::new`] checks that they agree, and the writers check it
/// again ([`NpyArray::validate`]).
#[derive(Debug, Clone, PartialEq)]
pub struct NpyArray {
    /// The extent of each axis; empty for a scalar (one element).
    pub shape: Vec<usize>,
    /// The elements, in C (row-major) order: `shape.iter().product()` of them.
    pub data: ArrayData,
}

/// The number of elements of `shape`, `None` on overflow.
fn element_count(shape: &[usize]) -> Option<usize> {
    shape.iter().try_fold(1usize, |n, &d| n.checked_mul(d))
}

impl NpyArray {
    /// An array of the given shape; fails unless the shape's product equals the data's length.
    pub fn new(shape: Vec<usize>, data: impl Into<ArrayData>) -> Result<Self, IoError> {
        let array = NpyArray {
            shape,
            data: data.into(),
        };
        array.validate()?;
        Ok(array)
    }

    /// A one-dimensional array holding `data`.
    pub fn from_vec(data: impl Into<ArrayData>) -> Self {
        let data = data.into();
        NpyArray {
            shape: vec![data.len()],
            data,
        }
    }

    /// Checks that the shape's product equals the data's length.
    pub fn validate(&self) -> Result<(), IoError> {
        if element_count(&self.shape) == Some(self.data.len()) {
            Ok(())
        } else {
            Err(IoError::ShapeMismatch {
                shape: self.shape.clone(),
                len: self.data.len(),
            })
        }
    }

    /// The number of elements.
    pub fn len(&self) -> usize {
        self.data.len()
    }

    /// Whether the array has no elements.
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    /// The elements if the array holds `float32`.
    pub fn as_f32(&self) -> Option<&[f32]> {
        match &self.data {
            ArrayData::F32(v) => Some(v),
            _ => None,
        }
    }

    /// The elements if the array holds `float64`.
    pub fn as_f64(&self) -> Option<&[f64]> {
        match &self.data {
            ArrayData::F64(v) => Some(v),
            _ => None,
        }
    }

    /// The elements if the array holds `int32`.
    pub fn as_i32(&self) -> Option<&[i32]> {
        match &self.data {
            ArrayData::I32(v) => Some(v),
            _ => None,
        }
    }

    /// The elements if the array holds `int64`.
    pub fn as_i64(&self) -> Option<&[i64]> {
        match &self.data {
            ArrayData::I64(v) => Some(v),
            _ => None,
        }
    }

    /// The elements if the array holds `uint8`.
    pub fn as_u8(&self) -> Option<&[u8]> {
        match &self.data {
            ArrayData::U8(v) => Some(v),
            _ => None,
        }
    }

    /// The size of the `.npy` encoding in bytes (header and data).
    fn npy_size(&self, header: &[u8]) -> Option<u64> {
        let data = (self.data.len() as u64).checked_mul(self.data.item_size() as u64)?;
        data.checked_add(header.len() as u64)
    }
}

// ---------------------------------------------------------------------------------------------
// .npy encoding

const NPY_MAGIC: &[u8; 6] = b"\x93NUMPY";

/// The `.npy` header (magic, version, length and the padded dictionary) for `array`.
fn npy_header(array: &NpyArray) -> Vec<u8> {
    let shape = match array.shape.as_slice() {
        [] => "()".to_string(),
        [n] => format!("({n},)"),
        dims => {
            let dims: Vec<String> = dims.iter().map(|d| d.to_string()).collect();
            format!("({})", dims.join(", "))
        }
    };
    let dict = format!(
        "{{'descr': '{}', 'fortran_order': False, 'shape': {shape}, }}",
        array.data.descr()
    );
    // Version 1.0 stores the header length in 2 bytes; longer headers (shapes with thousands of
    // axes) need version 2.0 and its 4-byte length.
    let padded = |prefix: usize| (prefix + dict.len() + 1).div_ceil(64) * 64;
    let (version, prefix) = if padded(10) - 10 <= usize::from(u16::MAX) {
        (1u8, 10)
    } else {
        (2u8, 12)
    };
    let total = padded(prefix);
    let header_len = total - prefix;
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(NPY_MAGIC);
    out.push(version);
    out.push(0);
    if version == 1 {
        out.extend_from_slice(&(header_len as u16).to_le_bytes());
    } else {
        out.extend_from_slice(&(header_len as u32).to_le_bytes());
    }
    out.extend_from_slice(dict.as_bytes());
    out.resize(total - 1, b' ');
    out.push(b'\n');
    out
}

/// Encodes `array` in the `.npy` format, version 1.0: the magic string, the version, a header
/// dictionary (`descr` `'<f4'`, `'<f8'`, `'<i4'`, `'<i8'` or `'|u1'`, `fortran_order: False`,
/// `shape`) padded with spaces and a final `'\n'` so that the data starts at a multiple of 64
/// bytes, then the elements in little-endian C order.
///
/// Fails with [`IoError::ShapeMismatch`] when the shape does not fit the data.
pub fn write_npy_bytes(array: &NpyArray) -> Result<Vec<u8>, IoError> {
    array.validate()?;
    let mut out = npy_header(array);
    out.reserve(array.data.len() * array.data.item_size());
    array.data.for_each_le_chunk(|chunk| {
        out.extend_from_slice(chunk);
        Ok::<(), IoError>(())
    })?;
    Ok(out)
}

/// Writes `array` to the `.npy` file `path` (see [`write_npy_bytes`]), atomically.
pub fn write_npy(path: impl AsRef<Path>, array: &NpyArray) -> Result<(), IoError> {
    let path = path.as_ref();
    array.validate()?;
    write_atomic(path, |w| {
        write_all(w, &npy_header(array), path)?;
        array
            .data
            .for_each_le_chunk(|chunk| write_all(w, chunk, path))
    })
}

// ---------------------------------------------------------------------------------------------
// .npy decoding

/// Why a `.npy` buffer could not be decoded.
enum NpyIssue {
    /// The data is damaged or not `.npy`.
    Invalid(String),
    /// The data is valid but uses a feature this module does not support.
    Unsupported(String),
}

fn invalid(reason: impl Into<String>) -> NpyIssue {
    NpyIssue::Invalid(reason.into())
}

/// A value of the Python literal that forms a `.npy` header.
enum PyValue {
    Str(String),
    Bool(bool),
    Tuple(Vec<usize>),
    /// Anything else (a list describing a structured dtype, ...), kept as text.
    Other(String),
}

/// A parser for the subset of Python literals used in `.npy` headers.
struct HeaderParser<'a> {
    s: &'a [u8],
    pos: usize,
}

impl HeaderParser<'_> {
    fn peek(&self) -> Option<u8> {
        self.s.get(self.pos).copied()
    }

    fn skip_ws(&mut self) {
        while self.peek().is_some_and(|c| c.is_ascii_whitespace()) {
            self.pos += 1;
        }
    }

    fn expect(&mut self, c: u8) -> Result<(), NpyIssue> {
        self.skip_ws();
        if self.peek() == Some(c) {
            self.pos += 1;
            Ok(())
        } else {
            Err(invalid(format!(
                "header: expected '{}' at byte {}",
                c as char, self.pos
            )))
        }
    }

    fn string(&mut self) -> Result<String, NpyIssue> {
        self.skip_ws();
        let quote = match self.peek() {
            Some(q @ (b'\'' | b'"')) => q,
            _ => {
                return Err(invalid(format!(
                    "header: expected a string at byte {}",
                    self.pos
                )));
            }
        };
        self.pos += 1;
        let start = self.pos;
        while let Some(c) = self.peek() {
            if c == quote {
                let text = String::from_utf8_lossy(&self.s[start..self.pos]).into_owned();
                self.pos += 1;
                return Ok(text);
            }
            self.pos += if c == b'\\' { 2 } else { 1 };
        }
        Err(invalid("header: unterminated string"))
    }

    fn word(&mut self) -> &[u8] {
        let start = self.pos;
        while self
            .peek()
            .is_some_and(|c| c.is_ascii_alphanumeric() || c == b'_')
        {
            self.pos += 1;
        }
        &self.s[start..self.pos]
    }

    fn tuple(&mut self) -> Result<Vec<usize>, NpyIssue> {
        self.expect(b'(')?;
        let mut dims = Vec::new();
        loop {
            self.skip_ws();
            if self.peek() == Some(b')') {
                self.pos += 1;
                return Ok(dims);
            }
            let word = self.word();
            // Python 2 wrote long integers with an `L` suffix.
            let digits = word.strip_suffix(b"L").unwrap_or(word);
            let text = std::str::from_utf8(digits).unwrap_or("");
            let dim = text.parse::<usize>().map_err(|_| {
                invalid(format!(
                    "header: invalid shape entry '{}'",
                    String::from_utf8_lossy(word)
                ))
            })?;
            dims.push(dim);
            self.skip_ws();
            match self.peek() {
                Some(b',') => self.pos += 1,
                Some(b')') => {}
                _ => return Err(invalid("header: malformed shape tuple")),
            }
        }
    }

    /// Skips a bracketed expression (`[...]`, `(...)`, `{...}`), returning its text.
    fn bracketed(&mut self) -> Result<String, NpyIssue> {
        let start = self.pos;
        let mut depth = 0usize;
        while let Some(c) = self.peek() {
            match c {
                b'\'' | b'"' => {
                    self.string()?;
                    continue;
                }
                b'[' | b'(' | b'{' => depth += 1,
                b']' | b')' | b'}' => {
                    depth = depth.saturating_sub(1);
                    if depth == 0 {
                        self.pos += 1;
                        return Ok(String::from_utf8_lossy(&self.s[start..self.pos]).into_owned());
                    }
                }
                _ => {}
            }
            self.pos += 1;
        }
        Err(invalid("header: unbalanced brackets"))
    }

    fn value(&mut self) -> Result<PyValue, NpyIssue> {
        self.skip_ws();
        match self.peek() {
            Some(b'\'' | b'"') => Ok(PyValue::Str(self.string()?)),
            Some(b'(') => {
                let start = self.pos;
                match self.tuple() {
                    Ok(dims) => Ok(PyValue::Tuple(dims)),
                    Err(_) => {
                        self.pos = start;
                        Ok(PyValue::Other(self.bracketed()?))
                    }
                }
            }
            Some(b'[' | b'{') => Ok(PyValue::Other(self.bracketed()?)),
            _ => match self.word() {
                b"True" => Ok(PyValue::Bool(true)),
                b"False" => Ok(PyValue::Bool(false)),
                _ => Err(invalid(format!(
                    "header: unexpected value at byte {}",
                    self.pos
                ))),
            },
        }
    }

    /// Parses the header dictionary into its `descr`, `fortran_order` and `shape` entries.
    fn dict(&mut self) -> Result<(PyValue, bool, Vec<usize>), NpyIssue> {
        self.expect(b'{')?;
        let (mut descr, mut fortran, mut shape) = (None, None, None);
        loop {
            self.skip_ws();
            if self.peek() == Some(b'}') {
                self.pos += 1;
                break;
            }
            let key = self.string()?;
            self.expect(b':')?;
            let value = self.value()?;
            match (key.as_str(), value) {
                ("descr", v) => descr = Some(v),
                ("fortran_order", PyValue::Bool(b)) => fortran = Some(b),
                ("shape", PyValue::Tuple(t)) => shape = Some(t),
                ("fortran_order" | "shape", _) => {
                    return Err(invalid(format!("header: invalid value for '{key}'")));
                }
                _ => {} // Unknown keys are ignored.
            }
            self.skip_ws();
            match self.peek() {
                Some(b',') => self.pos += 1,
                Some(b'}') => {}
                _ => return Err(invalid("header: malformed dictionary")),
            }
        }
        self.skip_ws();
        if self.pos != self.s.len() {
            return Err(invalid("header: trailing characters after the dictionary"));
        }
        match (descr, fortran, shape) {
            (Some(d), Some(f), Some(s)) => Ok((d, f, s)),
            _ => Err(invalid(
                "header: missing one of 'descr', 'fortran_order', 'shape'",
            )),
        }
    }
}

/// The element types that can be read, with their byte order.
#[derive(Clone, Copy)]
enum Dtype {
    F32,
    F64,
    I32,
    I64,
    U8,
    Bool,
}

fn parse_descr(descr: &str) -> Result<(Dtype, bool), NpyIssue> {
    let unsupported = || {
        NpyIssue::Unsupported(format!(
            "dtype '{descr}' (supported: float32, float64, int32, int64, uint8, bool)"
        ))
    };
    let (order, code) = match descr.as_bytes().first() {
        Some(b'<' | b'>' | b'|' | b'=') => descr.split_at(1),
        _ => ("|", descr),
    };
    let big_endian = match order {
        ">" => true,
        "=" => cfg!(target_endian = "big"),
        _ => false,
    };
    let dtype = match code {
        "f4" => Dtype::F32,
        "f8" => Dtype::F64,
        "i4" => Dtype::I32,
        "i8" => Dtype::I64,
        "u1" => Dtype::U8,
        "b1" | "?" => Dtype::Bool,
        _ => return Err(unsupported()),
    };
    Ok((dtype, big_endian))
}

/// Reorders Fortran-ordered (column-major) elements into C order.
fn fortran_to_c<T: Copy>(data: Vec<T>, shape: &[usize]) -> Vec<T> {
    let ndim = shape.len();
    if ndim < 2 || data.is_empty() {
        return data;
    }
    let mut strides = vec![1usize; ndim];
    for k in 1..ndim {
        strides[k] = strides[k - 1] * shape[k - 1];
    }
    let mut index = vec![0usize; ndim];
    let mut offset = 0usize;
    let mut out = Vec::with_capacity(data.len());
    for _ in 0..data.len() {
        out.push(data[offset]);
        // Advance the C-order multi-index (last axis fastest), tracking the Fortran offset.
        for k in (0..ndim).rev() {
            index[k] += 1;
            offset += strides[k];
            if index[k] < shape[k] {
                break;
            }
            offset -= strides[k] * shape[k];
            index[k] = 0;
        }
    }
    out
}

/// The parsed header of a `.npy` buffer.
struct ParsedHeader {
    descr: String,
    dtype: Dtype,
    big_endian: bool,
    fortran_order: bool,
    shape: Vec<usize>,
    /// Where the data starts (the length of magic, version and header).
    data_start: usize,
}

/// The length of the `.npy` preamble (magic, version and header length) that tells how long the
/// header is: 10 bytes for version 1, 12 for versions 2 and 3.
const NPY_PREAMBLE_MAX: usize = 12;

/// Parses the magic string, version and header of a `.npy` buffer; `bytes` may stop anywhere
/// after the header.
fn parse_npy_header(bytes: &[u8]) -> Result<ParsedHeader, NpyIssue> {
    if bytes.len() < 10 || &bytes[..6] != NPY_MAGIC {
        return Err(invalid("missing the .npy magic string"));
    }
    let (major, minor) = (bytes[6], bytes[7]);
    let (header_start, header_len) = match major {
        1 => (10, usize::from(u16::from_le_bytes([bytes[8], bytes[9]]))),
        2 | 3 => {
            let len = bytes
                .get(8..12)
                .ok_or_else(|| invalid("truncated header"))?;
            (
                12,
                u32::from_le_bytes([len[0], len[1], len[2], len[3]]) as usize,
            )
        }
        _ => {
            return Err(NpyIssue::Unsupported(format!(
                ".npy format version {major}.{minor}"
            )));
        }
    };
    let data_start = header_start + header_len;
    let header = bytes
        .get(header_start..data_start)
        .ok_or_else(|| invalid("truncated header"))?;
    let mut parser = HeaderParser { s: header, pos: 0 };
    let (descr, fortran_order, shape) = parser.dict()?;
    let descr = match descr {
        PyValue::Str(s) => s,
        PyValue::Other(s) => {
            return Err(NpyIssue::Unsupported(format!("structured dtype {s}")));
        }
        _ => return Err(invalid("header: invalid 'descr'")),
    };
    let (dtype, big_endian) = parse_descr(&descr)?;
    Ok(ParsedHeader {
        descr,
        dtype,
        big_endian,
        fortran_order,
        shape,
        data_start,
    })
}

fn parse_npy(bytes: &[u8]) -> Result<NpyArray, NpyIssue> {
    let ParsedHeader {
        descr,
        dtype,
        big_endian,
        fortran_order,
        shape,
        data_start,
    } = parse_npy_header(bytes)?;
    let count =
        element_count(&shape).ok_or_else(|| invalid(format!("shape {shape:?} is too large")))?;
    let item_size = match dtype {
        Dtype::F32 | Dtype::I32 => 4,
        Dtype::F64 | Dtype::I64 => 8,
        Dtype::U8 | Dtype::Bool => 1,
    };
    let body = &bytes[data_start..];
    if count.checked_mul(item_size) != Some(body.len()) {
        return Err(invalid(format!(
            "shape {shape:?} of '{descr}' needs {count} elements of {item_size} bytes but {} data \
             bytes follow the header",
            body.len()
        )));
    }
    macro_rules! decode {
        ($t:ty, $n:expr) => {
            body.chunks_exact($n)
                .map(|c| {
                    let mut a = [0u8; $n];
                    a.copy_from_slice(c);
                    if big_endian {
                        <$t>::from_be_bytes(a)
                    } else {
                        <$t>::from_le_bytes(a)
                    }
                })
                .collect::<Vec<$t>>()
        };
    }
    let data = match dtype {
        Dtype::F32 => ArrayData::F32(decode!(f32, 4)),
        Dtype::F64 => ArrayData::F64(decode!(f64, 8)),
        Dtype::I32 => ArrayData::I32(decode!(i32, 4)),
        Dtype::I64 => ArrayData::I64(decode!(i64, 8)),
        Dtype::U8 => ArrayData::U8(body.to_vec()),
        Dtype::Bool => ArrayData::U8(body.iter().map(|&b| u8::from(b != 0)).collect()),
    };
    let data = if fortran_order && shape.len() >= 2 {
        match data {
            ArrayData::F32(v) => ArrayData::F32(fortran_to_c(v, &shape)),
            ArrayData::F64(v) => ArrayData::F64(fortran_to_c(v, &shape)),
            ArrayData::I32(v) => ArrayData::I32(fortran_to_c(v, &shape)),
            ArrayData::I64(v) => ArrayData::I64(fortran_to_c(v, &shape)),
            ArrayData::U8(v) => ArrayData::U8(fortran_to_c(v, &shape)),
        }
    } else {
        data
    };
    Ok(NpyArray { shape, data })
}

/// Decodes a `.npy` buffer (format versions 1.0 to 3.0).
///
/// Accepts the dtypes of [`ArrayData`] in either byte order, `bool` (read as
/// [`ArrayData::U8`]) and Fortran order (converted to C order). Fails with
/// [`IoError::InvalidNpy`] when the buffer is not valid `.npy` data, is truncated or uses an
/// unsupported dtype.
pub fn read_npy_bytes(bytes: &[u8]) -> Result<NpyArray, IoError> {
    parse_npy(bytes).map_err(|issue| match issue {
        NpyIssue::Invalid(reason) => IoError::InvalidNpy { reason },
        NpyIssue::Unsupported(reason) => IoError::InvalidNpy {
            reason: format!("unsupported: {reason}"),
        },
    })
}

/// Maps a decoding issue of the array `what` in the file `path` to an [`IoError`].
fn npy_issue_error(path: &Path, what: &str, issue: NpyIssue) -> IoError {
    match issue {
        NpyIssue::Invalid(reason) => IoError::corrupt(path, format!("{what}: {reason}")),
        NpyIssue::Unsupported(reason) => IoError::Unsupported {
            path: path.to_path_buf(),
            reason: format!("{what}: {reason}"),
        },
    }
}

/// Reads the `.npy` file `path` (see [`read_npy_bytes`]).
pub fn read_npy(path: impl AsRef<Path>) -> Result<NpyArray, IoError> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|e| IoError::io(path, "cannot read", e))?;
    parse_npy(&bytes).map_err(|issue| npy_issue_error(path, "array", issue))
}

// ---------------------------------------------------------------------------------------------
// ZIP writing

const LOCAL_HEADER_SIG: u32 = 0x0403_4b50;
const CENTRAL_HEADER_SIG: u32 = 0x0201_4b50;
const EOCD_SIG: u32 = 0x0605_4b50;
const ZIP64_EOCD_SIG: u32 = 0x0606_4b50;
const ZIP64_LOCATOR_SIG: u32 = 0x0706_4b50;
const ZIP64_EXTRA_ID: u16 = 0x0001;
/// Marks a 32-bit field whose value lives in the ZIP64 extra field.
const U32_MAX: u64 = 0xFFFF_FFFF;
/// Marks a 16-bit entry count whose value lives in the ZIP64 end record.
const U16_MAX: u64 = 0xFFFF;
/// ZIP spec version 4.5 (ZIP64) and 2.0 (plain).
const VERSION_ZIP64: u16 = 45;
const VERSION_PLAIN: u16 = 20;
/// "Version made by": Unix, spec 4.5, so that the external attributes are Unix permissions.
const VERSION_MADE_BY: u16 = (3 << 8) | VERSION_ZIP64;
/// Regular file, rw-r--r--.
const EXTERNAL_ATTRIBUTES: u32 = 0o100_644 << 16;
/// General purpose flag: the name is UTF-8.
const FLAG_UTF8: u16 = 1 << 11;
const METHOD_STORED: u16 = 0;
const METHOD_DEFLATED: u16 = 8;

/// Little-endian field appending.
trait PutLe {
    fn u16(&mut self, v: u16);
    fn u32(&mut self, v: u32);
    fn u64(&mut self, v: u64);
}

impl PutLe for Vec<u8> {
    fn u16(&mut self, v: u16) {
        self.extend_from_slice(&v.to_le_bytes());
    }
    fn u32(&mut self, v: u32) {
        self.extend_from_slice(&v.to_le_bytes());
    }
    fn u64(&mut self, v: u64) {
        self.extend_from_slice(&v.to_le_bytes());
    }
}

/// The days since 1970-01-01 as a (year, month, day) civil date (proleptic Gregorian).
fn civil_from_days(days: i64) -> (i64, u32, u32) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let month = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    let year = yoe + era * 400 + i64::from(month <= 2);
    (year, month, day)
}

/// The MS-DOS (time, date) of `t` in UTC, clamped to the representable 1980..=2107.
fn dos_time_date(t: SystemTime) -> (u16, u16) {
    let secs = t
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    let days = (secs / 86_400) as i64;
    let rem = secs % 86_400;
    let (year, month, day) = civil_from_days(days);
    if year < 1980 {
        return (0, (1 << 5) | 1);
    }
    let year = year.min(2107);
    let time = ((rem / 3600) << 11) | (((rem % 3600) / 60) << 5) | ((rem % 60) / 2);
    let date = (((year - 1980) as u32) << 9) | (month << 5) | day;
    (time as u16, date as u16)
}

/// What the central directory needs to know of an entry written earlier.
struct WrittenEntry {
    name: Vec<u8>,
    flags: u16,
    crc: u32,
    size: u64,
    offset: u64,
}

/// Writes a `.npz` archive one array at a time, so that an archive larger than memory can be
/// written: each [`NpzWriter::add`] writes one STORED entry, and the central directory (a few
/// dozen bytes per entry) is kept until the end. Get one from [`write_npz_streamed`].
pub struct NpzWriter<'a> {
    w: &'a mut dyn Write,
    path: &'a Path,
    force_zip64: bool,
    time: u16,
    date: u16,
    pos: u64,
    written: Vec<WrittenEntry>,
    names: std::collections::HashSet<String>,
}

impl<'a> NpzWriter<'a> {
    fn new(w: &'a mut dyn Write, path: &'a Path, force_zip64: bool) -> Self {
        // Entries carry a fixed date (1980-01-01, the earliest a ZIP can hold), so the same
        // arrays always give the same bytes.
        let (time, date) = dos_time_date(UNIX_EPOCH);
        NpzWriter {
            w,
            path,
            force_zip64,
            time,
            date,
            pos: 0,
            written: Vec::new(),
            names: std::collections::HashSet::new(),
        }
    }

    fn too_large(&self) -> IoError {
        IoError::InvalidInput(format!("'{}': archive too large", self.path.display()))
    }

    /// Appends the array `array` as the entry `name.npy`.
    ///
    /// Fails on an empty, too long or repeated name, on an array whose shape does not fit its
    /// data, and on I/O errors (naming the path).
    pub fn add(&mut self, name: &str, array: &NpyArray) -> Result<(), IoError> {
        check_entry(name, array, self.path)?;
        if !self.names.insert(name.to_string()) {
            return Err(IoError::InvalidInput(format!(
                "'{}': array name '{name}' appears twice",
                self.path.display()
            )));
        }
        let header = npy_header(array);
        let size = array.npy_size(&header).ok_or_else(|| self.too_large())?;
        let (w, path) = (&mut *self.w, self.path);
        let mut hasher = crc32fast::Hasher::new();
        hasher.update(&header);
        array.data.for_each_le_chunk(|chunk| {
            hasher.update(chunk);
            Ok::<(), IoError>(())
        })?;
        let crc = hasher.finalize();

        let name = format!("{name}.npy").into_bytes();
        let flags = if name.is_ascii() { 0 } else { FLAG_UTF8 };
        let zip64 = self.force_zip64 || size >= U32_MAX;
        let mut local = Vec::with_capacity(30 + name.len() + 20);
        local.u32(LOCAL_HEADER_SIG);
        local.u16(if zip64 { VERSION_ZIP64 } else { VERSION_PLAIN });
        local.u16(flags);
        local.u16(METHOD_STORED);
        local.u16(self.time);
        local.u16(self.date);
        local.u32(crc);
        let size32 = if zip64 { U32_MAX as u32 } else { size as u32 };
        local.u32(size32); // compressed size
        local.u32(size32); // uncompressed size
        local.u16(name.len() as u16);
        local.u16(if zip64 { 20 } else { 0 });
        local.extend_from_slice(&name);
        if zip64 {
            local.u16(ZIP64_EXTRA_ID);
            local.u16(16);
            local.u64(size); // uncompressed
            local.u64(size); // compressed
        }
        write_all(w, &local, path)?;
        write_all(w, &header, path)?;
        array
            .data
            .for_each_le_chunk(|chunk| write_all(w, chunk, path))?;

        self.written.push(WrittenEntry {
            name,
            flags,
            crc,
            size,
            offset: self.pos,
        });
        self.pos = (local.len() as u64)
            .checked_add(size)
            .and_then(|n| n.checked_add(self.pos))
            .ok_or_else(|| self.too_large())?;
        Ok(())
    }

    /// Writes the central directory and the end records.
    fn finish(self) -> Result<(), IoError> {
        let (time, date, force_zip64) = (self.time, self.date, self.force_zip64);
        let (w, path) = (self.w, self.path);
        let too_large =
            || IoError::InvalidInput(format!("'{}': archive too large", path.display()));
        let written = self.written;
        let cd_offset = self.pos;
        let mut cd = Vec::new();
        for entry in &written {
            let big_size = force_zip64 || entry.size >= U32_MAX;
            let big_offset = force_zip64 || entry.offset >= U32_MAX;
            let mut extra = Vec::new();
            if big_size {
                extra.u64(entry.size); // uncompressed
                extra.u64(entry.size); // compressed
            }
            if big_offset {
                extra.u64(entry.offset);
            }
            cd.u32(CENTRAL_HEADER_SIG);
            cd.u16(VERSION_MADE_BY);
            cd.u16(if big_size || big_offset {
                VERSION_ZIP64
            } else {
                VERSION_PLAIN
            });
            cd.u16(entry.flags);
            cd.u16(METHOD_STORED);
            cd.u16(time);
            cd.u16(date);
            cd.u32(entry.crc);
            let size32 = if big_size {
                U32_MAX as u32
            } else {
                entry.size as u32
            };
            cd.u32(size32);
            cd.u32(size32);
            cd.u16(entry.name.len() as u16);
            cd.u16(if extra.is_empty() {
                0
            } else {
                extra.len() as u16 + 4
            });
            cd.u16(0); // comment length
            cd.u16(0); // disk number start
            cd.u16(0); // internal attributes
            cd.u32(EXTERNAL_ATTRIBUTES);
            cd.u32(if big_offset {
                U32_MAX as u32
            } else {
                entry.offset as u32
            });
            cd.extend_from_slice(&entry.name);
            if !extra.is_empty() {
                cd.u16(ZIP64_EXTRA_ID);
                cd.u16(extra.len() as u16);
                cd.extend_from_slice(&extra);
            }
        }
        let cd_size = cd.len() as u64;
        let count = written.len() as u64;
        let zip64_end =
            force_zip64 || count >= U16_MAX || cd_size >= U32_MAX || cd_offset >= U32_MAX;
        let mut end = Vec::new();
        if zip64_end {
            let zip64_eocd_offset = cd_offset.checked_add(cd_size).ok_or_else(too_large)?;
            end.u32(ZIP64_EOCD_SIG);
            end.u64(44); // size of the rest of the record
            end.u16(VERSION_MADE_BY);
            end.u16(VERSION_ZIP64);
            end.u32(0); // this disk
            end.u32(0); // disk of the central directory
            end.u64(count);
            end.u64(count);
            end.u64(cd_size);
            end.u64(cd_offset);
            end.u32(ZIP64_LOCATOR_SIG);
            end.u32(0); // disk of the ZIP64 end record
            end.u64(zip64_eocd_offset);
            end.u32(1); // number of disks
        }
        let count16 = if zip64_end {
            U16_MAX as u16
        } else {
            count as u16
        };
        end.u32(EOCD_SIG);
        end.u16(0); // this disk
        end.u16(0); // disk of the central directory
        end.u16(count16);
        end.u16(count16);
        end.u32(if zip64_end {
            U32_MAX as u32
        } else {
            cd_size as u32
        });
        end.u32(if zip64_end {
            U32_MAX as u32
        } else {
            cd_offset as u32
        });
        end.u16(0); // comment length
        write_all(w, &cd, path)?;
        write_all(w, &end, path)
    }
}

/// Writes the arrays to `w` as a `.npz` (ZIP) archive. With `force_zip64`, every ZIP64 field is
/// written even when not needed (tests use this to exercise the ZIP64 code on small files).
fn write_zip(
    w: &mut dyn Write,
    entries: &[(&str, &NpyArray)],
    path: &Path,
    force_zip64: bool,
) -> Result<(), IoError> {
    let mut npz = NpzWriter::new(w, path, force_zip64);
    for &(name, array) in entries {
        npz.add(name, array)?;
    }
    npz.finish()
}

/// Writes the `.npz` archive `path` atomically, array by array: `fill` calls
/// [`NpzWriter::add`] for each array, and only one array needs to be in memory at a time.
/// On any error (of `fill` or of writing) `path` is left untouched.
///
/// ```
/// # let dir = std::env::temp_dir().join(format!("phi-doc-npz-streamed-{}", std::process::id()));
/// # std::fs::create_dir_all(&dir).unwrap();
/// use phi_io::npz::{NpyArray, read_npz, write_npz_streamed};
/// let path = dir.join("many.npz");
/// write_npz_streamed(&path, |npz| {
///     for i in 0..3i64 {
///         npz.add(&format!("a{i}"), &NpyArray::from_vec(vec![i]))?;
///     }
///     Ok::<(), phi_io::IoError>(())
/// })?;
/// assert_eq!(read_npz(&path)?.len(), 3);
/// # std::fs::remove_dir_all(&dir).unwrap();
/// # Ok::<(), phi_io::IoError>(())
/// ```
pub fn write_npz_streamed<E: From<IoError>>(
    path: impl AsRef<Path>,
    fill: impl FnOnce(&mut NpzWriter<'_>) -> Result<(), E>,
) -> Result<(), E> {
    let path = path.as_ref();
    write_atomic(path, |w| {
        let mut npz = NpzWriter::new(w, path, false);
        fill(&mut npz)?;
        npz.finish()?;
        Ok(())
    })
}

/// Checks one array and its name before it is written.
fn check_entry(name: &str, array: &NpyArray, path: &Path) -> Result<(), IoError> {
    let bad = |why: &str| {
        IoError::InvalidInput(format!("'{}': array name '{name}' {why}", path.display()))
    };
    if name.is_empty() {
        return Err(bad("is empty"));
    }
    if name.len() + 4 > usize::from(u16::MAX) {
        return Err(bad("is too long"));
    }
    array
        .validate()
        .map_err(|e| IoError::InvalidInput(format!("'{}': array '{name}': {e}", path.display())))
}

/// Checks the arrays and their names before anything is written.
fn check_entries(entries: &[(&str, &NpyArray)], path: &Path) -> Result<(), IoError> {
    let mut seen = std::collections::HashSet::new();
    for &(name, array) in entries {
        check_entry(name, array, path)?;
        if !seen.insert(name) {
            return Err(IoError::InvalidInput(format!(
                "'{}': array name '{name}' appears twice",
                path.display()
            )));
        }
    }
    Ok(())
}

/// Writes the arrays to the `.npz` archive `path`, one STORED entry `name.npy` each, in order,
/// as `numpy.savez(path, name=array, ...)` would; `numpy.load(path)[name]` gives them back.
///
/// The file is written atomically: into `.{filename}.tmp-{pid}` in the same directory, synced,
/// then renamed to `path`. ZIP64 extensions are used for entries or archives of 4 GiB and more.
/// Fails on empty or duplicate names, on arrays whose shape does not fit their data, and on I/O
/// errors (naming the path); on failure `path` is left untouched.
pub fn write_npz<S: AsRef<str>>(
    path: impl AsRef<Path>,
    arrays: &[(S, &NpyArray)],
) -> Result<(), IoError> {
    write_npz_impl(path.as_ref(), arrays, false)
}

fn write_npz_impl<S: AsRef<str>>(
    path: &Path,
    arrays: &[(S, &NpyArray)],
    force_zip64: bool,
) -> Result<(), IoError> {
    let entries: Vec<(&str, &NpyArray)> = arrays
        .iter()
        .map(|(name, array)| (name.as_ref(), *array))
        .collect();
    check_entries(&entries, path)?;
    write_atomic(path, |w| write_zip(w, &entries, path, force_zip64))
}

// ---------------------------------------------------------------------------------------------
// ZIP reading

/// Little-endian field reading with bounds checks.
struct Fields<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Fields<'a> {
    fn new(bytes: &'a [u8]) -> Self {
        Fields { bytes, pos: 0 }
    }

    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        let end = self.pos.checked_add(n)?;
        let out = self.bytes.get(self.pos..end)?;
        self.pos = end;
        Some(out)
    }

    fn u16(&mut self) -> Option<u16> {
        self.take(2).map(|b| u16::from_le_bytes([b[0], b[1]]))
    }

    fn u32(&mut self) -> Option<u32> {
        self.take(4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    fn u64(&mut self) -> Option<u64> {
        self.take(8).map(|b| {
            let mut a = [0u8; 8];
            a.copy_from_slice(b);
            u64::from_le_bytes(a)
        })
    }
}

/// One entry of the central directory.
struct CentralEntry {
    name: String,
    method: u16,
    crc: u32,
    compressed_size: u64,
    size: u64,
    local_offset: u64,
}

/// Random access to the archive file, turning short reads into "truncated" errors.
struct Archive {
    reader: BufReader<File>,
    len: u64,
    path: PathBuf,
}

impl Archive {
    fn read_at(&mut self, offset: u64, len: u64, what: &str) -> Result<Vec<u8>, IoError> {
        let end = offset.checked_add(len);
        if end.is_none_or(|end| end > self.len) {
            return Err(IoError::corrupt(
                &self.path,
                format!(
                    "{what} ({len} bytes at offset {offset}) extends past the end of the file \
                     ({} bytes)",
                    self.len
                ),
            ));
        }
        // `len` is at most the file's length, so the buffer is bounded by real data.
        let mut buf = vec![0u8; len as usize];
        self.reader
            .seek(SeekFrom::Start(offset))
            .and_then(|_| self.reader.read_exact(&mut buf))
            .map_err(|e| {
                if e.kind() == io::ErrorKind::UnexpectedEof {
                    IoError::corrupt(&self.path, format!("{what}: unexpected end of file"))
                } else {
                    IoError::io(&self.path, "cannot read", e)
                }
            })?;
        Ok(buf)
    }

    fn corrupt(&self, reason: impl Into<String>) -> IoError {
        IoError::corrupt(&self.path, reason)
    }

    /// Finds the end records and returns (number of entries, central directory offset, size).
    fn end_of_central_directory(&mut self) -> Result<(u64, u64, u64), IoError> {
        const EOCD_LEN: u64 = 22;
        if self.len < EOCD_LEN {
            return Err(self.corrupt(format!("{} bytes are too few for a ZIP archive", self.len)));
        }
        let tail_len = self.len.min(EOCD_LEN + u64::from(u16::MAX));
        let tail_start = self.len - tail_len;
        let tail = self.read_at(tail_start, tail_len, "end of archive")?;
        let sig = EOCD_SIG.to_le_bytes();
        // The record is followed by its comment and nothing else.
        let found = (0..=tail.len() - EOCD_LEN as usize).rev().find(|&i| {
            tail[i..i + 4] == sig && {
                let comment = usize::from(u16::from_le_bytes([tail[i + 20], tail[i + 21]]));
                i + EOCD_LEN as usize + comment == tail.len()
            }
        });
        let Some(i) = found else {
            return Err(self
                .corrupt("no end-of-central-directory record (not a ZIP archive, or truncated)"));
        };
        let eocd_pos = tail_start + i as u64;
        let mut f = Fields::new(&tail[i + 4..]);
        let fields = (|| Some((f.u16()?, f.u16()?, f.u16()?, f.u16()?, f.u32()?, f.u32()?)))();
        let Some((disk, cd_disk, _on_disk, count, cd_size, cd_offset)) = fields else {
            return Err(self.corrupt("short end-of-central-directory record"));
        };
        if disk != 0 || cd_disk != 0 {
            return Err(IoError::Unsupported {
                path: self.path.to_path_buf(),
                reason: "multi-disk ZIP archives".into(),
            });
        }
        let (mut count, mut cd_size, mut cd_offset) =
            (u64::from(count), u64::from(cd_size), u64::from(cd_offset));
        let mut cd_end_limit = eocd_pos;
        if (count == U16_MAX || cd_size == U32_MAX || cd_offset == U32_MAX) && eocd_pos >= 20 {
            let locator = self.read_at(eocd_pos - 20, 20, "ZIP64 end locator")?;
            let mut f = Fields::new(&locator);
            if f.u32() == Some(ZIP64_LOCATOR_SIG) {
                let record_offset = f.u32().and_then(|_| f.u64()).unwrap_or(u64::MAX);
                let record = self.read_at(record_offset, 56, "ZIP64 end record")?;
                let mut f = Fields::new(&record);
                let fields = (|| {
                    let sig = f.u32()?;
                    f.take(20)?; // record size, versions, disk numbers
                    Some((sig, f.u64()?, f.u64()?, f.u64()?, f.u64()?))
                })();
                match fields {
                    Some((ZIP64_EOCD_SIG, _on_disk, total, size, offset)) => {
                        (count, cd_size, cd_offset) = (total, size, offset);
                        cd_end_limit = record_offset;
                    }
                    _ => return Err(self.corrupt("invalid ZIP64 end-of-central-directory record")),
                }
            }
        }
        if cd_offset
            .checked_add(cd_size)
            .is_none_or(|end| end > cd_end_limit)
        {
            return Err(self.corrupt(format!(
                "central directory ({cd_size} bytes at offset {cd_offset}) overlaps the end \
                 records at offset {cd_end_limit}"
            )));
        }
        Ok((count, cd_offset, cd_size))
    }

    fn central_directory(&mut self) -> Result<Vec<CentralEntry>, IoError> {
        let (count, cd_offset, cd_size) = self.end_of_central_directory()?;
        let cd = self.read_at(cd_offset, cd_size, "central directory")?;
        let mut f = Fields::new(&cd);
        let mut entries = Vec::with_capacity(count.min(cd_size / 46) as usize);
        for index in 0..count {
            let entry = parse_central_entry(&mut f).ok_or_else(|| {
                self.corrupt(format!("central directory entry {index} is damaged"))
            })?;
            if entry.flags & 1 != 0 {
                return Err(IoError::Unsupported {
                    path: self.path.to_path_buf(),
                    reason: format!("entry '{}' is encrypted", entry.entry.name),
                });
            }
            entries.push(entry.entry);
        }
        Ok(entries)
    }

    /// Checks the local header of `entry` and returns where its data starts.
    fn data_offset(&mut self, entry: &CentralEntry) -> Result<u64, IoError> {
        let name = &entry.name;
        let local = self.read_at(entry.local_offset, 30, "local file header")?;
        let mut f = Fields::new(&local);
        let sig = f.u32();
        f.take(22);
        let (name_len, extra_len) = (f.u16(), f.u16());
        let (Some(LOCAL_HEADER_SIG), Some(name_len), Some(extra_len)) = (sig, name_len, extra_len)
        else {
            return Err(self.corrupt(format!("entry '{name}': invalid local file header")));
        };
        let local_name = self.read_at(
            entry.local_offset + 30,
            u64::from(name_len),
            "local file name",
        )?;
        if String::from_utf8_lossy(&local_name) != *name {
            return Err(self.corrupt(format!(
                "entry '{name}': the local header names '{}'",
                String::from_utf8_lossy(&local_name)
            )));
        }
        Ok(entry.local_offset + 30 + u64::from(name_len) + u64::from(extra_len))
    }

    /// Reads, decompresses and checks the bytes of one entry.
    fn entry_bytes(&mut self, entry: &CentralEntry) -> Result<Vec<u8>, IoError> {
        let name = &entry.name;
        let data_offset = self.data_offset(entry)?;
        let raw = self.read_at(
            data_offset,
            entry.compressed_size,
            &format!("data of entry '{name}'"),
        )?;
        let bytes = match entry.method {
            METHOD_STORED => {
                if entry.size != entry.compressed_size {
                    return Err(self.corrupt(format!(
                        "stored entry '{name}' has different compressed ({}) and uncompressed \
                         ({}) sizes",
                        entry.compressed_size, entry.size
                    )));
                }
                raw
            }
            METHOD_DEFLATED => {
                // Deflate expands at most ~1032:1; a larger claim is damage, and checking it
                // bounds the allocation below.
                if entry.size
                    > entry
                        .compressed_size
                        .saturating_mul(1032)
                        .saturating_add(1024)
                {
                    return Err(self.corrupt(format!(
                        "entry '{name}' claims {} bytes from {} compressed bytes",
                        entry.size, entry.compressed_size
                    )));
                }
                let mut out = Vec::with_capacity(entry.size as usize);
                flate2::read::DeflateDecoder::new(raw.as_slice())
                    .take(entry.size.saturating_add(1))
                    .read_to_end(&mut out)
                    .map_err(|e| {
                        self.corrupt(format!("entry '{name}': invalid deflate data: {e}"))
                    })?;
                if out.len() as u64 != entry.size {
                    return Err(self.corrupt(format!(
                        "entry '{name}' inflates to {} bytes instead of {}",
                        out.len(),
                        entry.size
                    )));
                }
                out
            }
            method => {
                return Err(IoError::Unsupported {
                    path: self.path.to_path_buf(),
                    reason: format!(
                        "entry '{name}' uses ZIP compression method {method} (only stored and \
                         deflate are supported)"
                    ),
                });
            }
        };
        let crc = crc32fast::hash(&bytes);
        if crc != entry.crc {
            return Err(self.corrupt(format!(
                "entry '{name}': CRC-32 mismatch (recorded {:#010x}, computed {crc:#010x})",
                entry.crc
            )));
        }
        Ok(bytes)
    }
}

/// A central directory entry and its general purpose flags.
struct ParsedCentralEntry {
    entry: CentralEntry,
    flags: u16,
}

fn parse_central_entry(f: &mut Fields<'_>) -> Option<ParsedCentralEntry> {
    if f.u32()? != CENTRAL_HEADER_SIG {
        return None;
    }
    f.take(4)?; // versions
    let flags = f.u16()?;
    let method = f.u16()?;
    f.take(4)?; // time, date
    let crc = f.u32()?;
    let mut compressed_size = u64::from(f.u32()?);
    let mut size = u64::from(f.u32()?);
    let name_len = usize::from(f.u16()?);
    let extra_len = usize::from(f.u16()?);
    let comment_len = usize::from(f.u16()?);
    f.take(8)?; // disk number, internal and external attributes
    let mut local_offset = u64::from(f.u32()?);
    let name = String::from_utf8_lossy(f.take(name_len)?).into_owned();
    let mut extra = Fields::new(f.take(extra_len)?);
    f.take(comment_len)?;
    if size == U32_MAX || compressed_size == U32_MAX || local_offset == U32_MAX {
        // The ZIP64 extra field holds the saturated fields, in this order.
        let mut zip64 = loop {
            let id = extra.u16()?;
            let len = usize::from(extra.u16()?);
            let data = extra.take(len)?;
            if id == ZIP64_EXTRA_ID {
                break Fields::new(data);
            }
        };
        if size == U32_MAX {
            size = zip64.u64()?;
        }
        if compressed_size == U32_MAX {
            compressed_size = zip64.u64()?;
        }
        if local_offset == U32_MAX {
            local_offset = zip64.u64()?;
        }
    }
    Some(ParsedCentralEntry {
        entry: CentralEntry {
            name,
            method,
            crc,
            compressed_size,
            size,
            local_offset,
        },
        flags,
    })
}

/// The dtype and shape of an array, read from its `.npy` header by [`NpzReader::header`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NpyHeader {
    /// The NumPy type descriptor, e.g. `"<f4"`.
    pub descr: String,
    /// The extent of each axis.
    pub shape: Vec<usize>,
}

/// Random access to the arrays of one `.npz` archive: the central directory is read on
/// [`NpzReader::open`], and [`NpzReader::read`] then reads (and CRC-checks) only the entry asked
/// for, so a few small arrays of a large archive cost a few small reads.
///
/// ```
/// # let dir = std::env::temp_dir().join(format!("phi-doc-npz-reader-{}", std::process::id()));
/// # std::fs::create_dir_all(&dir).unwrap();
/// use phi_io::npz::{NpyArray, NpzReader, write_npz};
/// let path = dir.join("a.npz");
/// let big = NpyArray::from_vec(vec![0f32; 1000]);
/// let small = NpyArray::from_vec(vec![7i64]);
/// write_npz(&path, &[("big", &big), ("small", &small)])?;
/// let mut npz = NpzReader::open(&path)?;
/// assert_eq!(npz.names().collect::<Vec<_>>(), ["big", "small"]);
/// assert_eq!(npz.read("small")?.as_i64(), Some(&[7i64][..]));
/// # std::fs::remove_dir_all(&dir).unwrap();
/// # Ok::<(), phi_io::IoError>(())
/// ```
pub struct NpzReader {
    archive: Archive,
    /// The `.npy` entries (directory entries left out), in archive order.
    entries: Vec<CentralEntry>,
}

impl NpzReader {
    /// Opens the archive and reads its central directory.
    ///
    /// Fails with [`IoError::Corrupt`] (naming the file) on truncated or damaged archives,
    /// [`IoError::Unsupported`] on entries that are not `.npy` arrays, and [`IoError::Io`] on I/O
    /// errors.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, IoError> {
        let path = path.as_ref();
        let file = File::open(path).map_err(|e| IoError::io(path, "cannot open", e))?;
        let len = file
            .metadata()
            .map_err(|e| IoError::io(path, "cannot read the metadata of", e))?
            .len();
        let mut archive = Archive {
            reader: BufReader::new(file),
            len,
            path: path.to_path_buf(),
        };
        let mut entries = archive.central_directory()?;
        // Directory entries hold nothing.
        entries.retain(|entry| !entry.name.ends_with('/'));
        if let Some(entry) = entries.iter().find(|e| !e.name.ends_with(".npy")) {
            return Err(IoError::Unsupported {
                path: path.to_path_buf(),
                reason: format!("entry '{}' is not a .npy array", entry.name),
            });
        }
        Ok(NpzReader { archive, entries })
    }

    /// The file this reader reads.
    pub fn path(&self) -> &Path {
        &self.archive.path
    }

    /// The names of the arrays (without the `.npy` suffix), in archive order.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.entries
            .iter()
            .map(|entry| entry.name.strip_suffix(".npy").unwrap_or(&entry.name))
    }

    /// Whether the archive holds an array called `name`.
    pub fn contains(&self, name: &str) -> bool {
        self.names().any(|n| n == name)
    }

    /// Reads the array `name`, checking the entry's CRC-32.
    ///
    /// Fails with [`IoError::MissingArray`] when there is no such array, and otherwise as
    /// [`read_npz`] does.
    pub fn read(&mut self, name: &str) -> Result<NpyArray, IoError> {
        let index = self
            .names()
            .position(|n| n == name)
            .ok_or_else(|| IoError::MissingArray {
                path: self.archive.path.clone(),
                name: name.to_string(),
            })?;
        self.read_index(index)
    }

    /// Reads the `index`-th array in archive order.
    fn read_index(&mut self, index: usize) -> Result<NpyArray, IoError> {
        let entry = &self.entries[index];
        let bytes = self.archive.entry_bytes(entry)?;
        parse_npy(&bytes).map_err(|issue| {
            npy_issue_error(
                &self.archive.path,
                &format!("entry '{}'", entry.name),
                issue,
            )
        })
    }

    /// The dtype and shape of the array `name`, without reading its data when the entry is
    /// stored (not compressed): only the `.npy` header is read, and the entry's size is checked
    /// against it, but its CRC-32 is not (that needs all the data; [`NpzReader::read`] checks it).
    pub fn header(&mut self, name: &str) -> Result<NpyHeader, IoError> {
        let index = self.index_of(name)?;
        let entry = &self.entries[index];
        let what = format!("entry '{}'", entry.name);
        let (prefix, size) = if entry.method == METHOD_STORED {
            let offset = self.archive.data_offset(entry)?;
            let size = entry.size;
            let preamble = self.archive.read_at(
                offset,
                size.min(NPY_PREAMBLE_MAX as u64),
                &format!("header of {what}"),
            )?;
            let header_end = match preamble.get(6..12) {
                Some([1, _, a, b, ..]) => 10 + u64::from(u16::from_le_bytes([*a, *b])),
                Some([2 | 3, _, a, b, c, d]) => {
                    12 + u64::from(u32::from_le_bytes([*a, *b, *c, *d]))
                }
                _ => preamble.len() as u64,
            };
            let prefix =
                self.archive
                    .read_at(offset, header_end.min(size), &format!("header of {what}"))?;
            (prefix, size)
        } else {
            let bytes = self.archive.entry_bytes(entry)?;
            let size = bytes.len() as u64;
            (bytes, size)
        };
        let path = &self.archive.path;
        let parsed =
            parse_npy_header(&prefix).map_err(|issue| npy_issue_error(path, &what, issue))?;
        let item_size: u64 = match parsed.dtype {
            Dtype::F32 | Dtype::I32 => 4,
            Dtype::F64 | Dtype::I64 => 8,
            Dtype::U8 | Dtype::Bool => 1,
        };
        let data_len = element_count(&parsed.shape)
            .and_then(|n| (n as u64).checked_mul(item_size))
            .and_then(|n| n.checked_add(parsed.data_start as u64));
        if data_len != Some(size) {
            return Err(IoError::corrupt(
                path,
                format!(
                    "{what}: shape {:?} of '{}' does not fit the entry's {size} bytes",
                    parsed.shape, parsed.descr
                ),
            ));
        }
        Ok(NpyHeader {
            descr: parsed.descr,
            shape: parsed.shape,
        })
    }

    fn index_of(&self, name: &str) -> Result<usize, IoError> {
        self.names()
            .position(|n| n == name)
            .ok_or_else(|| IoError::MissingArray {
                path: self.archive.path.clone(),
                name: name.to_string(),
            })
    }

    /// Reads every array, in archive order, named without the `.npy` suffix.
    pub fn read_all(&mut self) -> Result<Vec<(String, NpyArray)>, IoError> {
        let names: Vec<String> = self.names().map(str::to_string).collect();
        let mut arrays = Vec::with_capacity(names.len());
        for (index, name) in names.into_iter().enumerate() {
            arrays.push((name, self.read_index(index)?));
        }
        Ok(arrays)
    }
}

/// Reads the `.npz` archive `path`: its arrays in archive order, named without the `.npy`
/// suffix.
///
/// Reads what [`write_npz`], `numpy.savez` and `numpy.savez_compressed` write: STORED or
/// deflate-compressed entries, with or without ZIP64 extensions. Every entry's CRC-32 is checked.
/// Fails with [`IoError::Corrupt`] (naming the file) on truncated or damaged archives,
/// [`IoError::Unsupported`] on entries that are not `.npy` arrays of a supported dtype or use
/// another compression method, and [`IoError::Io`] on I/O errors.
pub fn read_npz(path: impl AsRef<Path>) -> Result<Vec<(String, NpyArray)>, IoError> {
    NpzReader::open(path)?.read_all()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::temp_dir;
    use std::process::Command;

    fn sample_arrays() -> Vec<(&'static str, NpyArray)> {
        vec![
            (
                "positions",
                NpyArray::new(
                    vec![2, 3],
                    vec![0.5f32, -1.25, 3.0, f32::MAX, f32::MIN_POSITIVE, -0.0],
                )
                .unwrap(),
            ),
            (
                "f64",
                NpyArray::new(vec![3], vec![std::f64::consts::PI, -1e300, 1e-300]).unwrap(),
            ),
            (
                "i32",
                NpyArray::new(vec![2, 2], vec![i32::MIN, -1, 0, i32::MAX]).unwrap(),
            ),
            (
                "i64",
                NpyArray::new(vec![1, 2, 2], vec![i64::MIN, -7, 7, i64::MAX]).unwrap(),
            ),
            (
                "kinds",
                NpyArray::new(vec![5], vec![0u8, 1, 2, 254, 255]).unwrap(),
            ),
            ("scalar", NpyArray::new(vec![], vec![42.0f64]).unwrap()),
            (
                "empty",
                NpyArray::new(vec![0, 3], Vec::<f32>::new()).unwrap(),
            ),
        ]
    }

    fn as_refs<'a>(arrays: &'a [(&'static str, NpyArray)]) -> Vec<(&'static str, &'a NpyArray)> {
        arrays.iter().map(|(n, a)| (*n, a)).collect()
    }

    #[test]
    fn constructors_check_shape() {
        assert!(NpyArray::new(vec![2, 3], vec![0f32; 6]).is_ok());
        let err = NpyArray::new(vec![2, 3], vec![0f32; 5]).unwrap_err();
        assert!(
            matches!(err, IoError::ShapeMismatch { len: 5, .. }),
            "{err}"
        );
        assert!(NpyArray::new(vec![usize::MAX, 3], vec![0u8; 3]).is_err());
        assert_eq!(NpyArray::from_vec(vec![1i64, 2]).shape, vec![2]);
        let bad = NpyArray {
            shape: vec![4],
            data: ArrayData::U8(vec![1]),
        };
        assert!(write_npy_bytes(&bad).is_err());
        let dir = temp_dir("bad-shape");
        let err = write_npz(dir.join("x.npz"), &[("x", &bad)]).unwrap_err();
        assert!(err.to_string().contains("array 'x'"), "{err}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn npy_round_trip_every_dtype() {
        for (name, array) in sample_arrays() {
            let bytes = write_npy_bytes(&array).unwrap();
            let back = read_npy_bytes(&bytes).unwrap();
            assert_eq!(back, array, "{name}");
        }
    }

    #[test]
    fn npy_header_is_aligned_and_well_formed() {
        for (name, array) in sample_arrays() {
            let bytes = write_npy_bytes(&array).unwrap();
            assert_eq!(&bytes[..8], b"\x93NUMPY\x01\x00", "{name}");
            let header_len = usize::from(u16::from_le_bytes([bytes[8], bytes[9]]));
            let data_start = 10 + header_len;
            assert_eq!(data_start % 64, 0, "{name}");
            assert_eq!(bytes[data_start - 1], b'\n', "{name}");
            assert_eq!(
                bytes.len() - data_start,
                array.len() * array.data.item_size()
            );
            let header = std::str::from_utf8(&bytes[10..data_start]).unwrap();
            assert!(header.contains(&format!("'descr': '{}'", array.data.descr())));
            assert!(header.contains("'fortran_order': False"));
        }
        let bytes = write_npy_bytes(&NpyArray::from_vec(vec![1.0f32, 2.0])).unwrap();
        assert!(String::from_utf8_lossy(&bytes).contains("'shape': (2,), }"));
        let bytes = write_npy_bytes(&NpyArray::new(vec![], vec![1u8]).unwrap()).unwrap();
        assert!(String::from_utf8_lossy(&bytes).contains("'shape': (), }"));
    }

    #[test]
    fn npy_reader_accepts_numpy_variants() {
        // Big-endian, Fortran order, bool and an older-style header with extra spacing.
        let header = |dict: &str| {
            let mut h = b"\x93NUMPY\x01\x00".to_vec();
            let len = (10 + dict.len() + 1).div_ceil(64) * 64 - 10;
            h.extend_from_slice(&(len as u16).to_le_bytes());
            h.extend_from_slice(dict.as_bytes());
            h.resize(10 + len - 1, b' ');
            h.push(b'\n');
            h
        };
        let mut be = header("{'descr': '>i4', 'fortran_order': False, 'shape': (2,), }");
        be.extend_from_slice(&[0, 0, 0, 1, 0xFF, 0xFF, 0xFF, 0xFE]);
        assert_eq!(read_npy_bytes(&be).unwrap().as_i32(), Some(&[1, -2][..]));

        // [[1, 2, 3], [4, 5, 6]] stored column by column.
        let mut f = header("{\"descr\":\"<f8\",\"fortran_order\":True,\"shape\":(2,3)}");
        for v in [1.0f64, 4.0, 2.0, 5.0, 3.0, 6.0] {
            f.extend_from_slice(&v.to_le_bytes());
        }
        let a = read_npy_bytes(&f).unwrap();
        assert_eq!(a.shape, vec![2, 3]);
        assert_eq!(a.as_f64(), Some(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0][..]));

        let mut b = header("{'descr': '|b1', 'fortran_order': False, 'shape': (3,), }");
        b.extend_from_slice(&[1, 0, 1]);
        assert_eq!(read_npy_bytes(&b).unwrap().as_u8(), Some(&[1, 0, 1][..]));

        let mut c = header("{'descr': '<c16', 'fortran_order': False, 'shape': (1,), }");
        c.extend_from_slice(&[0; 16]);
        let err = read_npy_bytes(&c).unwrap_err().to_string();
        assert!(err.contains("unsupported") && err.contains("<c16"), "{err}");

        let s = header("{'descr': [('a', '<f4')], 'fortran_order': False, 'shape': (1,), }");
        let err = read_npy_bytes(&s).unwrap_err().to_string();
        assert!(err.contains("structured"), "{err}");
    }

    #[test]
    fn fortran_to_c_three_axes() {
        // shape (2, 3, 2); Fortran offset of (i, j, k) is i + 2 j + 6 k.
        let shape = [2, 3, 2];
        let fortran: Vec<usize> = (0..12).collect();
        let c = fortran_to_c(fortran, &shape);
        let mut expected = Vec::new();
        for i in 0..2 {
            for j in 0..3 {
                for k in 0..2 {
                    expected.push(i + 2 * j + 6 * k);
                }
            }
        }
        assert_eq!(c, expected);
    }

    #[test]
    fn npy_reader_rejects_garbage_without_panicking() {
        let good = write_npy_bytes(&sample_arrays()[0].1).unwrap();
        for len in 0..good.len() {
            assert!(
                read_npy_bytes(&good[..len]).is_err(),
                "prefix of {len} bytes"
            );
        }
        for i in 0..good.len() {
            for x in [0x01u8, 0x80, 0xFF] {
                let mut bad = good.clone();
                bad[i] ^= x;
                let _ = read_npy_bytes(&bad);
            }
        }
    }

    #[test]
    fn npy_file_round_trip() {
        let dir = temp_dir("npy-file");
        let path = dir.join("a.npy");
        let array = &sample_arrays()[3].1;
        write_npy(&path, array).unwrap();
        assert_eq!(&read_npy(&path).unwrap(), array);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn npz_round_trip_every_dtype() {
        let dir = temp_dir("npz-round-trip");
        let arrays = sample_arrays();
        for force_zip64 in [false, true] {
            let path = dir.join(format!("data-{force_zip64}.npz"));
            write_npz_impl(&path, &as_refs(&arrays), force_zip64).unwrap();
            let back = read_npz(&path).unwrap();
            assert_eq!(back.len(), arrays.len());
            for ((name, array), (back_name, back_array)) in arrays.iter().zip(&back) {
                assert_eq!(name, back_name);
                assert_eq!(array, back_array, "{name}");
            }
        }
        // An archive with no arrays is valid too.
        let path = dir.join("empty.npz");
        write_npz::<&str>(&path, &[]).unwrap();
        assert!(read_npz(&path).unwrap().is_empty());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn npz_rejects_bad_names() {
        let dir = temp_dir("npz-names");
        let a = NpyArray::from_vec(vec![1u8]);
        let path = dir.join("x.npz");
        assert!(write_npz(&path, &[("a", &a), ("a", &a)]).is_err());
        assert!(write_npz(&path, &[("", &a)]).is_err());
        assert!(!path.exists());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn truncated_npz_is_reported_with_its_path() {
        let dir = temp_dir("npz-truncated");
        let path = dir.join("trunc.npz");
        let arrays = sample_arrays();
        write_npz(&path, &as_refs(&arrays)).unwrap();
        let full = std::fs::read(&path).unwrap();
        for len in 0..full.len() {
            std::fs::write(&path, &full[..len]).unwrap();
            let err = read_npz(&path).expect_err("a truncated archive must not load");
            let msg = err.to_string();
            assert!(msg.contains("trunc.npz"), "{msg}");
            assert!(matches!(err, IoError::Corrupt { .. }), "{msg}");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn flipped_byte_is_reported_with_its_path() {
        let dir = temp_dir("npz-flipped");
        let path = dir.join("flip.npz");
        let array =
            NpyArray::new(vec![4, 2], (0..8).map(|i| i as f32).collect::<Vec<_>>()).unwrap();
        write_npz(&path, &[("x", &array)]).unwrap();
        let good = std::fs::read(&path).unwrap();
        // The data of the only entry starts after the local header (30 bytes + "x.npy") and the
        // 64-byte .npy header.
        let data_start = 30 + 5 + 64;
        let mut bad = good.clone();
        bad[data_start + 5] ^= 0x10;
        std::fs::write(&path, &bad).unwrap();
        let msg = read_npz(&path).unwrap_err().to_string();
        assert!(msg.contains("flip.npz") && msg.contains("CRC-32"), "{msg}");

        // Any single damaged byte either loads (a field the reader ignores, like a timestamp)
        // or gives an error naming the file; it never panics.
        for i in 0..good.len() {
            let mut bad = good.clone();
            bad[i] ^= 0xA5;
            std::fs::write(&path, &bad).unwrap();
            match read_npz(&path) {
                Ok(arrays) if (30 + 5..30 + 5 + 64 + 32).contains(&i) => {
                    panic!("damage to the entry at byte {i} went unnoticed: {arrays:?}")
                }
                Ok(_) => {}
                Err(e) => assert!(e.to_string().contains("flip.npz"), "{e}"),
            }
        }
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn missing_file_is_reported_with_its_path() {
        let err = read_npz("/nonexistent/phi-missing.npz")
            .unwrap_err()
            .to_string();
        assert!(err.contains("/nonexistent/phi-missing.npz"), "{err}");
    }

    #[test]
    fn reads_deflated_entries() {
        // A deflate-compressed entry, as numpy.savez_compressed writes, built by hand.
        use flate2::{Compression, write::DeflateEncoder};
        let array = NpyArray::new(vec![3, 2], vec![1i64, 2, 3, 4, 5, 6]).unwrap();
        let npy = write_npy_bytes(&array).unwrap();
        let mut enc = DeflateEncoder::new(Vec::new(), Compression::default());
        enc.write_all(&npy).unwrap();
        let compressed = enc.finish().unwrap();
        let name = b"a.npy";
        let crc = crc32fast::hash(&npy);
        let mut zip = Vec::new();
        zip.u32(LOCAL_HEADER_SIG);
        zip.u16(20);
        zip.u16(0);
        zip.u16(METHOD_DEFLATED);
        zip.u32(0);
        zip.u32(crc);
        zip.u32(compressed.len() as u32);
        zip.u32(npy.len() as u32);
        zip.u16(name.len() as u16);
        zip.u16(0);
        zip.extend_from_slice(name);
        zip.extend_from_slice(&compressed);
        let cd_offset = zip.len();
        zip.u32(CENTRAL_HEADER_SIG);
        zip.u16(20);
        zip.u16(20);
        zip.u16(0);
        zip.u16(METHOD_DEFLATED);
        zip.u32(0);
        zip.u32(crc);
        zip.u32(compressed.len() as u32);
        zip.u32(npy.len() as u32);
        zip.u16(name.len() as u16);
        zip.extend_from_slice(&[0; 12]);
        zip.u32(0);
        zip.extend_from_slice(name);
        let cd_size = zip.len() - cd_offset;
        zip.u32(EOCD_SIG);
        zip.extend_from_slice(&[0; 4]);
        zip.u16(1);
        zip.u16(1);
        zip.u32(cd_size as u32);
        zip.u32(cd_offset as u32);
        zip.u16(0);
        let dir = temp_dir("npz-deflate");
        let path = dir.join("c.npz");
        std::fs::write(&path, &zip).unwrap();
        let back = read_npz(&path).unwrap();
        assert_eq!(back, vec![("a".to_string(), array)]);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn dos_dates() {
        assert_eq!(civil_from_days(0), (1970, 1, 1));
        assert_eq!(civil_from_days(11_017), (2000, 3, 1));
        assert_eq!(civil_from_days(19_782), (2024, 2, 29));
        let t = UNIX_EPOCH + std::time::Duration::from_secs(19_782 * 86_400 + 13 * 3600 + 62);
        let (time, date) = dos_time_date(t);
        assert_eq!(date, ((2024 - 1980) << 9) | (2 << 5) | 29);
        assert_eq!(time, (13 << 11) | (1 << 5) | 1);
        assert_eq!(dos_time_date(UNIX_EPOCH), (0, (1 << 5) | 1));
    }

    fn numpy_available() -> bool {
        Command::new("python3")
            .args(["-c", "import numpy"])
            .output()
            .is_ok_and(|o| o.status.success())
    }

    fn python(script: &str) -> String {
        let out = Command::new("python3")
            .args(["-c", script])
            .output()
            .expect("run python3");
        assert!(
            out.status.success(),
            "python failed:\n{}\n{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    }

    #[test]
    fn numpy_interop() {
        if !numpy_available() {
            println!("note: skipping numpy_interop, `python3 -c 'import numpy'` failed");
            return;
        }
        let dir = temp_dir("npz-numpy");
        let arrays = sample_arrays();

        // numpy reads what we write, plain and with ZIP64 records.
        for force_zip64 in [false, true] {
            let path = dir.join(format!("ours-{force_zip64}.npz"));
            write_npz_impl(&path, &as_refs(&arrays), force_zip64).unwrap();
            let script = format!(
                r#"
import numpy as np
d = np.load({path:?})
f32 = np.float32
exp = {{
    'positions': np.array([[0.5, -1.25, 3.0], [np.finfo(f32).max, np.finfo(f32).tiny, -0.0]], dtype=f32),
    'f64': np.array([np.pi, -1e300, 1e-300]),
    'i32': np.array([[-2**31, -1], [0, 2**31 - 1]], dtype=np.int32),
    'i64': np.array([[[-2**63, -7], [7, 2**63 - 1]]], dtype=np.int64),
    'kinds': np.array([0, 1, 2, 254, 255], dtype=np.uint8),
    'scalar': np.array(42.0),
    'empty': np.zeros((0, 3), dtype=f32),
}}
assert list(d.keys()) == list(exp.keys()), list(d.keys())
for k, v in exp.items():
    a = d[k]
    assert a.dtype == v.dtype and a.shape == v.shape, (k, a.dtype, a.shape)
    assert np.array_equal(a, v), (k, a, v)
    assert a.flags['C_CONTIGUOUS']
print('ok')
"#,
                path = path.display().to_string()
            );
            assert_eq!(python(&script).trim(), "ok");
        }

        // We read what numpy writes, compressed or not, including Fortran-ordered, big-endian
        // and bool arrays.
        for (func, file) in [("savez", "np.npz"), ("savez_compressed", "npc.npz")] {
            let path = dir.join(file);
            let script = format!(
                r#"
import numpy as np
np.{func}({path:?},
    a=np.arange(12, dtype=np.float32).reshape(3, 4),
    b=np.asfortranarray(np.arange(6, dtype=np.int64).reshape(2, 3)),
    c=np.array([1.5, -2.5], dtype='>f8'),
    d=np.array([True, False, True]),
    e=np.arange(1000, dtype=np.int32) % 7,
    f=np.array(7, dtype=np.uint8))
"#,
                path = path.display().to_string()
            );
            python(&script);
            let back = read_npz(&path).unwrap();
            let names: Vec<&str> = back.iter().map(|(n, _)| n.as_str()).collect();
            assert_eq!(names, ["a", "b", "c", "d", "e", "f"], "{func}");
            let get = |n: &str| &back.iter().find(|(k, _)| k == n).unwrap().1;
            let a = get("a");
            assert_eq!(a.shape, vec![3, 4]);
            assert_eq!(
                a.as_f32().unwrap(),
                (0..12).map(|i| i as f32).collect::<Vec<_>>()
            );
            let b = get("b");
            assert_eq!(b.shape, vec![2, 3]);
            assert_eq!(b.as_i64().unwrap(), &[0, 1, 2, 3, 4, 5]);
            assert_eq!(get("c").as_f64().unwrap(), &[1.5, -2.5]);
            assert_eq!(get("d").as_u8().unwrap(), &[1, 0, 1]);
            let e = get("e").as_i32().unwrap();
            assert_eq!(e.len(), 1000);
            assert!(e.iter().enumerate().all(|(i, &v)| v == (i % 7) as i32));
            let f = get("f");
            assert!(f.shape.is_empty());
            assert_eq!(f.as_u8().unwrap(), &[7]);
        }
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn reader_reads_single_arrays_and_headers() {
        let dir = temp_dir("npz-reader");
        let arrays = sample_arrays();
        for force_zip64 in [false, true] {
            let path = dir.join(format!("r-{force_zip64}.npz"));
            write_npz_impl(&path, &as_refs(&arrays), force_zip64).unwrap();
            let mut npz = NpzReader::open(&path).unwrap();
            let names: Vec<&str> = npz.names().collect();
            assert_eq!(names, arrays.iter().map(|(n, _)| *n).collect::<Vec<_>>());
            // Out of order, one at a time.
            for (name, array) in arrays.iter().rev() {
                assert_eq!(&npz.read(name).unwrap(), array);
                let header = npz.header(name).unwrap();
                assert_eq!(header.shape, array.shape);
                assert_eq!(header.descr, array.data.descr());
            }
            assert!(npz.contains("i64") && !npz.contains("nope"));
            let err = npz.read("nope").unwrap_err();
            assert!(matches!(err, IoError::MissingArray { .. }), "{err}");
            assert!(err.to_string().contains("r-"), "{err}");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn header_checks_the_entry_size() {
        let dir = temp_dir("npz-header-size");
        let path = dir.join("h.npz");
        let array = NpyArray::new(vec![4, 2], vec![1.5f32; 8]).unwrap();
        write_npz(&path, &[("a", &array)]).unwrap();
        let mut bytes = std::fs::read(&path).unwrap();
        // Claim a shape of (5, 2) in the header: same header length, wrong data size.
        let at = bytes.windows(6).position(|w| w == b"(4, 2)").unwrap();
        bytes[at + 1] = b'5';
        std::fs::write(&path, &bytes).unwrap();
        let err = NpzReader::open(&path).unwrap().header("a").unwrap_err();
        assert!(matches!(err, IoError::Corrupt { .. }), "{err}");
        assert!(err.to_string().contains("h.npz"), "{err}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn streamed_writing_matches_write_npz_and_is_atomic() {
        let dir = temp_dir("npz-streamed");
        let arrays = sample_arrays();
        let (one_go, streamed) = (dir.join("one.npz"), dir.join("streamed.npz"));
        write_npz(&one_go, &as_refs(&arrays)).unwrap();
        write_npz_streamed(&streamed, |npz| {
            for (name, array) in &arrays {
                npz.add(name, array)?;
            }
            Ok::<(), IoError>(())
        })
        .unwrap();
        assert_eq!(read_npz(&one_go).unwrap(), read_npz(&streamed).unwrap());

        // A failure half-way leaves the old file in place and no temporary file.
        let err = write_npz_streamed(&streamed, |npz| {
            npz.add("x", &arrays[0].1)?;
            npz.add("x", &arrays[1].1)
        })
        .unwrap_err();
        assert!(err.to_string().contains("appears twice"), "{err}");
        assert_eq!(read_npz(&streamed).unwrap().len(), arrays.len());
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 2);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
