//! FASTRAK bytes to records: a pure parser, fixed-size and allocation-free, testable without a
//! tty; and its inverse, [`encode_record`], for the emulator and the tests.
//!
//! Resynchronisation: a candidate record is accepted only if it is complete, every value is a
//! finite number in the device's range, the quaternion has unit length and the record ends in
//! CR LF; otherwise the parser drops one byte and looks for the next `0<station>` header. ASCII
//! fields are read as signed numbers between blanks or signs rather than by column, so both
//! the FASTRAK's fixed columns and a tolerant writer parse.

use super::frame::TrackerRecord;
use super::Format;
use crate::devices::link_loop::{RecordBuffer, RecordBytes};
use crate::devices::serial::LinkStats;

/// Output-list item numbers.
pub mod item {
    pub const SPACE: u8 = 0;
    pub const CRLF: u8 = 1;
    pub const POSITION: u8 = 2;
    pub const EULER: u8 = 4;
    pub const QUATERNION: u8 = 11;
}

const MAX_ITEMS: usize = 8;
const MAX_ASCII_RECORD: usize = 160;

/// Bytes in, FASTRAK records out; pure, fixed-size, no allocation.
#[derive(Debug, Clone)]
pub struct FastrakParser {
    format: Format,
    items: [u8; MAX_ITEMS],
    item_count: usize,
    bytes: RecordBytes,
    pub stats: LinkStats,
}

fn binary_item_len(item: u8) -> Option<usize> {
    match item {
        item::SPACE => Some(1),
        item::CRLF => Some(2),
        item::POSITION | item::EULER => Some(12),
        item::QUATERNION => Some(16),
        _ => None,
    }
}

fn value_count(item: u8) -> usize {
    match item {
        item::POSITION | item::EULER => 3,
        item::QUATERNION => 4,
        _ => 0,
    }
}

impl FastrakParser {
    /// A parser for records of `items` (supported: 0, 1, 2, 4, 11; ASCII lists must end in 1).
    pub fn new(format: Format, items: &[u8]) -> Result<FastrakParser, String> {
        if items.is_empty() || items.len() > MAX_ITEMS {
            return Err(format!("an output list has 1 to {MAX_ITEMS} items"));
        }
        if let Some(bad) = items.iter().find(|i| binary_item_len(**i).is_none()) {
            return Err(format!(
                "output item {bad} is not supported (use 0, 1, 2, 4, 11)"
            ));
        }
        if format == Format::Ascii && items.last() != Some(&item::CRLF) {
            return Err("an ASCII output list must end with item 1 (CR LF)".into());
        }
        let mut p = FastrakParser {
            format,
            items: [0; MAX_ITEMS],
            item_count: items.len(),
            bytes: RecordBytes::new(1024),
            stats: LinkStats::default(),
        };
        p.items[..items.len()].copy_from_slice(items);
        Ok(p)
    }

    fn items(&self) -> &[u8] {
        &self.items[..self.item_count]
    }

    fn binary_len(&self) -> usize {
        3 + self
            .items()
            .iter()
            .map(|i| binary_item_len(*i).unwrap_or(0))
            .sum::<usize>()
    }

    /// Appends bytes (for tests); returns how many fit.
    pub fn push(&mut self, bytes: &[u8]) -> usize {
        self.bytes.push(bytes, &mut self.stats.garbage_bytes)
    }

    /// The next valid record (any station), or None until more bytes arrive.
    pub fn next(&mut self, out: &mut TrackerRecord) -> bool {
        let mut p = 0;
        let found = loop {
            let filled = self.bytes.filled();
            while p < filled.len() && filled[p] != b'0' {
                p += 1;
            }
            if p >= filled.len() {
                break None;
            }
            let avail = &filled[p..];
            if avail.len() < 3 {
                // Reject early when what is there already cannot be a header.
                if avail.len() >= 2 && !(b'1'..=b'4').contains(&avail[1]) {
                    p += 1;
                    continue;
                }
                break None;
            }
            if !(b'1'..=b'4').contains(&avail[1]) || !(0x20..0x7f).contains(&avail[2]) {
                p += 1;
                continue;
            }
            let verdict = match self.format {
                Format::Binary => self.try_binary(p, out),
                Format::Ascii => self.try_ascii(p, out),
            };
            match verdict {
                Verdict::Record(len) => break Some(len),
                Verdict::Incomplete => break None,
                Verdict::Bad => {
                    self.stats.rejected_records += 1;
                    p += 1;
                }
            }
        };
        self.stats.garbage_bytes += p as u64;
        match found {
            Some(len) => {
                self.bytes.consume(p + len);
                true
            }
            None => {
                self.bytes.consume(p);
                false
            }
        }
    }

