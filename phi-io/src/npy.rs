//! NumPy `.npy` arrays: one n-dimensional array in the
//! [`.npy` format](https://numpy.org/doc/stable/reference/generated/numpy.lib.format.html).
//!
//! - [`write_npy_bytes`] / [`read_npy_bytes`] convert one array to and from its `.npy` encoding
//!   (version 1.0, little-endian, C order; version 2.0 only for headers above 64 KiB);
//! - [`write_npy`] / [`read_npy`] do the same with a file.
//!
//! Supported dtypes: `float32`, `float64`, `int32`, `int64`, `uint8` ([`ArrayData`]). The reader
//! also accepts big-endian data, Fortran-ordered arrays (converted to C order) and `bool` arrays
//! (read as [`ArrayData::U8`] holding 0 and 1). `.npz` archives of such arrays are [`crate::npz`].

use std::path::Path;

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
    pub(crate) fn item_size(&self) -> usize {
        match self {
            ArrayData::F32(_) | ArrayData::I32(_) => 4,
            ArrayData::F64(_) | ArrayData::I64(_) => 8,
            ArrayData::U8(_) => 1,
        }
    }

    /// Calls `f` with the little-endian bytes of the elements, a bounded chunk at a time (so that
    /// no copy of the whole array is made).
    pub(crate) fn for_each_le_chunk<E>(
        &self,
        mut f: impl FnMut(&[u8]) -> Result<(), E>,
    ) -> Result<(), E> {
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
pub(crate) fn element_count(shape: &[usize]) -> Option<usize> {
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
    pub(crate) fn npy_size(&self, header: &[u8]) -> Option<u64> {
        let data = (self.data.len() as u64).checked_mul(self.data.item_size() as u64)?;
        data.checked_add(header.len() as u64)
    }
}

const NPY_MAGIC: &[u8; 6] = b"\x93NUMPY";

/// The `.npy` header (magic, version, length and the padded dictionary) for `array`.
pub(crate) fn npy_header(array: &NpyArray) -> Vec<u8> {
    npy_header_for(array.data.descr(), &array.shape)
}

/// The `.npy` header for an array of type descriptor `descr` (e.g. `"<f4"`, or `"|O"` for an
/// array of Python objects) and shape `shape`.
pub(crate) fn npy_header_for(descr: &str, shape: &[usize]) -> Vec<u8> {
    let shape = match shape {
        [] => "()".to_string(),
        [n] => format!("({n},)"),
        dims => {
            let dims: Vec<String> = dims.iter().map(|d| d.to_string()).collect();
            format!("({})", dims.join(", "))
        }
    };
    let dict = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}");
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

/// The dtype and shape of an array, read from its `.npy` header alone (see
/// [`crate::npz::NpzReader::header`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NpyHeader {
    /// The NumPy type descriptor, e.g. `"<f4"`.
    pub descr: String,
    /// The extent of each axis.
    pub shape: Vec<usize>,
}

/// Why a `.npy` buffer could not be decoded.
pub(crate) enum NpyIssue {
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

impl Dtype {
    /// The size of one element in bytes.
    fn item_size(self) -> usize {
        match self {
            Dtype::F32 | Dtype::I32 => 4,
            Dtype::F64 | Dtype::I64 => 8,
            Dtype::U8 | Dtype::Bool => 1,
        }
    }
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
pub(crate) struct ParsedHeader {
    pub(crate) descr: String,
    dtype: Dtype,
    big_endian: bool,
    fortran_order: bool,
    pub(crate) shape: Vec<usize>,
    /// Where the data starts (the length of magic, version and header).
    data_start: usize,
}

impl ParsedHeader {
    /// The length of the whole `.npy` encoding that this header announces (header and data), `None`
    /// on overflow.
    pub(crate) fn encoded_len(&self) -> Option<u64> {
        element_count(&self.shape)
            .and_then(|n| (n as u64).checked_mul(self.dtype.item_size() as u64))
            .and_then(|n| n.checked_add(self.data_start as u64))
    }
}

/// The length of the `.npy` preamble (magic, version and header length) that tells how long the
/// header is: 10 bytes for version 1, 12 for versions 2 and 3.
pub(crate) const NPY_PREAMBLE_MAX: usize = 12;

/// Parses the magic string, version and header of a `.npy` buffer; `bytes` may stop anywhere
/// after the header.
pub(crate) fn parse_npy_header(bytes: &[u8]) -> Result<ParsedHeader, NpyIssue> {
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

pub(crate) fn parse_npy(bytes: &[u8]) -> Result<NpyArray, NpyIssue> {
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
    let item_size = dtype.item_size();
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
pub(crate) fn npy_issue_error(path: &Path, what: &str, issue: NpyIssue) -> IoError {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::{sample_arrays, temp_dir};

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
}
