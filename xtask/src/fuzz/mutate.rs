//! A case's input: random bytes, random text from the formats' alphabet, or a mutation of a
//! seed, from the seed, the target and the case number alone.

use synthetic::Rng;

use super::Target;

// ---------------------------------------------------------------------------------------
// inputs

pub(super) const INTERESTING_BYTES: [u8; 14] = [
    0, 0xFF, 0x7F, 0x80, b'0', b'9', b'-', b'.', b'\n', b'\r', b' ', b',', b'e', b'#',
];

pub(super) const INTERESTING_U32: [u32; 9] = [
    0,
    1,
    0x7F,
    0xFF,
    0xFFFF,
    0x7FFF_FFFF,
    0x8000_0000,
    0xFFFF_FFFF,
    0x0001_0000,
];

pub(super) const INTERESTING_NUMBERS: [&str; 22] = [
    "0",
    "-0",
    "1",
    "-1",
    "0.5",
    "1e308",
    "-1e308",
    "1e-320",
    "nan",
    "NaN",
    "inf",
    "-inf",
    "65535",
    "65536",
    "4294967296",
    "18446744073709551616",
    "1e9",
    "999999999999999999999",
    "0x10",
    "1,5",
    "",
    "2e9",
];

pub(super) const ALPHABET: &[u8] = b"0123456789.-+eE naNIif#,\n\n\r\t:xX/%";

pub(super) fn is_number_byte(c: u8) -> bool {
    c.is_ascii_digit() || matches!(c, b'.' | b'-' | b'+' | b'e' | b'E')
}

/// Replaces one number token with an interesting number.
pub(super) fn replace_number(rng: &mut Rng, b: &mut Vec<u8>) {
    let starts: Vec<usize> = (0..b.len())
        .filter(|&i| is_number_byte(b[i]) && (i == 0 || !is_number_byte(b[i - 1])))
        .collect();
    if starts.is_empty() {
        return;
    }
    let s = starts[rng.below(starts.len())];
    let mut e = s;
    while e < b.len() && is_number_byte(b[e]) {
        e += 1;
    }
    let n = INTERESTING_NUMBERS[rng.below(INTERESTING_NUMBERS.len())];
    b.splice(s..e, n.bytes());
}

pub(super) fn line_ranges(b: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut s = 0;
    for (i, &c) in b.iter().enumerate() {
        if c == b'\n' {
            out.push((s, i + 1));
            s = i + 1;
        }
    }
    if s < b.len() {
        out.push((s, b.len()));
    }
    out
}

/// Deletes, duplicates or swaps whole lines.
pub(super) fn mutate_lines(rng: &mut Rng, b: &mut Vec<u8>) {
    let lines = line_ranges(b);
    if lines.is_empty() {
        return;
    }
    let (s, e) = lines[rng.below(lines.len())];
    match rng.below(3) {
        0 => {
            b.drain(s..e);
        }
        1 => {
            let l = b[s..e].to_vec();
            b.splice(e..e, l);
        }
        _ => {
            let (s2, e2) = lines[rng.below(lines.len())];
            if (s2, e2) != (s, e) {
                let (a, c) = if s < s2 {
                    ((s, e), (s2, e2))
                } else {
                    ((s2, e2), (s, e))
                };
                let first = b[a.0..a.1].to_vec();
                let second = b[c.0..c.1].to_vec();
                b.splice(c.0..c.1, first);
                b.splice(a.0..a.1, second);
            }
        }
    }
}

/// Makes the CRC of every complete PNG chunk valid again, so that mutations reach the
/// decoder past the checksum.
pub(super) fn fix_png_crcs(b: &mut [u8]) {
    if !b.starts_with(b"\x89PNG\r\n\x1a\n") {
        return;
    }
    let mut at = 8;
    while at + 12 <= b.len() {
        let len = u32::from_be_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]]) as usize;
        let Some(end) = (at + 8).checked_add(len) else {
            return;
        };
        if end + 4 > b.len() {
            return;
        }
        let crc = crc32fast::hash(&b[at + 4..end]);
        b[end..end + 4].copy_from_slice(&crc.to_be_bytes());
        at = end + 4;
    }
}

