//! Packed encodings of the bulky history columns (schema version 4), and their inverses.
//!
//! Lifts keep the unit of version 1 (0.1 µm, the gauge's resolution as stored), so a packed
//! row reads back exactly the values a version-1 row gave. What changes is the layout:
//!
//! - averaged profile: second differences of the units around the revolution (a smooth
//!   profile has small ones), zigzag LEB128 varints, zstd;
//! - raw revolutions: each value minus the averaged profile's value at its angle (what is
//!   left is the gauge's noise and the part's run-out, a few µm), zigzag varints, zstd;
//! - text (table program, its learning, learning state): zstd with the parent row's text as
//!   dictionary (format 1), or what changed in its numbers against the parent's (format 2,
//!   see `pack_numbers`), whichever is smaller. Consecutive programs differ only in digits.
//!
//! Every packed blob starts with one format byte, so a later format can sit beside this one.

use super::error::StoreError;
use super::pack_numbers;
use std::cell::RefCell;
use std::io;

/// Format byte of the blobs this build writes.
const FORMAT_V1: u8 = 1;
/// zstd level: 3. Level 19 packed about 20 % smaller but took ~10 ms per table inside the
/// writer's transaction (an 8-lobe shaft at 360 points went from 13 to 79 ms p50, at 3600 points
/// to 2.5 s); the part path matters more than the last kilobyte.
const LEVEL: i32 = 3;

pub(super) fn zigzag(v: i64) -> u64 {
    ((v << 1) ^ (v >> 63)) as u64
}

pub(super) fn unzigzag(u: u64) -> i64 {
    ((u >> 1) as i64) ^ -((u & 1) as i64)
}

/// Why a varint could not be read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum VarintError {
    /// The bytes end mid-value.
    Truncated,
    /// More than 64 bits of continuation.
    TooLong,
}

/// Takes one little-endian base-128 varint off the front of `bytes`. The one reader of
/// every packed format (history rows and analysis reports).
pub(super) fn take_varint(bytes: &mut &[u8]) -> Result<u64, VarintError> {
    let mut u: u64 = 0;
    for shift in (0..64).step_by(7) {
        let (&b, rest) = bytes.split_first().ok_or(VarintError::Truncated)?;
        *bytes = rest;
        u |= u64::from(b & 0x7f) << shift;
        if b & 0x80 == 0 {
            return Ok(u);
        }
    }
    Err(VarintError::TooLong)
}

pub(super) fn put_varint(out: &mut Vec<u8>, mut u: u64) {
    while u >= 0x80 {
        out.push((u as u8) | 0x80);
        u >>= 7;
    }
    out.push(u as u8);
}

/// Reads varints from a byte slice; `None` at the end, an error on a truncated one.
pub(super) struct Varints<'a> {
    pub(super) bytes: &'a [u8],
    pub(super) field: &'static str,
}

impl Varints<'_> {
    pub(super) fn next_i64(&mut self) -> Result<i64, StoreError> {
        self.next_u64().map(unzigzag)
    }

    pub(super) fn next_u64(&mut self) -> Result<u64, StoreError> {
        take_varint(&mut self.bytes).map_err(|e| match e {
            VarintError::Truncated => {
                StoreError::invalid(self.field, "packed values end mid-value")
            }
            VarintError::TooLong => {
                StoreError::invalid(self.field, "a packed value is longer than 64 bits")
            }
        })
    }
}

thread_local! {
    /// This thread's zstd compression context, made once and reused: a new context per
    /// call allocated and cleared zstd's tables (about a megabyte at level 3) for every
    /// blob, several blobs per part, which a profile of the part path showed as most of
    /// zstd's time. Each call sets its level and dictionary before compressing.
    static COMPRESSOR: RefCell<Option<zstd::bulk::Compressor<'static>>> =
        const { RefCell::new(None) };
}

/// zstd of `plain` at `level` with `dictionary` (may be empty: none) in this thread's one
/// context. The frame is the one a fresh `Compressor::with_dictionary` makes.
pub(super) fn zstd_compress(level: i32, plain: &[u8], dictionary: &[u8]) -> io::Result<Vec<u8>> {
    COMPRESSOR.with(|slot| {
        let mut slot = slot.borrow_mut();
        let c = match slot.as_mut() {
            Some(c) => c,
            None => slot.insert(zstd::bulk::Compressor::new(level)?),
        };
        c.set_dictionary(level, dictionary)?;
        c.compress(plain)
    })
}

fn compress(field: &'static str, plain: &[u8], dictionary: &[u8]) -> Result<Vec<u8>, StoreError> {
    let mut out = vec![FORMAT_V1];
    out.extend(
        zstd_compress(LEVEL, plain, dictionary)
            .map_err(|e| StoreError::invalid(field, format!("compressing: {e}")))?,
    );
    Ok(out)
}

