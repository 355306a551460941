//! `.npy` arrays of Python objects whose items are numeric arrays, as `numpy.load(...,
//! allow_pickle=True)` reads them.
//!
//! numpy stores an array of dtype `object` (`'|O'`) as the usual `.npy` header followed by a
//! pickle of the array; `numpy.load` unpickles it and returns what comes out. Some tools store a
//! dataset that way, one object array per trajectory holding `(positions, particle_type)`
//! (geoelements/gns, for instance). This module writes the pickle for exactly that case: a
//! one-dimensional object array whose items are numeric arrays ([`NpyArray`]).
//!
//! The pickle (protocol 3, which every Python 3 reads) builds the values with public numpy
//! functions only, so that numpy 1.x and 2.x both load it without touching numpy's private
//! modules (whose names changed between the two):
//!
//! ```text
//! items = numpy.empty((len,), 'O')
//! items[i] = numpy.reshape(numpy.frombuffer(bytearray(<bytes>), '<f4'), (d0, d1, ...))
//! ```
//!
//! `bytearray` makes the unpickled arrays writable, as arrays saved by numpy are.

use crate::IoError;
use crate::npy::{NpyArray, npy_header_for};

/// Pickle opcodes of protocols 2 and 3 (Python's `Lib/pickletools.py` documents them).
mod op {
    pub(crate) const PROTO: u8 = 0x80;
    pub(crate) const GLOBAL: u8 = b'c';
    pub(crate) const BININT: u8 = b'J';
    pub(crate) const BINUNICODE: u8 = b'X';
    pub(crate) const BINBYTES: u8 = b'B';
    pub(crate) const MARK: u8 = b'(';
    pub(crate) const TUPLE: u8 = b't';
    pub(crate) const TUPLE1: u8 = 0x85;
    pub(crate) const TUPLE2: u8 = 0x86;
    pub(crate) const REDUCE: u8 = b'R';
    pub(crate) const SETITEMS: u8 = b'u';
    pub(crate) const STOP: u8 = b'.';
}

/// The pickle protocol written.
const PROTOCOL: u8 = 3;

/// The `.npy` encoding of a one-dimensional array of dtype `object` whose item `i` is the
/// numeric array `items[i]`: `numpy.load(..., allow_pickle=True)` gives back an `ndarray` of
/// dtype `object` and shape `(len(items),)` holding `ndarray`s with the items' dtypes, shapes
/// and values.
///
/// Fails when an item's shape does not fit its data, when an item holds 4 GiB or more (the
/// pickle's 32-bit byte count) or has an axis of 2³¹ or more, or when `items` is empty.
pub fn object_array_npy(items: &[&NpyArray]) -> Result<Vec<u8>, IoError> {
    if items.is_empty() {
        return Err(IoError::InvalidInput(
            "an object array needs at least one item".into(),
        ));
    }
    let mut out = npy_header_for("|O", &[items.len()]);
    out.extend_from_slice(&[op::PROTO, PROTOCOL]);
    global(&mut out, "numpy", "empty");
    int(&mut out, items.len())?;
    out.push(op::TUPLE1);
    unicode(&mut out, "O");
    out.extend_from_slice(&[op::TUPLE2, op::REDUCE, op::MARK]);
    for (i, item) in items.iter().enumerate() {
        int(&mut out, i)?;
        array(&mut out, item)?;
    }
    out.extend_from_slice(&[op::SETITEMS, op::STOP]);
    Ok(out)
}

