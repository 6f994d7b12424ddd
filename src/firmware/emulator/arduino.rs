//! The Arduino core's arithmetic and printing, as the board firmware sees
//! them: `Print::print(float)` with two decimals, `print(x, HEX)`, `atoi`,
//! `map`, `constrain`, the sketch's `mapf`, and its `Timer` class.
//!
//! Owns only pure functions on numbers and text: the AVR's `double` is a
//! 32-bit float and its `int` 16 bits wide, so everything here computes in
//! `f32`/`i32` exactly as the board would and truncates where C truncates.
//! It never touches the board's state or the clock (the time is an argument).

/// `Print::print(double, 2)` of the Arduino AVR core: sign, integer part,
/// then each decimal extracted after adding half of the last digit, all in
/// single precision (which is what makes `0.125` print `0.13` and large
/// uptimes lose their last digits).
pub(super) fn float(x: f32) -> String {
    float_digits(x, 2)
}

fn float_digits(x: f32, digits: u8) -> String {
    if x.is_nan() {
        return "nan".into();
    }
    if x.is_infinite() {
        return "inf".into();
    }
    if !(-4_294_967_040.0..=4_294_967_040.0).contains(&x) {
        return "ovf".into();
    }
    let mut s = String::with_capacity(12);
    let mut n = x;
    if n < 0.0 {
        s.push('-');
        n = -n;
    }
    let mut rounding: f32 = 0.5;
    for _ in 0..digits {
        rounding /= 10.0;
    }
    n += rounding;
    // In range by the check above; the C cast truncates.
    let int_part = n as u32;
    let mut remainder = n - int_part as f32;
    s.push_str(&int_part.to_string());
    if digits > 0 {
        s.push('.');
    }
    for _ in 0..digits {
        remainder *= 10.0;
        let digit = remainder as u32;
        s.push_str(&digit.to_string());
        remainder -= digit as f32;
    }
    s
}

/// `Print::print(byte, HEX)`: upper case, no leading zero.
pub(super) fn hex(b: u8) -> String {
    format!("{b:X}")
}

/// avr-libc `atoi` into a 16-bit `int`: leading white space, an optional
/// sign, the digits that follow; anything after is ignored, and the value
/// wraps as the board's multiply-and-add does.
pub(super) fn atoi(s: &[u8]) -> i32 {
    let mut i = 0;
    while i < s.len() && matches!(s[i], b' ' | b'\t' | b'\n' | b'\r' | 0x0b | 0x0c) {
        i += 1;
    }
    let mut neg = false;
    if i < s.len() && (s[i] == b'-' || s[i] == b'+') {
        neg = s[i] == b'-';
        i += 1;
    }
    let mut v: i16 = 0;
    while i < s.len() && s[i].is_ascii_digit() {
        v = v.wrapping_mul(10).wrapping_add(i16::from(s[i] - b'0'));
        i += 1;
    }
    i32::from(if neg { v.wrapping_neg() } else { v })
}

/// Arduino `map` on `long`s (C division truncates toward zero).
pub(super) fn map(x: i32, in_min: i32, in_max: i32, out_min: i32, out_max: i32) -> i32 {
    let (x, in_min, in_max, out_min, out_max) = (
        i64::from(x),
        i64::from(in_min),
        i64::from(in_max),
        i64::from(out_min),
        i64::from(out_max),
    );
    if in_max == in_min {
        // The AVR's division by zero gives garbage; never reached with the
        // firmware's constant ranges.
        return out_min as i32;
    }
    ((x - in_min) * (out_max - out_min) / (in_max - in_min) + out_min) as i32
}

/// Arduino `constrain`.
pub(super) fn constrain(x: i32, lo: i32, hi: i32) -> i32 {
    x.clamp(lo, hi)
}

/// The controller board's `mapf(long x, long in_min, long in_max, long
/// out_min, long out_max)`: the ADC code scaled in single precision.
pub(super) fn mapf(x: i32, in_min: i32, in_max: i32, out_min: i32, out_max: i32) -> f32 {
    (x - in_min) as f32 * (out_max - out_min) as f32 / (in_max - in_min) as f32 + out_min as f32
}

/// C's conversion of a float to `int`: toward zero, saturating here where
/// the AVR would wrap (only reached with values the firmware never makes).
pub(super) fn trunc(x: f32) -> i32 {
    if x.is_nan() {
        0
    } else {
        (x as i32).clamp(i32::from(i16::MIN), i32::from(i16::MAX))
    }
}

/// The sketch's `Timer`: `elapsed(ms)` is true once more than `ms`
/// milliseconds passed since the last time it was, and restarts from now
/// (not from the due time, so the periods drift by the loop's lateness).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Timer {
    last_ms: u64,
}

impl Timer {
    pub(super) fn reset(&mut self, now_ms: u64) {
        self.last_ms = now_ms;
    }

    pub(super) fn elapsed(&mut self, now_ms: u64, period_ms: u64) -> bool {
        if now_ms.saturating_sub(self.last_ms) > period_ms {
            self.last_ms = now_ms;
            true
        } else {
            false
        }
    }

    /// The first `millis()` at which [`Timer::elapsed`] would be true.
    pub(super) fn due_ms(&self, period_ms: u64) -> u64 {
        self.last_ms + period_ms + 1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floats_print_as_the_avr_core_prints_them() {
        assert_eq!(float(0.0), "0.00");
        assert_eq!(float(12.004), "12.00");
        assert_eq!(float(0.2), "0.20");
        assert_eq!(float(-0.001), "-0.00");
        assert_eq!(float(25.059), "25.06");
        assert_eq!(float(912.0), "912.00");
        assert_eq!(float(51.0 / 255.0), "0.20");
        assert_eq!(float(f32::NAN), "nan");
        assert_eq!(float(5e9), "ovf");
        // Single precision: an uptime past 2^24 ms loses its last digit.
        assert_eq!(float(16_777_217.0), "16777216.00");
    }

    #[test]
    fn atoi_takes_the_leading_number_and_wraps_at_16_bits() {
        assert_eq!(atoi(b" 7 "), 7);
        assert_eq!(atoi(b"8x"), 8);
        assert_eq!(atoi(b"-20"), -20);
        assert_eq!(atoi(b"x"), 0);
        assert_eq!(atoi(b"40000"), 40000 - 65536);
    }

    #[test]
    fn map_truncates_like_c() {
        assert_eq!(map(1600, 1500, 2000, 1550, 2000), 1640);
        assert_eq!(map(1300, 1000, 1500, 1000, 1450), 1270);
        assert_eq!(map(10, -100, 100, 1000, 2000), 1550);
        assert_eq!(map(1750, 1000, 2000, -100, 100), 50);
    }

    #[test]
    fn a_timer_fires_after_more_than_its_period_and_restarts_from_then() {
        let mut t = Timer::default();
        t.reset(0);
        assert!(!t.elapsed(100, 100));
        assert_eq!(t.due_ms(100), 101);
        assert!(t.elapsed(103, 100));
        assert!(!t.elapsed(203, 100));
        assert!(t.elapsed(204, 100));
    }
}