/// Largest plain size a pack may claim: 64 MiB, far above any real row, so a damaged length
/// cannot make a read allocate without bound.
pub(super) const MAX_PLAIN: usize = 64 << 20;

fn decompress(field: &'static str, blob: &[u8], dictionary: &[u8]) -> Result<Vec<u8>, StoreError> {
    let (&format, body) = blob
        .split_first()
        .ok_or_else(|| StoreError::invalid(field, "empty packed blob"))?;
    if format != FORMAT_V1 {
        return Err(StoreError::invalid(
            field,
            format!("unknown packed format {format}"),
        ));
    }
    let mut d = zstd::bulk::Decompressor::with_dictionary(dictionary)
        .map_err(|e| StoreError::invalid(field, format!("decompressor: {e}")))?;
    d.decompress(body, MAX_PLAIN)
        .map_err(|e| StoreError::invalid(field, format!("not a readable pack: {e}")))
}

/// Packs bytes without a dictionary.
pub(crate) fn pack_bytes(field: &'static str, plain: &[u8]) -> Result<Vec<u8>, StoreError> {
    compress(field, plain, &[])
}

/// Unpacks [`pack_bytes`].
pub(crate) fn unpack_bytes(field: &'static str, blob: &[u8]) -> Result<Vec<u8>, StoreError> {
    decompress(field, blob, &[])
}

/// Packs text (UTF-8) against `dictionary` (its parent, may be empty): as the changes in
/// its numbers ([`pack_numbers`]) or as zstd with the parent as dictionary, whichever is
/// smaller.
pub(crate) fn pack_text(
    field: &'static str,
    text: &str,
    dictionary: &str,
) -> Result<Vec<u8>, StoreError> {
    let plain = compress(field, text.as_bytes(), dictionary.as_bytes())?;
    Ok(match pack_numbers::pack(field, text, dictionary, LEVEL) {
        Some(numbers) if numbers.len() < plain.len() => numbers,
        _ => plain,
    })
}

/// Unpacks what [`pack_text`] made with the same dictionary (either format).
pub(crate) fn unpack_text(
    field: &'static str,
    blob: &[u8],
    dictionary: &str,
) -> Result<String, StoreError> {
    if blob.first() == Some(&pack_numbers::FORMAT_NUMBERS) {
        return pack_numbers::unpack(field, blob, dictionary);
    }
    String::from_utf8(decompress(field, blob, dictionary.as_bytes())?)
        .map_err(|_| StoreError::invalid(field, "packed text is not UTF-8"))
}

/// Packs one revolution of lift units (the averaged profile).
pub(crate) fn pack_profile(units: &[i32]) -> Result<Vec<u8>, StoreError> {
    let mut plain = Vec::with_capacity(units.len() * 2);
    let (mut prev, mut step) = (0_i64, 0_i64);
    for &u in units {
        let u = i64::from(u);
        let d = u - prev;
        put_varint(&mut plain, zigzag(d - step));
        step = d;
        prev = u;
    }
    compress("averaged_profile", &plain, &[])
}

/// Unpacks [`pack_profile`]: exactly `points` values.
pub(crate) fn unpack_profile(blob: &[u8], points: usize) -> Result<Vec<i32>, StoreError> {
    const FIELD: &str = "averaged_profile";
    let plain = decompress(FIELD, blob, &[])?;
    let mut values = Varints {
        bytes: &plain,
        field: FIELD,
    };
    let (mut prev, mut step) = (0_i64, 0_i64);
    let mut out = Vec::with_capacity(points);
    for _ in 0..points {
        step += values.next_i64()?;
        prev += step;
        out.push(to_i32(FIELD, prev)?);
    }
    if !values.bytes.is_empty() {
        return Err(StoreError::invalid(
            FIELD,
            format!("more than {points} packed values"),
        ));
    }
    Ok(out)
}

/// Packs raw revolutions (revolution-major, `profile.len()` values each) as differences
/// from the averaged profile.
pub(crate) fn pack_revolutions(raw: &[i32], profile: &[i32]) -> Result<Vec<u8>, StoreError> {
    let mut plain = Vec::with_capacity(raw.len() * 2);
    for (i, &u) in raw.iter().enumerate() {
        let base = profile.get(i % profile.len().max(1)).copied().unwrap_or(0);
        put_varint(&mut plain, zigzag(i64::from(u) - i64::from(base)));
    }
    compress("raw_revolutions", &plain, &[])
}