/// `numpy.reshape(numpy.frombuffer(bytearray(data), descr), shape)`.
fn array(out: &mut Vec<u8>, item: &NpyArray) -> Result<(), IoError> {
    item.validate()?;
    let bytes = item.data.len() as u64 * item.data.item_size() as u64;
    let len = u32::try_from(bytes).map_err(|_| {
        IoError::InvalidInput(format!(
            "an item of {bytes} bytes is too large for an object array (at most 4 GiB)"
        ))
    })?;
    global(out, "numpy", "reshape");
    global(out, "numpy", "frombuffer");
    global(out, "builtins", "bytearray");
    out.push(op::BINBYTES);
    out.extend_from_slice(&len.to_le_bytes());
    item.data.for_each_le_chunk(|chunk| {
        out.extend_from_slice(chunk);
        Ok::<(), IoError>(())
    })?;
    out.extend_from_slice(&[op::TUPLE1, op::REDUCE]);
    unicode(out, item.data.descr());
    out.extend_from_slice(&[op::TUPLE2, op::REDUCE, op::MARK]);
    for &d in &item.shape {
        int(out, d)?;
    }
    out.extend_from_slice(&[op::TUPLE, op::TUPLE2, op::REDUCE]);
    Ok(())
}

fn global(out: &mut Vec<u8>, module: &str, name: &str) {
    out.push(op::GLOBAL);
    for part in [module, name] {
        out.extend_from_slice(part.as_bytes());
        out.push(b'\n');
    }
}

fn int(out: &mut Vec<u8>, v: usize) -> Result<(), IoError> {
    let v = i32::try_from(v).map_err(|_| {
        IoError::InvalidInput(format!(
            "{v} is too large for an object array's index or axis"
        ))
    })?;
    out.push(op::BININT);
    out.extend_from_slice(&v.to_le_bytes());
    Ok(())
}

fn unicode(out: &mut Vec<u8>, s: &str) {
    out.push(op::BINUNICODE);
    out.extend_from_slice(&(s.len() as u32).to_le_bytes());
    out.extend_from_slice(s.as_bytes());
}

#[cfg(test)]
mod tests {
    //! The pickle is read back by a small interpreter of the opcodes above, which evaluates it
    //! into a tree of calls; the tree must be the one the module documents.

    use super::*;
    use crate::npy::ArrayData;

    #[derive(Debug, Clone, PartialEq)]
    enum Value {
        Global(String),
        Int(i64),
        Str(String),
        Bytes(Vec<u8>),
        Tuple(Vec<Value>),
        Call(Box<Value>, Vec<Value>),
        /// An object that received `obj[key] = value` for each pair, in order.
        Filled(Box<Value>, Vec<(Value, Value)>),
    }

    fn unpickle(bytes: &[u8]) -> Value {
        let mut stack: Vec<Option<Value>> = Vec::new(); // None marks a MARK
        let mut i = 0;
        let take = |i: &mut usize, n: usize| {
            let s = &bytes[*i..*i + n];
            *i += n;
            s
        };
        let u32_at = |s: &[u8]| u32::from_le_bytes(s.try_into().unwrap()) as usize;
        loop {
            let code = bytes[i];
            i += 1;
            match code {
                op::PROTO => assert_eq!(take(&mut i, 1), [PROTOCOL]),
                op::GLOBAL => {
                    let rest = &bytes[i..];
                    let a = rest.iter().position(|&b| b == b'\n').unwrap();
                    let b = rest[a + 1..].iter().position(|&b| b == b'\n').unwrap();
                    let module = std::str::from_utf8(&rest[..a]).unwrap();
                    let name = std::str::from_utf8(&rest[a + 1..a + 1 + b]).unwrap();
                    stack.push(Some(Value::Global(format!("{module}.{name}"))));
                    i += a + b + 2;
                }
                op::BININT => {
                    let v = i32::from_le_bytes(take(&mut i, 4).try_into().unwrap());
                    stack.push(Some(Value::Int(v.into())));
                }
                op::BINUNICODE => {
                    let n = u32_at(take(&mut i, 4));
                    let s = String::from_utf8(take(&mut i, n).to_vec()).unwrap();
                    stack.push(Some(Value::Str(s)));
                }
                op::BINBYTES => {
                    let n = u32_at(take(&mut i, 4));
                    stack.push(Some(Value::Bytes(take(&mut i, n).to_vec())));
                }
                op::MARK => stack.push(None),
                op::TUPLE | op::SETITEMS => {
                    let mark = stack.iter().rposition(Option::is_none).unwrap();
                    let items: Vec<Value> =
                        stack.drain(mark..).skip(1).map(Option::unwrap).collect();
                    if code == op::TUPLE {
                        stack.push(Some(Value::Tuple(items)));
                    } else {
                        let target = stack.pop().unwrap().unwrap();
                        let pairs = items
                            .chunks(2)
                            .map(|p| (p[0].clone(), p[1].clone()))
                            .collect();
                        stack.push(Some(Value::Filled(Box::new(target), pairs)));
                    }
                }
                op::TUPLE1 | op::TUPLE2 => {
                    let n = if code == op::TUPLE1 { 1 } else { 2 };
                    let at = stack.len() - n;
                    let items = stack.drain(at..).map(Option::unwrap).collect();
                    stack.push(Some(Value::Tuple(items)));
                }
                op::REDUCE => {
                    let Some(Value::Tuple(args)) = stack.pop().unwrap() else {
                        panic!("REDUCE without an argument tuple")
                    };
                    let f = stack.pop().unwrap().unwrap();
                    stack.push(Some(Value::Call(Box::new(f), args)));
                }
                op::STOP => {
                    assert_eq!(i, bytes.len(), "bytes after STOP");
                    assert_eq!(stack.len(), 1);
                    return stack.pop().unwrap().unwrap();
                }
                other => panic!("unexpected opcode {other:#04x}"),
            }
        }
    }

