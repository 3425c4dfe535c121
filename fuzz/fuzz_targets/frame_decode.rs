//! Fuzz target: raw CAN frames into the DBC decoder and the assembler.
//! Input: a sequence of records `[id: 4 bytes LE, bit 31 = extended][len: 1 byte][data]`.
#![no_main]

use camloop::gauge::{Assembled, Assembler, CanId, GaugeDbc};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|input: &[u8]| {
    let dbc = GaugeDbc::builtin();
    let mut assembler = Assembler::new("fuzz");
    let mut rest = input;
    while rest.len() >= 5 {
        let word = u32::from_le_bytes([rest[0], rest[1], rest[2], rest[3]]);
        // Bias ids towards the gauge's own so the decoder's paths are reached often.
        let id = match (word >> 31, word & 3) {
            (1, _) => CanId::Extended(word & 0x1fff_ffff),
            (0, 0) => CanId::Standard((word >> 2 & 0x7ff) as u16),
            (_, low) => CanId::Standard(0x5a0 + low as u16 - 1),
        };
        let len = usize::from(rest[4] % 12).min(rest.len() - 5);
        let data = &rest[5..5 + len];
        rest = &rest[5 + len..];
        if let Ok(frame) = dbc.decode(id, data)
            && let Some(Assembled::Measurement(m)) = assembler.push(frame)
        {
            for s in &m.samples {
                assert!(s.revolution < m.header.revolutions);
                assert!(s.angle_index < m.header.points_per_rev);
                assert!(s.lift_mm.is_finite());
            }
        }
    }
    let _ = assembler.finish();
});
