//! Time without internet, end to end: the vehicle runs under libfaketime
//! (`faketime`, Debian's package) with its clock at 2000-01-01, as a
//! BeagleBone without RTC boots. Its telemetry log and event log start in
//! 2000; a SYSTEM_TIME from stations not in control changes nothing; once the
//! station in control sends its time, the next tlog file and event lines
//! carry that time, and a STATUSTEXT says so.

mod common;

use std::net::UdpSocket;
use std::path::Path;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use anyhow::{Context as _, bail};
use common::{Gcs, Traffic, Vehicle, board_runtime, free_udp_port, spawn_board, statustext};
use neptunus::dialect::neptunus::*;
use neptunus::mavlink::frame::encode_v2;

fn system_time(unix_us: u64) -> MavMessage {
    MavMessage::SYSTEM_TIME(SYSTEM_TIME_DATA {
        time_unix_usec: unix_us,
        time_boot_ms: 0,
    })
}

fn tlog_names(data: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(data.join("tlogs"))
        .map(|d| {
            d.flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    names.sort();
    names
}

fn event_lines(data: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(data.join("events/events.jsonl"))
        .unwrap_or_default()
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect()
}

/// Heartbeats until a STATUSTEXT containing `needle` arrives (true), or `within` passes.
fn await_text(
    gcs: &mut Gcs,
    vehicle: &mut Vehicle,
    needle: &str,
    within: Duration,
) -> anyhow::Result<bool> {
    gcs.run_until(vehicle, Traffic::Heartbeats, within, |msgs| {
        msgs.iter().any(|m| match m {
            MavMessage::STATUSTEXT(s) => statustext(s).contains(needle),
            _ => false,
        })
    })
}

#[test]
fn a_vehicle_booted_in_2000_takes_the_owners_time_for_its_logs() -> anyhow::Result<()> {
    let Ok(faketime) = which("faketime") else {
        bail!("faketime is not installed — `apt-get install faketime` (tests/run_all.sh does)");
    };
    let dir = tempfile::tempdir()?;
    let rt = board_runtime()?;
    let board = spawn_board(&rt, None)?;
    let (mut gcs, port) = Gcs::bind()?;
    let other_port = free_udp_port()?;
    let serial = board.path().to_string_lossy().into_owned();
    let udpout = format!("udpout:127.0.0.1:{port}");
    let udpin = format!("udpin:127.0.0.1:{other_port}");
    let bin = env!("CARGO_BIN_EXE_neptunus");
    let mut vehicle = Vehicle::spawn_env(
        &faketime,
        &[
            "2000-01-01 00:00:00",
            bin,
            "--serial",
            &serial,
            "--mavlink",
            &udpout,
            "--mavlink",
            &udpin,
        ],
        dir.path(),
        "",
        &[("FAKETIME_DONT_FAKE_MONOTONIC", "1")],
    )?;
    let data = vehicle.data_dir().to_path_buf();
    gcs.await_vehicle(&mut vehicle, Duration::from_secs(30))?;
    let first = tlog_names(&data);
    assert!(
        first.iter().all(|n| n.starts_with("neptunus-2000")) && !first.is_empty(),
        "the vehicle's clock is not in 2000 (is faketime working?): {first:?}"
    );

    // Stations not in control: 77 (not allowed) and 245 (allowed, MAVSDK's id).
    let now_us = || {
        SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| d.as_micros() as u64)
    };
    let other = UdpSocket::bind("127.0.0.1:0")?;
    for sysid in [77, 245] {
        let frame = encode_v2(sysid, 190, 0, &system_time(now_us()));
        other.send_to(&frame, ("127.0.0.1", other_port))?;
    }
    gcs.wait_ready(&mut vehicle)?;
    gcs.arm(&mut vehicle)?;
    let ignored = !await_text(&mut gcs, &mut vehicle, "Clock set", Duration::from_secs(2))?;
    assert!(ignored, "a non-owner's SYSTEM_TIME set the clock");
    assert!(
        tlog_names(&data)
            .iter()
            .all(|n| n.starts_with("neptunus-2000"))
    );

    // The station in control (255, armed) sends its time.
    let sent = now_us();
    gcs.send(&system_time(sent))?;
    let set = await_text(
        &mut gcs,
        &mut vehicle,
        "Clock set from GCS 255",
        Duration::from_secs(10),
    )?;
    assert!(
        set,
        "no 'Clock set from GCS 255' STATUSTEXT:\n{}",
        vehicle.stderr_tail()
    );
    // The next telemetry log is named with the station's time.
    let today = neptunus::eventlog::rfc3339_utc(sent);
    let stem = format!("neptunus-{}{}{}", &today[0..4], &today[5..7], &today[8..10]);
    let end = Instant::now() + Duration::from_secs(10);
    while !tlog_names(&data).iter().any(|n| n.starts_with(&stem)) {
        if Instant::now() > end {
            bail!("no tlog named {stem}…: {:?}", tlog_names(&data));
        }
        gcs.pump(Traffic::Heartbeats)?;
    }
    // And the event log: 2000 before, the station's time from the clock_set line on.
    let lines = event_lines(&data);
    let at = lines
        .iter()
        .position(|l| l["event"] == "clock_set")
        .context("no clock_set event")?;
    let year = |l: &serde_json::Value| l["time"].as_str().unwrap_or("").get(..4).map(str::to_owned);
    assert!(
        lines[..at]
            .iter()
            .all(|l| year(l).as_deref() == Some("2000")),
        "{lines:?}"
    );
    assert!(
        lines[at..]
            .iter()
            .all(|l| year(l) == Some(today[..4].to_owned())),
        "{lines:?}"
    );
    assert_eq!(lines[at]["sysid"], 255);
    let stamped = lines[at]["unix_us"].as_u64().unwrap_or(0);
    assert!(
        stamped.abs_diff(sent) < 5_000_000,
        "clock_set stamped {stamped}, sent {sent}"
    );
    Ok(())
}

fn which(name: &str) -> anyhow::Result<std::path::PathBuf> {
    std::env::var_os("PATH")
        .iter()
        .flat_map(std::env::split_paths)
        .map(|d| d.join(name))
        .find(|p| p.is_file())
        .context("not on PATH")
}
