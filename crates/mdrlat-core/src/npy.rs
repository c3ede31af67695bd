//! Writing NumPy `.npy` files (format version 1.0), so Python users load sensor frames with
//! `numpy.load` directly.

use std::io::{self, Write};

/// Writes a little-endian `f32` array of the given shape in `.npy` format.
///
/// # Errors
/// Any I/O error of `w`; an `InvalidInput` error if `shape` does not match `data.len()`.
pub fn write_f32(mut w: impl Write, shape: &[usize], data: &[f32]) -> io::Result<()> {
    let count: usize = shape.iter().product();
    if count != data.len() {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("npy: shape {shape:?} holds {count} values, data has {}", data.len()),
        ));
    }
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let shape_txt =
        if shape.len() == 1 { format!("({},)", dims[0]) } else { format!("({})", dims.join(", ")) };
    let mut header = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {shape_txt}, }}");
    // Magic (6) + version (2) + header length (2) + header + '\n' is a multiple of 64.
    let unpadded = 10 + header.len() + 1;
    header.push_str(&" ".repeat((64 - unpadded % 64) % 64));
    header.push('\n');
    w.write_all(b"\x93NUMPY\x01\x00")?;
    w.write_all(&(header.len() as u16).to_le_bytes())?;
    w.write_all(header.as_bytes())?;
    let mut bytes = Vec::with_capacity(data.len() * 4);
    for x in data {
        bytes.extend_from_slice(&x.to_le_bytes());
    }
    w.write_all(&bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_is_aligned_and_data_follows() {
        let mut buf = Vec::new();
        write_f32(&mut buf, &[2, 3], &[0.0, 1.0, 2.0, 3.0, 4.0, 5.0]).expect("write");
        assert_eq!(&buf[..8], b"\x93NUMPY\x01\x00");
        let hlen = u16::from_le_bytes([buf[8], buf[9]]) as usize;
        assert_eq!((10 + hlen) % 64, 0);
        let header = std::str::from_utf8(&buf[10..10 + hlen]).expect("utf8");
        assert!(header.contains("'shape': (2, 3)"));
        assert_eq!(buf.len(), 10 + hlen + 24);
        assert_eq!(&buf[10 + hlen + 4..10 + hlen + 8], &1.0f32.to_le_bytes());
        assert!(write_f32(&mut Vec::new(), &[4], &[1.0]).is_err());
    }
}
