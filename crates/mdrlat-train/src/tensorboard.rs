//! TensorBoard event files (`events.out.tfevents.*`), written without TensorFlow.
//!
//! The format is TFRecord framing (length, masked CRC-32C of the length, payload, masked
//! CRC-32C of the payload) around `tensorflow.Event` protocol buffers holding scalar
//! summaries; the few protobuf fields needed are encoded by hand. Metric names follow
//! CleanRL's groups: `losses/…`, `charts/…`, `eval/…`.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

/// CRC-32C (Castagnoli), as TFRecord uses.
pub fn crc32c(data: &[u8]) -> u32 {
    const fn table() -> [u32; 256] {
        let mut t = [0u32; 256];
        let mut i = 0;
        while i < 256 {
            let mut c = i as u32;
            let mut k = 0;
            while k < 8 {
                c = if c & 1 != 0 { 0x82F6_3B78 ^ (c >> 1) } else { c >> 1 };
                k += 1;
            }
            t[i] = c;
            i += 1;
        }
        t
    }
    const TABLE: [u32; 256] = table();
    !data.iter().fold(!0u32, |c, &b| TABLE[((c ^ u32::from(b)) & 0xff) as usize] ^ (c >> 8))
}

fn masked(crc: u32) -> u32 {
    crc.rotate_right(15).wrapping_add(0xa282_ead8)
}

fn varint(mut v: u64, out: &mut Vec<u8>) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

fn len_field(tag: u8, bytes: &[u8], out: &mut Vec<u8>) {
    out.push(tag);
    varint(bytes.len() as u64, out);
    out.extend_from_slice(bytes);
}

fn wall_time() -> f64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0.0, |d| d.as_secs_f64())
}

/// An open event file.
pub struct EventWriter {
    path: PathBuf,
    out: BufWriter<File>,
}

impl std::fmt::Debug for EventWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EventWriter").field("path", &self.path).finish()
    }
}

impl EventWriter {
    /// Creates a new event file in `dir` (TensorBoard reads every `*tfevents*` file of a run).
    ///
    /// # Errors
    /// The file cannot be created.
    pub fn create(dir: &Path) -> std::io::Result<Self> {
        let secs = SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs());
        let path = dir.join(format!("events.out.tfevents.{secs}.mdrlat.{}", std::process::id()));
        let mut w = EventWriter { out: BufWriter::new(File::create(&path)?), path };
        // Event { wall_time = 1, file_version = 3 }
        let mut ev = Vec::new();
        ev.push(0x09);
        ev.extend_from_slice(&wall_time().to_le_bytes());
        len_field(0x1a, b"brain.Event:2", &mut ev);
        w.record(&ev)?;
        Ok(w)
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn record(&mut self, data: &[u8]) -> std::io::Result<()> {
        let len = (data.len() as u64).to_le_bytes();
        self.out.write_all(&len)?;
        self.out.write_all(&masked(crc32c(&len)).to_le_bytes())?;
        self.out.write_all(data)?;
        self.out.write_all(&masked(crc32c(data)).to_le_bytes())
    }

    /// Writes scalars `(tag, value)` at `step`; non-finite values are skipped.
    ///
    /// # Errors
    /// A write error.
    pub fn scalars(&mut self, step: u64, values: &[(&str, f32)]) -> std::io::Result<()> {
        let mut summary = Vec::new();
        for (tag, v) in values.iter().filter(|(_, v)| v.is_finite()) {
            // Summary.Value { tag = 1, simple_value = 2 }
            let mut value = Vec::new();
            len_field(0x0a, tag.as_bytes(), &mut value);
            value.push(0x15);
            value.extend_from_slice(&v.to_le_bytes());
            len_field(0x0a, &value, &mut summary);
        }
        if summary.is_empty() {
            return Ok(());
        }
        // Event { wall_time = 1, step = 2, summary = 5 }
        let mut ev = Vec::new();
        ev.push(0x09);
        ev.extend_from_slice(&wall_time().to_le_bytes());
        ev.push(0x10);
        varint(step, &mut ev);
        len_field(0x2a, &summary, &mut ev);
        self.record(&ev)
    }

    /// Marks a restart at `step` (`SessionLog { status: START }`): TensorBoard then drops
    /// the points after `step` that an interrupted run had written.
    ///
    /// # Errors
    /// A write error.
    pub fn session_start(&mut self, step: u64) -> std::io::Result<()> {
        // Event { wall_time = 1, step = 2, session_log = 6 { status = 1: START } }
        let mut ev = Vec::new();
        ev.push(0x09);
        ev.extend_from_slice(&wall_time().to_le_bytes());
        ev.push(0x10);
        varint(step, &mut ev);
        len_field(0x32, &[0x08, 0x01], &mut ev);
        self.record(&ev)
    }

    /// Flushes buffered events to the file.
    ///
    /// # Errors
    /// A write error.
    pub fn flush(&mut self) -> std::io::Result<()> {
        self.out.flush()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32c_test_vector() {
        assert_eq!(crc32c(b"123456789"), 0xE306_9283);
    }

    /// Reads the records back, checking both CRCs, and finds the tags and values.
    #[test]
    fn records_frame_and_checksum_correctly() {
        let dir = std::env::temp_dir().join(format!("mdrlat-tb-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let mut w = EventWriter::create(&dir).expect("create");
        w.scalars(
            300,
            &[("losses/td", 0.25), ("charts/epsilon", f32::NAN), ("eval/reward_mean", -1.5)],
        )
        .expect("write");
        w.flush().expect("flush");
        let bytes = std::fs::read(w.path()).expect("read");
        let mut pos = 0;
        let mut records = Vec::new();
        while pos < bytes.len() {
            let len_bytes: [u8; 8] = bytes[pos..pos + 8].try_into().expect("len");
            let crc = u32::from_le_bytes(bytes[pos + 8..pos + 12].try_into().expect("crc"));
            assert_eq!(crc, masked(crc32c(&len_bytes)));
            let n = u64::from_le_bytes(len_bytes) as usize;
            let data = &bytes[pos + 12..pos + 12 + n];
            let dcrc =
                u32::from_le_bytes(bytes[pos + 12 + n..pos + 16 + n].try_into().expect("crc"));
            assert_eq!(dcrc, masked(crc32c(data)));
            records.push(data.to_vec());
            pos += 16 + n;
        }
        assert_eq!(records.len(), 2);
        assert!(records[0].windows(13).any(|w| w == b"brain.Event:2"));
        let ev = &records[1];
        assert!(ev.windows(9).any(|w| w == b"losses/td"));
        assert!(!ev.windows(14).any(|w| w == b"charts/epsilon"), "NaN skipped");
        assert!(ev.windows(5).any(|w| w == [0x15, 0, 0, 0x80, 0x3e]), "simple_value 0.25");
        assert_eq!(&ev[9..12], &[0x10, 0xac, 0x02], "step 300 as a varint");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
