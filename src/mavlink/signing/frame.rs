//! Where the signature sits in a raw MAVLink frame.
//!
//! Owns the wire constants of the signature block, the check that a byte
//! slice is exactly one frame ([`layout`]), and the small byte helpers the
//! verifier and the signer share. Pure functions of bytes; never panics on
//! any input.

pub(super) const STX_V1: u8 = mavlink_core::MAV_STX;
pub(super) const STX_V2: u8 = mavlink_core::MAV_STX_V2;
const V1_HEADER_LEN: usize = 6;
const V2_HEADER_LEN: usize = 10;
pub(super) const CRC_LEN: usize = 2;
/// Link id (1), timestamp (6), signature (6).
pub(super) const SIGNATURE_BLOCK_LEN: usize = 13;
pub(super) const TIMESTAMP_LEN: usize = 6;
pub(super) const SIGNATURE_LEN: usize = 6;
pub(super) const IFLAG_SIGNED: u8 = 0x01;

/// Where things are in one complete frame.
pub(super) enum Layout {
    Unsigned,
    Signed {
        /// End of the CRC: everything before is covered by the signature.
        crc_end: usize,
    },
}

/// Checks that `raw` is exactly one frame (by its own length byte and
/// flags); the CRC is not checked (the signature covers it).
pub(super) fn layout(raw: &[u8]) -> Option<Layout> {
    let payload_len = usize::from(*raw.get(1)?);
    match *raw.first()? {
        STX_V1 => (raw.len() == V1_HEADER_LEN + payload_len + CRC_LEN).then_some(Layout::Unsigned),
        STX_V2 => {
            let crc_end = V2_HEADER_LEN + payload_len + CRC_LEN;
            if raw.get(2)? & IFLAG_SIGNED == 0 {
                (raw.len() == crc_end).then_some(Layout::Unsigned)
            } else {
                (raw.len() == crc_end + SIGNATURE_BLOCK_LEN).then_some(Layout::Signed { crc_end })
            }
        }
        _ => None,
    }
}

pub(super) fn read_timestamp(bytes: &[u8; TIMESTAMP_LEN]) -> u64 {
    let mut le = [0u8; 8];
    le[..TIMESTAMP_LEN].copy_from_slice(bytes);
    u64::from_le_bytes(le)
}

/// Compares without an early exit, so the time taken does not tell an
/// attacker how many leading signature bytes were right.
pub(super) fn same_signature(a: &[u8; SIGNATURE_LEN], b: &[u8; SIGNATURE_LEN]) -> bool {
    a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// `raw` is a MAVLink 2 frame with the signed flag set (signature not checked).
pub fn is_signed(raw: &[u8]) -> bool {
    matches!(layout(raw), Some(Layout::Signed { .. }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constants_match_the_crate() {
        assert_eq!(
            SIGNATURE_BLOCK_LEN,
            mavlink_core::consts::v2::SIGNATURE_SIZE
        );
        assert_eq!(
            TIMESTAMP_LEN,
            mavlink_core::consts::v2::SIGNATURE_TIMESTAMP_SIZE
        );
        assert_eq!(
            SIGNATURE_LEN,
            mavlink_core::consts::v2::SIGNATURE_VALUE_SIZE
        );
        assert_eq!(IFLAG_SIGNED, mavlink_core::consts::v2::IFLAG_SIGNED);
    }
}
