//! Throughput of the simulator's RK4 step. The emulator steps at 100 Hz, so
//! anything near a million steps a second leaves the BeagleBone idle; the
//! target on a desktop core is ≥ 1 M steps/s.

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use nalgebra::Vector4;
use neptunus::sim::{Demand, SensorModel, SensorParams, SimState, ThesisModel, ThesisParams};

const STEPS: u64 = 1000;

fn rk4_step(c: &mut Criterion) {
    let model = ThesisModel::new(ThesisParams::default());
    let demand = Demand {
        surge: 0.8,
        heave: 0.3,
        yaw: 0.2,
    };
    let start = SimState {
        eta: Vector4::new(0.0, 0.0, 1.0, 0.3),
        nu: Vector4::new(0.5, 0.01, 0.1, 0.05),
    };
    let mut group = c.benchmark_group("sim");
    // Steps are chained, as in a real run, so each depends on the last and
    // the compiler cannot overlap or drop them.
    group.throughput(Throughput::Elements(STEPS));
    group.bench_function("thesis_rk4_step_x1000", |b| {
        b.iter(|| {
            let mut s = black_box(start);
            for _ in 0..STEPS {
                s = model.step(&s, black_box(&demand), black_box(0.01));
            }
            s
        })
    });
    let sensors = SensorModel::new(SensorParams::default());
    group.throughput(Throughput::Elements(1));
    group.bench_function("sensor_read", |b| {
        b.iter(|| sensors.read(black_box(&start), black_box(&demand)))
    });
    group.finish();
}

criterion_group!(benches, rk4_step);
criterion_main!(benches);