    fn try_binary(&self, p: usize, out: &mut TrackerRecord) -> Verdict {
        let need = self.binary_len();
        let avail = &self.bytes.filled()[p..];
        if avail.len() < need {
            return Verdict::Incomplete;
        }
        let mut rec = header(avail);
        let mut at = 3;
        for &it in self.items() {
            let len = binary_item_len(it).unwrap_or(0);
            let bytes = &avail[at..at + len];
            let ok = match it {
                item::SPACE => bytes[0] == b' ',
                item::CRLF => bytes == b"\r\n",
                _ => {
                    let mut v = [0.0f64; 4];
                    for (k, chunk) in bytes.chunks_exact(4).enumerate() {
                        v[k] =
                            f64::from(f32::from_le_bytes([chunk[0], chunk[1], chunk[2], chunk[3]]));
                    }
                    rec.set(it, &v)
                }
            };
            if !ok {
                return Verdict::Bad;
            }
            at += len;
        }
        if !rec.plausible() {
            return Verdict::Bad;
        }
        *out = rec;
        Verdict::Record(need)
    }

    fn try_ascii(&self, p: usize, out: &mut TrackerRecord) -> Verdict {
        let avail = &self.bytes.filled()[p..];
        let window = &avail[..avail.len().min(MAX_ASCII_RECORD)];
        let Some(end) = window.windows(2).position(|w| w == b"\r\n") else {
            if avail.len() >= MAX_ASCII_RECORD {
                return Verdict::Bad;
            }
            return Verdict::Incomplete;
        };
        let mut rec = header(avail);
        let mut values = [0.0f64; 4 * MAX_ITEMS];
        let Some(count) = parse_numbers(&avail[3..end], &mut values) else {
            return Verdict::Bad;
        };
        let mut at = 0;
        for &it in self.items() {
            let n = value_count(it);
            if n == 0 {
                continue;
            }
            if at + n > count || !rec.set(it, &values[at..at + n]) {
                return Verdict::Bad;
            }
            at += n;
        }
        if at != count || !rec.plausible() {
            return Verdict::Bad;
        }
        *out = rec;
        Verdict::Record(end + 2)
    }
}

enum Verdict {
    Record(usize),
    Incomplete,
    Bad,
}

fn header(avail: &[u8]) -> TrackerRecord {
    TrackerRecord {
        station: avail[1] - b'0',
        error: avail[2],
        ..TrackerRecord::default()
    }
}

impl TrackerRecord {
    fn set(&mut self, it: u8, v: &[f64]) -> bool {
        if v.iter().any(|x| !x.is_finite()) {
            return false;
        }
        match it {
            item::POSITION => {
                self.position.copy_from_slice(&v[..3]);
                self.has_position = true;
            }
            item::EULER => {
                self.euler.copy_from_slice(&v[..3]);
                self.has_euler = true;
            }
            item::QUATERNION => {
                self.quaternion.copy_from_slice(&v[..4]);
                self.has_quaternion = true;
            }
            _ => {}
        }
        true
    }

    /// Values a working FASTRAK can report (positions within 10 m in either unit, angles in
    /// their ranges, unit quaternions): anything else is a damaged record.
    fn plausible(&self) -> bool {
        if self.position.iter().any(|v| v.abs() > 1000.0) {
            return false;
        }
        if self.has_euler {
            let [az, el, roll] = self.euler;
            if az.abs() > 180.01 || el.abs() > 90.01 || roll.abs() > 180.01 {
                return false;
            }
        }
        if self.has_quaternion {
            let n2: f64 = self.quaternion.iter().map(|q| q * q).sum();
            if !(0.96..=1.04).contains(&n2) {
                return false;
            }
        }
        self.has_quaternion || self.has_euler || self.has_position
    }
}

