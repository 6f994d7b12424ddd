//! Decoder throughput on realistic board output: nine nav lines (10 Hz) for
//! every status line (1 Hz), as the board sends them. Target: well above
//! 1 M lines/s, so that decoding is never what limits the link task on a
//! BeagleBone.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use neptunus::firmware::codec::{Command, Framing, LineDecoder, encode};
use std::hint::black_box;

const LINES: usize = 10_000;

fn board_output() -> Vec<u8> {
    let mut out = Vec::new();
    for i in 0..LINES {
        // Deterministic, varied values so the float parser sees real digits.
        let f = i as f64;
        if i % 10 == 9 {
            out.extend_from_slice(
                format!(
                    "vout:{:.2};iout:{:.2};BT1I:{:.2};pres:{:.2};temp:{:.2};time:{};fmem:{};\
                     motorAttached:1;servo:{};starg:1500;mtarg:1500,1500,1500;\r\n",
                    11.0 + (f * 0.01) % 2.0,
                    (f * 0.003) % 3.0,
                    (f * 0.007) % 5.0,
                    1013.0 + (f * 0.37) % 500.0,
                    12.0 + (f * 0.01) % 5.0,
                    i * 100,
                    2000 + i % 100,
                    1400 + i % 200,
                )
                .as_bytes(),
            );
        } else {
            out.extend_from_slice(
                format!(
                    "hdgd:{:.2};deep:{:.2};pitc:{:.2};roll:{:.2};yaw:{:.2};fthr:{:.2};\r\n",
                    (f * 1.37) % 360.0,
                    (f * 0.01) % 50.0,
                    (f * 0.73) % 90.0 - 45.0,
                    (f * 0.29) % 60.0 - 30.0,
                    (f * 1.37) % 360.0 - 180.0,
                    (f * 0.11) % 200.0 - 100.0,
                )
                .as_bytes(),
            );
        }
    }
    out
}

fn decode(c: &mut Criterion) {
    let stream = board_output();
    let mut group = c.benchmark_group("codec");
    group.throughput(Throughput::Elements(LINES as u64));
    let mut events = Vec::with_capacity(LINES);
    group.bench_function("decode_nav_status_lines", |b| {
        b.iter(|| {
            let mut decoder = LineDecoder::new();
            events.clear();
            // Serial reads arrive in small pieces; 64 bytes is typical.
            for chunk in black_box(stream.as_slice()).chunks(64) {
                decoder.push(chunk, &mut events);
            }
            assert_eq!(decoder.stats().lines_accepted, LINES as u64);
            black_box(&events);
        });
    });
    group.finish();

    let mut group = c.benchmark_group("codec");
    group.throughput(Throughput::Elements(1));
    let go = Command::Go {
        port_us: 1534,
        vertical_us: 1500,
        starboard_us: 1466,
    };
    let mut out = Vec::with_capacity(32);
    group.bench_function("encode_go_crc8", |b| {
        b.iter(|| {
            out.clear();
            encode(black_box(&go), Framing::Crc8, &mut out);
            black_box(&out);
        });
    });
    group.finish();
}

criterion_group!(benches, decode);
criterion_main!(benches);