    fn call(f: &str, args: Vec<Value>) -> Value {
        Value::Call(Box::new(Value::Global(f.into())), args)
    }

    fn expected_array(a: &NpyArray, bytes: Vec<u8>) -> Value {
        let buffer = call("builtins.bytearray", vec![Value::Bytes(bytes)]);
        let flat = call(
            "numpy.frombuffer",
            vec![buffer, Value::Str(a.data.descr().into())],
        );
        let shape = a.shape.iter().map(|&d| Value::Int(d as i64)).collect();
        call("numpy.reshape", vec![flat, Value::Tuple(shape)])
    }

    #[test]
    fn an_object_array_of_two_arrays_unpickles_to_the_documented_calls() {
        let position = NpyArray::new(vec![2, 1, 2], vec![0.5f32, -1.0, 0.25, 3.0]).unwrap();
        let types = NpyArray::from_vec(vec![3i64]);
        let npy = object_array_npy(&[&position, &types]).unwrap();

        // The header: dtype object, one axis of two items, data aligned to 64 bytes.
        let header = crate::npy::npy_header_for("|O", &[2]);
        assert_eq!(&npy[..header.len()], header.as_slice());
        assert_eq!(header.len() % 64, 0);
        let text = std::str::from_utf8(&header[10..]).unwrap();
        assert!(text.starts_with("{'descr': '|O', 'fortran_order': False, 'shape': (2,), }"));

        let pos_bytes: Vec<u8> = [0.5f32, -1.0, 0.25, 3.0]
            .iter()
            .flat_map(|x| x.to_le_bytes())
            .collect();
        let empty = call(
            "numpy.empty",
            vec![Value::Tuple(vec![Value::Int(2)]), Value::Str("O".into())],
        );
        let want = Value::Filled(
            Box::new(empty),
            vec![
                (Value::Int(0), expected_array(&position, pos_bytes)),
                (
                    Value::Int(1),
                    expected_array(&types, 3i64.to_le_bytes().to_vec()),
                ),
            ],
        );
        assert_eq!(unpickle(&npy[header.len()..]), want);
    }

    #[test]
    fn bad_items_are_refused() {
        assert!(matches!(
            object_array_npy(&[]),
            Err(IoError::InvalidInput(_))
        ));
        let bad = NpyArray {
            shape: vec![3],
            data: ArrayData::F32(vec![1.0]),
        };
        assert!(matches!(
            object_array_npy(&[&bad]),
            Err(IoError::ShapeMismatch { .. })
        ));
    }
}
