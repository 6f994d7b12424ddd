//! The synthetic camera's cost: what one frame takes to draw and encode,
//! and what the running source costs in CPU at its default 10 fps.
//!
//! 1. **Per frame**: [`SyntheticRenderer`] draws and encodes `CAMERA_FRAMES`
//!    frames (default 300) of a moving scene (heading, roll, pitch, depth
//!    change every frame), timed separately. The floor, measured in the same
//!    run, is encoding a flat grey picture of the same size: the JPEG
//!    encoder's least possible work; the ratio shows what the picture's
//!    content and the drawing add.
//! 2. **CPU at 10 fps**: [`Camera`] with the synthetic source at 640×480,
//!    10 fps for `CAMERA_SOAK_S` seconds (default 10) while a task moves
//!    the scene at 10 Hz; CPU time of this whole process (getrusage) over
//!    wall time, as a share of one core.
//!
//! Under `cargo test --all-targets` (no `--bench` argument) it does a smoke
//! run: 10 frames and a 1 s soak. Figures are printed, never asserted.

#![allow(
    clippy::print_stdout,
    reason = "a bench binary's output is its figures"
)]

use std::hint::black_box;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use jpeg_encoder::{ColorType, Encoder};
use neptunus::camera::{Camera, CameraConfig, Scene, SyntheticRenderer};
use nix::sys::resource::{UsageWho, getrusage};
use tokio::sync::watch;

fn knob(name: &str, full: u64, smoke: u64, is_full: bool) -> anyhow::Result<u64> {
    match std::env::var(name) {
        Ok(v) => v
            .trim()
            .parse::<u64>()
            .map(|n| n.max(1))
            .with_context(|| format!("{name}={v:?} is not a whole number")),
        Err(_) => Ok(if is_full { full } else { smoke }),
    }
}

fn scene(i: u64) -> Scene {
    let t = i as f64 * 0.1;
    Scene {
        depth_m: 5.0 + 4.0 * (t * 0.3).sin(),
        heading_deg: (t * 12.0) % 360.0,
        roll_deg: 15.0 * (t * 0.7).sin(),
        pitch_deg: 8.0 * (t * 0.5).cos(),
        tilt_deg: 10.0,
        simulated: true,
        armed: i % 20 < 10,
    }
}

fn pct(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((sorted.len() - 1) as f64 * q).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

struct Times(Vec<f64>);

impl Times {
    fn summary(&mut self) -> (f64, f64, f64) {
        self.0.sort_by(f64::total_cmp);
        let mean = self.0.iter().sum::<f64>() / self.0.len().max(1) as f64;
        (pct(&self.0, 0.5), pct(&self.0, 0.99), mean)
    }
}

fn per_frame(width: u32, height: u32, frames: u64) -> anyhow::Result<()> {
    let mut r = SyntheticRenderer::new(width, height, 80);
    let (mut render, mut encode, mut total) = (Times(vec![]), Times(vec![]), Times(vec![]));
    let mut bytes = 0usize;
    // Warm-up: first-touch of the buffers.
    r.render_jpeg(&scene(0))?;
    for i in 0..frames {
        let t0 = Instant::now();
        black_box(r.render(black_box(&scene(i))));
        let t1 = Instant::now();
        let jpeg = r.encode()?;
        let t2 = Instant::now();
        bytes += jpeg.len();
        render.0.push((t1 - t0).as_secs_f64() * 1e3);
        encode.0.push((t2 - t1).as_secs_f64() * 1e3);
        total.0.push((t2 - t0).as_secs_f64() * 1e3);
    }
    let grey = vec![128u8; width as usize * height as usize * 3];
    let mut floor = Times(vec![]);
    for _ in 0..frames {
        let mut out = Vec::with_capacity(64 * 1024);
        let t0 = Instant::now();
        Encoder::new(&mut out, 80).encode(
            black_box(&grey),
            width as u16,
            height as u16,
            ColorType::Rgb,
        )?;
        floor.0.push(t0.elapsed().as_secs_f64() * 1e3);
        black_box(&out);
    }
    let (rp50, rp99, _) = render.summary();
    let (ep50, ep99, _) = encode.summary();
    let (tp50, tp99, tmean) = total.summary();
    let (fp50, fp99, _) = floor.summary();
    println!("{width}×{height}, quality 80, {frames} frames:");
    println!("  {:<34} {:>8} {:>8}", "", "p50 ms", "p99 ms");
    println!("  {:<34} {rp50:>8.3} {rp99:>8.3}", "draw");
    println!("  {:<34} {ep50:>8.3} {ep99:>8.3}", "encode");
    println!("  {:<34} {tp50:>8.3} {tp99:>8.3}", "draw + encode");
    println!(
        "  {:<34} {fp50:>8.3} {fp99:>8.3}",
        "floor: encode a flat grey frame"
    );
    println!(
        "  draw + encode is {:.1}× the floor; mean JPEG {:.1} KiB; at 10 fps that is {:.1}% of one core (mean {tmean:.3} ms × 10 per second)",
        tp50 / fp50,
        bytes as f64 / frames as f64 / 1024.0,
        // ms per frame × 10 frames per 1000 ms, in percent.
        tmean * 10.0 / 1000.0 * 100.0,
    );
    Ok(())
}

fn cpu_s() -> anyhow::Result<f64> {
    let u = getrusage(UsageWho::RUSAGE_SELF)?;
    let tv = |t: nix::sys::time::TimeVal| t.tv_sec() as f64 + t.tv_usec() as f64 * 1e-6;
    Ok(tv(u.user_time()) + tv(u.system_time()))
}

fn soak(seconds: u64) -> anyhow::Result<()> {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    rt.block_on(async {
        let (tx, rx) = watch::channel(scene(0));
        let camera = Camera::start(CameraConfig::synthetic(), rx);
        let mover = tokio::spawn(async move {
            let mut tick = tokio::time::interval(Duration::from_millis(100));
            for i in 0.. {
                tick.tick().await;
                tx.send_replace(scene(i));
            }
        });
        // Let the first frame and the thread pool settle before measuring.
        let mut frames = camera.subscribe();
        frames.wait_for(|f| f.is_some()).await?;
        let (cpu0, wall0, n0) = (cpu_s()?, Instant::now(), camera.status().frames_total);
        tokio::time::sleep(Duration::from_secs(seconds)).await;
        let (cpu1, wall, s) = (cpu_s()?, wall0.elapsed(), camera.status());
        mover.abort();
        camera.shutdown().await;
        let share = (cpu1 - cpu0) / wall.as_secs_f64() * 100.0;
        println!(
            "synthetic source 640×480 at 10 fps for {:.1} s: {} frames ({:.2} fps measured), process CPU {share:.1}% of one core",
            wall.as_secs_f64(),
            s.frames_total - n0,
            s.fps
        );
        anyhow::Ok(())
    })
}

fn main() -> anyhow::Result<()> {
    // `cargo bench` passes --bench; `cargo test --all-targets` does not,
    // and then a smoke run shows the bench still works.
    let full = std::env::args().any(|a| a == "--bench");
    let frames = knob("CAMERA_FRAMES", 300, 10, full)?;
    let soak_s = knob("CAMERA_SOAK_S", 10, 1, full)?;
    if !full {
        println!("smoke run (cargo bench runs the full one)");
    }
    per_frame(640, 480, frames)?;
    if full {
        per_frame(1280, 720, frames / 3)?;
    }
    soak(soak_s)
}