pub(super) fn mutate(rng: &mut Rng, seeds: &[Vec<u8>], text: bool, mut b: Vec<u8>) -> Vec<u8> {
    // mostly one or two mutations, so that many inputs still parse and reach what follows
    let rounds = [1, 1, 1, 2, 2, 3, 4, 8][rng.below(8)];
    for _ in 0..rounds {
        let len = b.len();
        // text: a third of the mutations replace a number, which keeps the format
        let op = if text && rng.below(3) == 0 {
            10
        } else {
            rng.below(if text { 12 } else { 10 })
        };
        match op {
            0 if len > 0 => {
                let i = rng.below(len);
                b[i] ^= 1 << rng.below(8);
            }
            1 if len > 0 => {
                let i = rng.below(len);
                b[i] = INTERESTING_BYTES[rng.below(INTERESTING_BYTES.len())];
            }
            2 => {
                let i = rng.below(len + 1);
                let n = 1 + rng.below(8);
                let ins: Vec<u8> = (0..n).map(|_| rng.next_u64() as u8).collect();
                b.splice(i..i, ins);
            }
            3 if len > 0 => {
                let i = rng.below(len);
                let n = (1 + rng.below(16)).min(len - i);
                b.drain(i..i + n);
            }
            4 if len > 0 => {
                let i = rng.below(len);
                let n = (1 + rng.below(64)).min(len - i);
                let chunk = b[i..i + n].to_vec();
                let j = rng.below(b.len() + 1);
                b.splice(j..j, chunk);
            }
            5 if len > 0 => b.truncate(rng.below(len)),
            6 if len >= 4 => {
                let i = rng.below(len - 3);
                let v = INTERESTING_U32[rng.below(INTERESTING_U32.len())];
                let bytes = if rng.below(2) == 0 {
                    v.to_le_bytes()
                } else {
                    v.to_be_bytes()
                };
                b[i..i + 4].copy_from_slice(&bytes);
            }
            7 if !seeds.is_empty() => {
                let other = &seeds[rng.below(seeds.len())];
                let cut = rng.below(b.len() + 1);
                let from = rng.below(other.len() + 1);
                b.truncate(cut);
                b.extend_from_slice(&other[from..]);
            }
            8 if len > 0 => {
                // a large range deleted or overwritten with one byte
                let i = rng.below(len);
                let n = rng.below(len - i + 1);
                if rng.below(2) == 0 {
                    b.drain(i..i + n);
                } else {
                    let v = INTERESTING_BYTES[rng.below(INTERESTING_BYTES.len())];
                    b[i..i + n].fill(v);
                }
            }
            9 => fix_png_crcs(&mut b),
            10 => replace_number(rng, &mut b),
            11 => mutate_lines(rng, &mut b),
            _ => {}
        }
    }
    if !text && rng.below(2) == 0 {
        fix_png_crcs(&mut b);
    }
    b
}

/// The input of case `case` of the target whose name hashes to `key`.
pub(super) fn input(seed: u64, key: u64, case: u64, t: &Target) -> Vec<u8> {
    let mut rng = Rng::derive(seed ^ key, case);
    let kind = rng.below(20);
    if kind == 0 || t.seeds.is_empty() {
        let n = rng.below(512);
        return (0..n).map(|_| rng.next_u64() as u8).collect();
    }
    if kind == 1 && t.text {
        let n = rng.below(512);
        return (0..n)
            .map(|_| ALPHABET[rng.below(ALPHABET.len())])
            .collect();
    }
    let base = t.seeds[rng.below(t.seeds.len())].clone();
    mutate(&mut rng, &t.seeds, t.text, base)
}
