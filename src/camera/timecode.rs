//! A capture time painted into the synthetic picture, for measuring the
//! delay from the camera to a screen (`benches/video_latency.rs`).
//!
//! The code is 32 square blocks, black (0) or white (1), in two rows of
//! 16 along the picture's bottom-left corner: the low 24 bits of the
//! capture time in milliseconds since the Unix epoch (CLOCK_REALTIME, the
//! clock a browser's `Date.now()` reads; they wrap every 4.7 hours), then
//! a CRC-8 of those three bytes, most significant bit first, row by row.
//! A block is 16 pixels square (32 from 960 lines up) and sits on the
//! 16-pixel grid JPEG's and H.264's blocks use, so it survives either
//! encoder at its default quality. A reader samples the middle of each
//! block and refuses the code when a block is neither clearly black nor
//! clearly white or the CRC does not match — a picture the decoder has
//! only half updated, or one blended on the way, is not misread.
//!
//! Off unless `[camera] synthetic_timecode = true`: the picture stays a
//! pure function of the scene, and the pilot sees no code.
//! `tests/browser/latency-bench.js` reads the same code in the browser;
//! the two must change together.

use crate::firmware::codec::crc8;

/// Blocks per row, and rows.
const COLUMNS: usize = 16;
const ROWS: usize = 2;
/// Bits of the time in the code.
pub const TIME_BITS: u32 = 24;
const TIME_MASK: u32 = (1 << TIME_BITS) - 1;
/// A block's mean luma at or below this reads 0, at or above the other 1;
/// anything between is no code.
const DARK_MAX: u32 = 80;
const LIGHT_MIN: u32 = 175;

/// The side of one block in pixels for a picture `height` lines high.
pub fn block_px(height: usize) -> usize {
    if height >= 960 { 32 } else { 16 }
}

/// Where the code sits: its top-left corner and block size, or `None`
/// when the picture is too small to hold it.
fn place(width: usize, height: usize) -> Option<(usize, usize, usize)> {
    let b = block_px(height);
    (width >= COLUMNS * b && height >= ROWS * b).then(|| (0, height - ROWS * b, b))
}

/// Whether a `width`×`height` picture can carry the code.
pub fn fits(width: u32, height: u32) -> bool {
    place(width as usize, height as usize).is_some()
}

/// XORed into the check, so an all-black or all-white corner (a video
/// element before its first picture) is no code.
const CHECK_XOR: u8 = 0xA5;

fn check(t: u32) -> u8 {
    crc8(&t.to_be_bytes()[1..]) ^ CHECK_XOR
}

/// The 32 bits for `unix_ms`, first block first.
fn bits(unix_ms: u64) -> u32 {
    let t = (unix_ms as u32) & TIME_MASK;
    (t << 8) | u32::from(check(t))
}

/// Paints the code for `unix_ms` into `rgb` (`width`×`height` RGB pixels,
/// row by row). Nothing when the picture is too small.
pub fn paint(rgb: &mut [u8], width: usize, height: usize, unix_ms: u64) {
    let Some((x0, y0, b)) = place(width, height) else {
        return;
    };
    if rgb.len() < width * height * 3 {
        return;
    }
    let code = bits(unix_ms);
    for i in 0..COLUMNS * ROWS {
        let on = code & (1 << (31 - i)) != 0;
        let v = if on { 255 } else { 0 };
        let (bx, by) = (x0 + (i % COLUMNS) * b, y0 + (i / COLUMNS) * b);
        for y in by..by + b {
            rgb[(y * width + bx) * 3..(y * width + bx + b) * 3].fill(v);
        }
    }
}

/// Why a picture gave no time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum Unreadable {
    #[error("the picture is too small for the code")]
    TooSmall,
    #[error("block {0} is neither black nor white")]
    Grey(usize),
    #[error("the check does not match")]
    Check,
}

/// Reads the code from `luma` (`width`×`height` 8-bit luma, row by row):
/// the low [`TIME_BITS`] bits of the capture time in milliseconds.
pub fn read(luma: &[u8], width: usize, height: usize) -> Result<u32, Unreadable> {
    let (x0, y0, b) = place(width, height).ok_or(Unreadable::TooSmall)?;
    if luma.len() < width * height {
        return Err(Unreadable::TooSmall);
    }
    // The middle half of the block: away from the ringing at its edges.
    let (m0, m1) = (b / 4, b - b / 4);
    let mut code = 0u32;
    for i in 0..COLUMNS * ROWS {
        let (bx, by) = (x0 + (i % COLUMNS) * b, y0 + (i / COLUMNS) * b);
        let mut sum = 0u32;
        for y in by + m0..by + m1 {
            let row = &luma[y * width + bx + m0..y * width + bx + m1];
            sum += row.iter().map(|&v| u32::from(v)).sum::<u32>();
        }
        let mean = sum / ((m1 - m0) * (m1 - m0)) as u32;
        let bit = if mean <= DARK_MAX {
            0
        } else if mean >= LIGHT_MIN {
            1
        } else {
            return Err(Unreadable::Grey(i));
        };
        code = (code << 1) | bit;
    }
    let t = code >> 8;
    if check(t) != (code & 0xff) as u8 {
        return Err(Unreadable::Check);
    }
    Ok(t)
}

