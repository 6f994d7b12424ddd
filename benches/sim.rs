//! Throughput of the simulator. The emulator steps at 100 Hz, so anything
//! near a million steps a second leaves the BeagleBone idle; the target on a
//! desktop core is ≥ 1 M steps/s for the thesis model's RK4 step and
//! ≥ 100 k steps/s for a whole 6-DOF plant step (thrusters, environment,
//! RK4), still 1000× real time.
//!
//! Besides criterion's figures, the binary prints the 6-DOF plant's steps/s
//! beside the thesis plant's and their ratio, measured in the same run
//! (the machine is shared, so only a same-run ratio compares fairly).

#![allow(
    clippy::print_stdout,
    reason = "a bench binary's output is its figures"
)]

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{Criterion, Throughput, criterion_group};
use nalgebra::Vector4;
use neptunus::sim::{
    Demand, Plant, SensorModel, SensorParams, SimOptions, SimState, ThesisModel, ThesisParams,
};

const STEPS: u64 = 1000;
const WIRING: [i8; 3] = [-1, 1, 1];
/// A varied but fixed drive: surge, some heave, a turn.
const ESC_US: [u16; 3] = [1250, 1650, 1800];

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
    for (name, opts) in [
        ("plant_thesis_ideal_step_x1000", SimOptions::ideal_thesis()),
        ("plant_six_dof_step_x1000", SimOptions::default()),
    ] {
        let plant = Plant::new(&opts, WIRING).unwrap_or_else(|e| panic!("{e}"));
        group.bench_function(name, |b| {
            b.iter(|| {
                let mut p = black_box(plant.clone());
                for _ in 0..STEPS {
                    p.step(black_box(ESC_US), black_box(0.01));
                }
                p.truth()
            })
        });
    }
    let sensors = SensorModel::new(SensorParams::default());
    group.throughput(Throughput::Elements(1));
    group.bench_function("sensor_read", |b| {
        b.iter(|| sensors.read(black_box(&start), black_box(&demand)))
    });
    let mut plant = Plant::new(&SimOptions::default(), WIRING).unwrap_or_else(|e| panic!("{e}"));
    let mut t = Duration::ZERO;
    group.bench_function("plant_read_noisy", |b| {
        b.iter(|| {
            t += Duration::from_millis(100);
            plant.read(black_box(t))
        })
    });
    group.finish();
}

criterion_group!(benches, rk4_step);

/// Median steps/s of `rounds` runs of `steps` chained plant steps.
fn plant_steps_per_s(opts: &SimOptions, steps: u32, rounds: usize) -> f64 {
    let mut rates: Vec<f64> = (0..rounds)
        .map(|_| {
            let mut p = Plant::new(opts, WIRING).unwrap_or_else(|e| panic!("{e}"));
            let start = Instant::now();
            for _ in 0..steps {
                p.step(black_box(ESC_US), black_box(0.01));
            }
            black_box(p.truth());
            f64::from(steps) / start.elapsed().as_secs_f64()
        })
        .collect();
    rates.sort_by(f64::total_cmp);
    rates[rates.len() / 2]
}

fn main() {
    benches();
    Criterion::default().configure_from_args().final_summary();
    // `cargo bench` passes --bench; `cargo test --all-targets` runs this
    // binary without it: then a short smoke run shows the bench still works.
    let full = std::env::args().any(|a| a == "--bench");
    let (steps, rounds) = if full { (100_000, 21) } else { (1_000, 3) };
    // Interleaved so both see the same machine load.
    let mut thesis = Vec::new();
    let mut six = Vec::new();
    for _ in 0..3 {
        thesis.push(plant_steps_per_s(
            &SimOptions::ideal_thesis(),
            steps,
            rounds,
        ));
        six.push(plant_steps_per_s(&SimOptions::default(), steps, rounds));
    }
    thesis.sort_by(f64::total_cmp);
    six.sort_by(f64::total_cmp);
    let (thesis, six) = (thesis[1], six[1]);
    println!();
    println!(
        "Plant::step, same run (median of {rounds} × {steps} chained steps, 3 interleaved passes):"
    );
    println!("  thesis-4dof, ideal options : {:>12.0} steps/s", thesis);
    println!("  six-dof, default options   : {:>12.0} steps/s", six);
    println!(
        "  six-dof / thesis ratio     : {:>12.3}  (six-dof is {:.1}× slower; real time needs 100 steps/s)",
        six / thesis,
        thesis / six
    );
}