impl RecordBuffer for FastrakParser {
    fn window(&mut self) -> (&mut RecordBytes, &mut LinkStats) {
        (&mut self.bytes, &mut self.stats)
    }

    fn stats(&self) -> &LinkStats {
        &self.stats
    }
}

/// Reads signed decimal numbers separated by blanks (or by the next number's sign) into `out`;
/// None if anything else is there or there are too many.
fn parse_numbers(body: &[u8], out: &mut [f64]) -> Option<usize> {
    let mut count = 0;
    let mut i = 0;
    while i < body.len() {
        let c = body[i];
        if c == b' ' || c == b'\t' {
            i += 1;
            continue;
        }
        if !(c == b'+' || c == b'-' || c == b'.' || c.is_ascii_digit()) {
            return None;
        }
        let start = i;
        i += 1;
        while i < body.len() {
            let c = body[i];
            let exp_sign = (c == b'+' || c == b'-') && matches!(body[i - 1], b'e' | b'E');
            if c.is_ascii_digit() || c == b'.' || c == b'e' || c == b'E' || exp_sign {
                i += 1;
            } else {
                break;
            }
        }
        let text = std::str::from_utf8(&body[start..i]).ok()?;
        let v: f64 = text.parse().ok()?;
        if count >= out.len() {
            return None;
        }
        out[count] = v;
        count += 1;
    }
    Some(count)
}