/// Milliseconds from a capture time read as `code` to `now_unix_ms`: the
/// nearest candidate, so a reader's clock slightly behind the camera's
/// gives a small negative figure rather than a wrap.
pub fn age_ms(code: u32, now_unix_ms: u64) -> i64 {
    let d = ((now_unix_ms as u32).wrapping_sub(code)) & TIME_MASK;
    if d >= 1 << (TIME_BITS - 1) {
        i64::from(d) - (1 << TIME_BITS)
    } else {
        i64::from(d)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn luma_of(rgb: &[u8]) -> Vec<u8> {
        rgb.chunks_exact(3)
            .map(|p| {
                ((u32::from(p[0]) * 77 + u32::from(p[1]) * 150 + u32::from(p[2]) * 29) >> 8) as u8
            })
            .collect()
    }

    #[test]
    fn a_painted_time_reads_back_and_its_age_is_the_difference() {
        let (w, h) = (320, 240);
        let mut rgb = vec![90u8; w * h * 3];
        for ms in [
            0u64,
            1,
            0xff_ffff,
            0x1_0000_0000 + 12_345,
            1_764_000_000_123,
        ] {
            paint(&mut rgb, w, h, ms);
            let code = read(&luma_of(&rgb), w, h).expect("reads");
            assert_eq!(code, ms as u32 & TIME_MASK);
            assert_eq!(age_ms(code, ms + 42), 42);
            if ms >= 3 {
                assert_eq!(age_ms(code, ms - 3), -3);
            }
        }
    }

    #[test]
    fn the_code_survives_jpeg_at_the_cameras_quality() {
        use super::super::frame::Scene;
        use super::super::render::SyntheticRenderer;
        for (w, h) in [(640, 480), (1280, 960)] {
            let mut r = SyntheticRenderer::new(w, h, 80);
            r.render(&Scene {
                depth_m: 3.0,
                heading_deg: 120.0,
                ..Scene::default()
            });
            r.stamp(1_764_000_000_789);
            let jpeg = r.encode().expect("encodes");
            let mut dec = jpeg_decoder::Decoder::new(&jpeg[..]);
            let rgb = dec.decode().expect("decodes");
            let code = read(&luma_of(&rgb), w as usize, h as usize).expect("reads");
            assert_eq!(code, 1_764_000_000_789u64 as u32 & TIME_MASK);
        }
    }

    #[test]
    fn a_half_updated_or_blended_code_is_refused_not_misread() {
        let (w, h) = (640, 480);
        let (mut a, mut b) = (vec![0u8; w * h * 3], vec![0u8; w * h * 3]);
        // Far enough apart that both rows of blocks differ (pictures whose
        // first rows agree read as the newer one, which is right).
        paint(&mut a, w, h, 1_000_000);
        paint(&mut b, w, h, 1_000_000 + 0x1_0000 + 33);
        // The first row of blocks from one picture, the second from the other.
        let mut torn = a.clone();
        let split = (h - 16) * w * 3;
        torn[split..].copy_from_slice(&b[split..]);
        assert_eq!(read(&luma_of(&torn), w, h), Err(Unreadable::Check));
        // Two pictures blended half and half.
        let blend: Vec<u8> = a
            .iter()
            .zip(&b)
            .map(|(x, y)| ((u16::from(*x) + u16::from(*y)) / 2) as u8)
            .collect();
        assert!(matches!(
            read(&luma_of(&blend), w, h),
            Err(Unreadable::Grey(_))
        ));
        // No code at all: a picture without it, black, white.
        let plain = vec![128u8; w * h];
        assert!(read(&plain, w, h).is_err());
        assert_eq!(read(&vec![0u8; w * h], w, h), Err(Unreadable::Check));
        assert_eq!(read(&vec![255u8; w * h], w, h), Err(Unreadable::Check));
        assert_eq!(read(&plain, 100, 20), Err(Unreadable::TooSmall));
    }

    #[test]
    fn a_picture_too_small_is_left_alone() {
        let mut rgb = vec![7u8; 100 * 20 * 3];
        paint(&mut rgb, 100, 20, 123);
        assert!(rgb.iter().all(|&v| v == 7));
        assert!(!fits(100, 20));
        assert!(fits(256, 32));
    }
}
