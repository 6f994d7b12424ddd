//! Fuzzes the telemetry line decoder: any bytes, in any chunking, must
//! neither panic nor produce a value outside its key's physical range, and
//! the chunking must not change what comes out.
#![no_main]

use libfuzzer_sys::fuzz_target;
use neptunus::firmware::codec::{Event, LineDecoder, physical_range};

fn check(key: &str, value: f64) {
    let Some((lo, hi)) = physical_range(key) else {
        panic!("{key} has no range");
    };
    assert!(
        value.is_finite() && (lo..=hi).contains(&value),
        "{key}={value}"
    );
}

fn check_events(events: &[Event]) {
    for event in events {
        match event {
            Event::Nav(n) => {
                for (key, v) in [
                    ("hdgd", n.heading_deg),
                    ("deep", n.depth_m),
                    ("pitc", n.pitch_deg),
                    ("roll", n.roll_deg),
                    ("yaw", n.yaw_deg),
                    ("fthr", n.fthr_pct),
                ] {
                    v.into_iter().for_each(|v| check(key, v));
                }
            }
            Event::Status(s) => {
                for (key, v) in [
                    ("vout", s.vout_v),
                    ("iout", s.iout_a),
                    ("BT1I", s.battery_current_a.map(|a| a / 2.0)),
                    ("pres", s.pres_mbar),
                    ("temp", s.temp_c),
                    ("time", s.time_ms.map(|t| t as f64)),
                    ("fmem", s.fmem_bytes.map(f64::from)),
                    ("servo", s.servo_us.map(f64::from)),
                    ("starg", s.starg_us.map(f64::from)),
                ] {
                    v.into_iter().for_each(|v| check(key, v));
                }
                for (key, triple) in [("mtarg", s.mtarg_us), ("motors", s.motors_us)] {
                    triple
                        .into_iter()
                        .flatten()
                        .for_each(|v| check(key, f64::from(v)));
                }
            }
            Event::Capabilities(c) => check("CAPA", f64::from(*c)),
            Event::Lights { level, fraction } => {
                check("LIGT", f64::from(*level));
                fraction.iter().for_each(|&f| check("LIGP", f));
            }
            _ => {}
        }
    }
}

fuzz_target!(|data: &[u8]| {
    // The first byte picks the chunk size, the rest is the stream.
    let Some((&chunk, stream)) = data.split_first() else {
        return;
    };
    let chunk = usize::from(chunk).max(1);

    let mut whole = LineDecoder::new();
    let mut whole_events = Vec::new();
    whole.push(stream, &mut whole_events);
    check_events(&whole_events);

    let mut chunked = LineDecoder::new();
    let mut chunked_events = Vec::new();
    for piece in stream.chunks(chunk) {
        chunked.push(piece, &mut chunked_events);
    }
    assert_eq!(whole_events, chunked_events);
    assert_eq!(whole.stats(), chunked.stats());
});