/// Encodes one record as a FASTRAK would (used by the emulator and the tests): `values` in
/// device units, the quaternion as w, x, y, z.
pub fn encode_record(
    format: Format,
    items: &[u8],
    station: u8,
    position: [f64; 3],
    euler: [f64; 3],
    quaternion: [f64; 4],
    out: &mut Vec<u8>,
) {
    use std::io::Write;
    out.push(b'0');
    out.push(b'0' + station);
    out.push(b' ');
    for &it in items {
        let vals: &[f64] = match it {
            item::POSITION => &position,
            item::EULER => &euler,
            item::QUATERNION => &quaternion,
            item::SPACE => {
                out.push(b' ');
                continue;
            }
            item::CRLF => {
                out.extend_from_slice(b"\r\n");
                continue;
            }
            _ => continue,
        };
        for v in vals {
            match format {
                Format::Binary => out.extend_from_slice(&(*v as f32).to_le_bytes()),
                Format::Ascii => {
                    let _ = if it == item::QUATERNION {
                        write!(out, "{v:7.4}")
                    } else {
                        write!(out, "{v:7.2}")
                    };
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::*;

    const LIST_Q: [u8; 3] = [item::POSITION, item::QUATERNION, item::CRLF];
    const LIST_E: [u8; 3] = [item::POSITION, item::EULER, item::CRLF];

    fn quat(k: u32) -> [f64; 4] {
        let a = k as f64 * 0.1;
        let (s, c) = (a / 2.0).sin_cos();
        let axis = DVec3::new(1.0, 2.0, 2.0) / 3.0;
        [c, s * axis.x, s * axis.y, s * axis.z]
    }

    fn stream(format: Format, list: &[u8], ks: std::ops::Range<u32>) -> Vec<u8> {
        let mut out = Vec::new();
        for k in ks {
            encode_record(
                format,
                list,
                1 + (k % 2) as u8,
                [k as f64, -2.5 * k as f64, 100.25],
                [k as f64, -(k as f64) / 2.0, 170.0],
                quat(k),
                &mut out,
            );
        }
        out
    }

    fn drain(p: &mut FastrakParser) -> Vec<TrackerRecord> {
        let mut r = TrackerRecord::default();
        let mut v = Vec::new();
        while p.next(&mut r) {
            v.push(r);
        }
        v
    }

    #[test]
    fn clean_streams_in_both_formats() {
        for format in [Format::Ascii, Format::Binary] {
            for list in [&LIST_Q, &LIST_E] {
                let mut p = FastrakParser::new(format, list).unwrap();
                p.push(&stream(format, list, 0..10));
                let recs = drain(&mut p);
                assert_eq!(recs.len(), 10, "{format:?} {list:?}");
                for (k, r) in recs.iter().enumerate() {
                    assert_eq!(r.station, 1 + (k % 2) as u8);
                    assert!((r.position[1] + 2.5 * k as f64).abs() < 0.006);
                    if list == &LIST_Q {
                        for (a, b) in r.quaternion.iter().zip(quat(k as u32)) {
                            assert!((a - b).abs() < 1e-4);
                        }
                    } else {
                        assert!((r.euler[2] - 170.0).abs() < 1e-4);
                    }
                }
                assert_eq!(p.stats.garbage_bytes, 0);
            }
        }
    }

    #[test]
    fn noise_and_cut_records_resynchronise() {
        for format in [Format::Ascii, Format::Binary] {
            let mut bytes = b"\x00\xff01 junk\r\n0".to_vec();
            bytes.extend(stream(format, &LIST_Q, 0..2));
            let cut = stream(format, &LIST_Q, 2..3);
            bytes.extend(&cut[..cut.len() / 2]);
            bytes.extend(stream(format, &LIST_Q, 3..5));
            bytes.extend(b"01 "); // a lone header
            bytes.extend(stream(format, &LIST_Q, 5..6));
            let mut p = FastrakParser::new(format, &LIST_Q).unwrap();
            // Feed in uneven pieces.
            let mut recs = Vec::new();
            for chunk in bytes.chunks(7) {
                p.push(chunk);
                recs.extend(drain(&mut p));
            }
            let xs: Vec<f64> = recs.iter().map(|r| r.position[0].round()).collect();
            assert_eq!(xs, vec![0.0, 1.0, 3.0, 4.0, 5.0], "{format:?}");
            assert!(p.stats.garbage_bytes > 0);
        }
    }

    #[test]
    fn non_finite_and_out_of_range_values_are_rejected() {
        let mut bytes = Vec::new();
        encode_record(
            Format::Binary,
            &LIST_Q,
            1,
            [f64::NAN, 0.0, 0.0],
            [0.0; 3],
            quat(1),
            &mut bytes,
        );
        encode_record(
            Format::Binary,
            &LIST_Q,
            1,
            [1.0, 0.0, 0.0],
            [0.0; 3],
            [2.0, 0.0, 0.0, 0.0],
            &mut bytes,
        );
        encode_record(
            Format::Binary,
            &LIST_Q,
            1,
            [f64::INFINITY, 0.0, 0.0],
            [0.0; 3],
            quat(1),
            &mut bytes,
        );
        let mut p = FastrakParser::new(Format::Binary, &LIST_Q).unwrap();
        p.push(&bytes);
        assert!(drain(&mut p).is_empty());
        let mut p = FastrakParser::new(Format::Ascii, &LIST_Q).unwrap();
        p.push(b"01    nan   0.00   0.00 1.0000 0.0000 0.0000 0.0000\r\n");
        p.push(b"01   1.00   0.00   0.00 1.0000 0.0000 0.0000\r\n"); // a value short
        assert!(drain(&mut p).is_empty());
    }

    #[test]
    fn ascii_fields_that_touch_still_parse() {
        let mut p = FastrakParser::new(Format::Ascii, &LIST_E).unwrap();
        p.push(b"02 -100.00-120.50  +3.25-179.99 -89.00 180.00\r\n");
        let r = drain(&mut p);
        assert_eq!(r.len(), 1);
        assert_eq!(r[0].station, 2);
        assert_eq!(r[0].position, [-100.0, -120.5, 3.25]);
        assert_eq!(r[0].euler, [-179.99, -89.0, 180.0]);
    }

    #[test]
    fn arbitrary_bytes_never_panic() {
        for format in [Format::Ascii, Format::Binary] {
            let mut x: u32 = 99;
            let mut p = FastrakParser::new(format, &LIST_Q).unwrap();
            let mut r = TrackerRecord::default();
            for _ in 0..3000 {
                let mut chunk = [0u8; 41];
                for b in chunk.iter_mut() {
                    x = x.wrapping_mul(1_103_515_245).wrapping_add(12345);
                    // Bias towards header and digit bytes so candidates get far.
                    *b = match (x >> 16) % 4 {
                        0 => b"01234 .-\r\n"[(x >> 20) as usize % 10],
                        _ => (x >> 16) as u8,
                    };
                }
                p.push(&chunk[..(x as usize % 41) + 1]);
                while p.next(&mut r) {
                    assert!(r.position.iter().all(|v| v.is_finite()));
                }
            }
        }
    }
}
