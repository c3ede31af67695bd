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
        // Event { wall_time = 1, step = 2, session_log = 7 { status = 1: START } }
        let mut ev = Vec::new();
        ev.push(0x09);
        ev.extend_from_slice(&wall_time().to_le_bytes());
        ev.push(0x10);
        varint(step, &mut ev);
        len_field(0x3a, &[0x08, 0x01], &mut ev);
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

/// One event's wall time (seconds since the epoch) and step (none for a file's first).
fn read_events(path: &Path) -> std::io::Result<Vec<(f64, Option<u64>)>> {
    let bytes = std::fs::read(path)?;
    let bad = |what: &str| {
        std::io::Error::new(std::io::ErrorKind::InvalidData, format!("{}: {what}", path.display()))
    };
    let mut events = Vec::new();
    let mut pos = 0;
    while pos + 12 <= bytes.len() {
        let len = u64::from_le_bytes(bytes[pos..pos + 8].try_into().map_err(|_| bad("length"))?);
        let n = usize::try_from(len).map_err(|_| bad("length"))?;
        let Some(data) = bytes.get(pos + 12..).and_then(|rest| rest.get(..n)) else {
            break; // a record cut short by a killed run: the ones before it stand
        };
        pos = pos.saturating_add(16).saturating_add(n);
        let (mut wall, mut step, mut i) = (None, None, 0);
        while i < data.len() {
            let key = data[i];
            i += 1;
            match key & 7 {
                1 => {
                    let v = data.get(i..i + 8).ok_or_else(|| bad("fixed64"))?;
                    if key >> 3 == 1 {
                        wall = Some(f64::from_le_bytes(v.try_into().map_err(|_| bad("fixed64"))?));
                    }
                    i += 8;
                }
                0 | 2 => {
                    let (mut v, mut shift) = (0u64, 0);
                    loop {
                        let b = *data.get(i).ok_or_else(|| bad("varint"))?;
                        i += 1;
                        v |= u64::from(b & 0x7f) << shift.min(63);
                        shift += 7;
                        if b < 0x80 {
                            break;
                        }
                    }
                    if key & 7 == 2 {
                        i = i.saturating_add(usize::try_from(v).map_err(|_| bad("length"))?);
                    } else if key >> 3 == 2 {
                        step = Some(v);
                    }
                }
                5 => i += 4,
                _ => return Err(bad("unknown wire type")),
            }
        }
        if let Some(w) = wall {
            events.push((w, step));
        }
    }
    Ok(events)
}

/// Seconds of training at each logged step of the run in `dir`, from its event files' wall
/// times: each session (one event file) counts from its start, and a session's time after
/// the step the next one resumed from (work redone after a restart) is left out. Steps in
/// increasing order. Wall-clock time depends on the machine and what ran beside the run: a
/// figure from it names the CPU.
///
/// # Errors
/// The folder or an event file cannot be read.
pub fn training_seconds(dir: &Path) -> std::io::Result<Vec<(u64, f64)>> {
    let mut sessions = Vec::new();
    for entry in std::fs::read_dir(dir)? {
        let path = entry?.path();
        if path.file_name().is_some_and(|n| n.to_string_lossy().contains("tfevents")) {
            let events = read_events(&path)?;
            if let Some(&(start, _)) = events.first() {
                let steps: Vec<(u64, f64)> =
                    events.iter().filter_map(|&(w, s)| s.map(|s| (s, w - start))).collect();
                sessions.push((start, steps));
            }
        }
    }
    sessions.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut out: Vec<(u64, f64)> = Vec::new();
    let mut offset = 0.0;
    for (k, (_, steps)) in sessions.iter().enumerate() {
        // The step the next session resumed from: its first event's (the restart mark).
        let resumed = sessions.get(k + 1).and_then(|(_, s)| s.first()).map(|&(s, _)| s);
        let kept: Vec<(u64, f64)> =
            steps.iter().copied().filter(|&(s, _)| resumed.is_none_or(|r| s <= r)).collect();
        out.retain(|&(s, _)| kept.first().is_none_or(|&(first, _)| s < first));
        out.extend(kept.iter().map(|&(s, t)| (s, offset + t)));
        offset += kept.last().map_or(0.0, |&(_, t)| t);
    }
    out.sort_by_key(|&(s, _)| s);
    out.dedup_by_key(|p| p.0);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An event file with chosen wall times: its start, then `(wall, step)` scalars, then
    /// (for a resumed session) the restart mark first.
    fn session(dir: &Path, name: &str, start: f64, resumed: Option<u64>, events: &[(f64, u64)]) {
        let path = dir.join(format!("events.out.tfevents.{name}"));
        let mut w = EventWriter { out: BufWriter::new(File::create(&path).expect("file")), path };
        let mut ev = vec![0x09];
        ev.extend_from_slice(&start.to_le_bytes());
        len_field(0x1a, b"brain.Event:2", &mut ev);
        w.record(&ev).expect("write");
        let mut at = |wall: f64, step: u64, payload: &[u8]| {
            let mut ev = vec![0x09];
            ev.extend_from_slice(&wall.to_le_bytes());
            ev.push(0x10);
            varint(step, &mut ev);
            ev.extend_from_slice(payload);
            w.record(&ev).expect("write");
        };
        if let Some(r) = resumed {
            at(start, r, &[0x3a, 2, 0x08, 0x01]);
        }
        for &(wall, step) in events {
            at(wall, step, &[0x2a, 0]);
        }
        w.flush().expect("flush");
    }

    #[test]
    fn training_time_counts_each_session_and_leaves_out_redone_work() {
        let dir = std::env::temp_dir().join(format!("mdrlat-tb-time-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("dir");
        // Session 1: 100 s to step 100, 200 s to 200, 300 s to 300 (killed; checkpoint at 200).
        session(&dir, "1", 1000.0, None, &[(1100.0, 100), (1200.0, 200), (1300.0, 300)]);
        // Session 2, a day later, resumes at 200: 50 s to step 300, 150 s to 400.
        session(&dir, "2", 90_000.0, Some(200), &[(90_050.0, 300), (90_150.0, 400)]);
        let t = training_seconds(&dir).expect("reads");
        assert_eq!(t, vec![(100, 100.0), (200, 200.0), (300, 250.0), (400, 350.0)]);
        // The writer's own files read back.
        let mut w = EventWriter::create(&dir.join("..").join(dir.file_name().expect("name")))
            .expect("create");
        w.scalars(500, &[("losses/td", 1.0)]).expect("write");
        w.flush().expect("flush");
        assert!(training_seconds(&dir).expect("reads").iter().any(|&(s, _)| s == 500));
        let _ = std::fs::remove_dir_all(&dir);
    }

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