/// Unpacks [`pack_revolutions`] against the same profile: every value the pack holds.
pub(crate) fn unpack_revolutions(blob: &[u8], profile: &[i32]) -> Result<Vec<i32>, StoreError> {
    const FIELD: &str = "raw_revolutions";
    let plain = decompress(FIELD, blob, &[])?;
    let mut values = Varints {
        bytes: &plain,
        field: FIELD,
    };
    let mut out = Vec::new();
    while !values.bytes.is_empty() {
        let base = profile.get(out.len() % profile.len().max(1)).copied();
        let base =
            base.ok_or_else(|| StoreError::invalid(FIELD, "raw values without a profile"))?;
        out.push(to_i32(FIELD, values.next_i64()? + i64::from(base))?);
    }
    Ok(out)
}

fn to_i32(field: &'static str, v: i64) -> Result<i32, StoreError> {
    i32::try_from(v)
        .map_err(|_| StoreError::invalid(field, format!("packed value {v} is out of range")))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The one reused context makes the same frames as a fresh context per call, whatever
    /// came before: a dictionary or level set for one blob never leaks into the next (a
    /// blob packed without a dictionary must read back without one).
    #[test]
    fn the_reused_context_packs_as_a_fresh_one() {
        let parent = b"N10 G1 C=0 X=1.2345\nN20 G1 C=1 X=1.2399\n".repeat(20);
        let child = b"N10 G1 C=0 X=1.2346\nN20 G1 C=1 X=1.2398\n".repeat(20);
        let empty: &[u8] = &[];
        let jobs = [
            (3, &child[..], &parent[..]),
            (3, &child[..], empty),
            (19, &parent[..], &child[..]),
            (3, &parent[..], empty),
            (1, &child[..], &parent[..]),
        ];
        for (k, (level, plain, dictionary)) in jobs.into_iter().enumerate() {
            let reused = zstd_compress(level, plain, dictionary).unwrap();
            let fresh = zstd::bulk::Compressor::with_dictionary(level, dictionary)
                .unwrap()
                .compress(plain)
                .unwrap();
            assert_eq!(reused, fresh, "job {k}");
            let back = zstd::bulk::Decompressor::with_dictionary(dictionary)
                .unwrap()
                .decompress(&reused, MAX_PLAIN)
                .unwrap();
            assert_eq!(back, plain, "job {k}");
        }
    }

    #[test]
    fn zigzag_and_varints_round_trip_at_the_extremes() {
        let values = [
            0,
            1,
            -1,
            63,
            -64,
            64,
            i64::from(i32::MAX),
            i64::from(i32::MIN) * 2,
        ];
        let mut bytes = Vec::new();
        for v in values {
            put_varint(&mut bytes, zigzag(v));
        }
        let mut r = Varints {
            bytes: &bytes,
            field: "test",
        };
        for v in values {
            assert_eq!(r.next_i64().unwrap(), v);
        }
        assert!(r.bytes.is_empty());
        // A value cut off after its first byte is an error, not a zero.
        let mut cut = Varints {
            bytes: &[0x80],
            field: "test",
        };
        assert!(cut.next_i64().is_err());
    }

    #[test]
    fn profiles_and_revolutions_round_trip_exactly_including_extremes() {
        let profile: Vec<i32> = (0..360)
            .map(|i| (f64::from(i).to_radians().sin() * 40_000.0) as i32)
            .chain([i32::MAX, i32::MIN, 0])
            .collect();
        let blob = pack_profile(&profile).unwrap();
        assert_eq!(unpack_profile(&blob, profile.len()).unwrap(), profile);
        assert!(unpack_profile(&blob, profile.len() - 1).is_err());
        assert!(unpack_profile(&blob, profile.len() + 1).is_err());
        let raw: Vec<i32> = (0..3)
            .flat_map(|rev| profile.iter().map(move |&p| p.wrapping_add(rev * 7 - 3)))
            .collect();
        let blob = pack_revolutions(&raw, &profile).unwrap();
        assert_eq!(unpack_revolutions(&blob, &profile).unwrap(), raw);
    }

    #[test]
    fn text_round_trips_with_and_without_a_dictionary_and_damage_is_an_error() {
        let parent = "N10 CTABDEF(1,1)\nX=1.2345 Y=2.3456\n".repeat(50);
        let child = parent.replace("2.3456", "2.3457");
        let alone = pack_text("program", &child, "").unwrap();
        let with = pack_text("program", &child, &parent).unwrap();
        assert!(
            with.len() < alone.len(),
            "{} vs {}",
            with.len(),
            alone.len()
        );
        assert_eq!(unpack_text("program", &with, &parent).unwrap(), child);
        assert_eq!(unpack_text("program", &alone, "").unwrap(), child);
        let mut bad = with.clone();
        bad[0] = 9;
        assert!(unpack_text("program", &bad, &parent).is_err());
        assert!(unpack_text("program", &with[..with.len() / 2], &parent).is_err());
    }
}
