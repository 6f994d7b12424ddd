//! Configuration: the user guide's example parses, precedence holds, bad input is refused clearly.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use clap::Parser;
use neptunus::config::{BoardSource, Cli, FileConfig, resolve};
use neptunus::sim::{ModelKind, NoiseOptions, SimOptions, TetherOptions};

/// The example configuration of the guide's "Running and configuration".
fn guide_example() -> String {
    let page = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/docs/guide/src/running.md"
    ))
    .unwrap();
    let start = page
        .find("```toml\nsim = false")
        .expect("docs/guide/src/running.md has the example config");
    let body = &page[start + "```toml\n".len()..];
    body[..body.find("```").unwrap()].to_owned()
}

#[test]
fn the_guides_example_config_parses() {
    let cfg = FileConfig::parse(&guide_example()).unwrap();
    assert_eq!(cfg.emulator.wiring_directions, [-1, 1, 1]);
    assert_eq!(cfg.mavlink.endpoints.as_ref().unwrap().len(), 2);
    // The guide documents the simulator's defaults: they must be the defaults.
    assert_eq!(cfg.emulator.sim, SimOptions::default());
}

#[test]
fn flags_override_file_override_defaults() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("n.toml");
    std::fs::write(&path, "sim = true\n[board]\nbaud = 57600\n[mavlink]\nendpoints = [\"udpin:127.0.0.1:14551\"]\nidentity = \"generic\"\n").unwrap();
    let cli = Cli::parse_from([
        "neptunus",
        "--config",
        path.to_str().unwrap(),
        "--baud",
        "9600",
        "--data-dir",
        "/tmp/x",
    ]);
    let s = resolve(&cli.run).unwrap();
    assert_eq!(s.link.baud, 9600, "flag wins");
    assert!(
        matches!(s.board, BoardSource::Simulated(_)),
        "file sets sim"
    );
    assert_eq!(s.mavlink.endpoints.len(), 1);
    assert_eq!(
        s.mavlink.identity,
        neptunus::vehicle::machine::Identity::Generic
    );
    let cli = Cli::parse_from([
        "neptunus",
        "--config",
        path.to_str().unwrap(),
        "--serial",
        "/dev/ttyUSB0",
        "--mavlink",
        "tcpin:127.0.0.1:0",
    ]);
    let s = resolve(&cli.run).unwrap();
    assert!(
        matches!(s.board, BoardSource::Serial),
        "--serial wins over sim in the file"
    );
    assert_eq!(s.link.baud, 57600, "file over default");
    assert_eq!(s.mavlink.endpoints[0].to_string(), "tcpin:127.0.0.1:0");
}

#[test]
fn defaults_are_the_documented_endpoints() {
    let cli = Cli::parse_from(["neptunus", "--sim", "--data-dir", "/tmp/x"]);
    let s = resolve(&cli.run).unwrap();
    let urls: Vec<String> = s
        .mavlink
        .endpoints
        .iter()
        .map(ToString::to_string)
        .collect();
    assert_eq!(urls, ["udpout:127.0.0.1:14550", "tcpin:0.0.0.0:5760"]);
}

#[test]
fn bad_values_are_refused_with_the_key() {
    for (text, needle) in [
        ("[emulator.faults]\nwild = 2.0\n", "wild"),
        ("[board]\nbaud = 0\n", "baud"),
        ("[mavlink]\nendpoints = [\"udpon:1.2.3.4:5\"]\n", "udpon"),
        ("[mavlink]\nsysid = 300\n", "sysid"),
        ("[mavlink]\nbogus = 1\n", "bogus"),
        ("[mavlink]\npeer_timeout_s = 1e300\n", "peer_timeout_s"),
        ("[hmi]\nopen_control = \"everyone\"\n", "open_control"),
        (
            "[hmi]\nallowed_origins = [\"topside.local\"]\n",
            "allowed_origins",
        ),
        (
            "[hmi]\nallowed_origins = [\"http://x/path\"]\n",
            "scheme://host[:port]",
        ),
        ("[hmi]\nmax_watchers = 5000\n", "max_watchers"),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("n.toml");
        std::fs::write(&path, text).unwrap();
        let cli = Cli::parse_from([
            "neptunus",
            "--sim",
            "--config",
            path.to_str().unwrap(),
            "--data-dir",
            "/tmp/x",
        ]);
        let err = resolve(&cli.run).map(|_| ()).unwrap_err().to_string();
        assert!(err.contains(needle), "{text:?} → {err}");
    }
}

#[test]
fn emulator_sim_table_parses() {
    let cfg = FileConfig::parse(
        "[emulator.sim]\nmodel = \"thesis-4dof\"\nthruster_rise_time_s = 0.1\nreverse_thrust_ratio = 0.6\n\
         depth_update_hz = 0.0\nwild_rate = 0.01\nseed = 7\n\
         [emulator.sim.tether]\nenabled = false\nmin_length_m = 30.0\n\
         [emulator.sim.current]\nspeed_mps = 0.2\ndirection_deg = 90.0\n\
         [emulator.sim.noise]\nheading_std_deg = 0.5\ndepth_bias_m = 0.0\n",
    )
    .unwrap();
    let sim = &cfg.emulator.sim;
    assert_eq!(sim.model, ModelKind::Thesis4Dof);
    assert_eq!(sim.thruster_rise_time_s, 0.1);
    assert_eq!(sim.reverse_thrust_ratio, 0.6);
    assert_eq!(sim.seed, 7);
    assert!(!sim.tether.enabled);
    assert_eq!(sim.tether.min_length_m, 30.0);
    assert_eq!(sim.tether.diameter_m, TetherOptions::default().diameter_m);
    assert_eq!(sim.current.direction_deg, 90.0);
    assert_eq!(sim.noise.heading_std_deg, 0.5);
    assert_eq!(
        sim.noise.roll_bias_deg,
        NoiseOptions::default().roll_bias_deg
    );
    // No table: the realistic defaults.
    let cfg = FileConfig::parse("").unwrap();
    assert_eq!(cfg.emulator.sim, SimOptions::default());
    assert_eq!(cfg.emulator.sim.model, ModelKind::SixDof);
    assert!(FileConfig::parse("[emulator.sim]\nmodel = \"six-dof\"\n").is_ok());
}

#[test]
fn emulator_sim_bad_values_name_the_key_the_value_and_the_fix() {
    for (text, needles) in [
        (
            "[emulator.sim]\nthruster_rise_time_s = 1.5\n",
            &["emulator.sim.thruster_rise_time_s", "1.5", "0..1 s"][..],
        ),
        (
            "[emulator.sim]\nthruster_rise_time_s = -0.1\n",
            &["thruster_rise_time_s", "-0.1"],
        ),
        (
            "[emulator.sim]\nreverse_thrust_ratio = 0.0\n",
            &["emulator.sim.reverse_thrust_ratio", "= 0", "(0, 1]"],
        ),
        (
            "[emulator.sim]\nreverse_thrust_ratio = nan\n",
            &["reverse_thrust_ratio", "NaN"],
        ),
        (
            "[emulator.sim]\nwild_rate = 1.2\n",
            &["emulator.sim.wild_rate", "1.2", "probability"],
        ),
        (
            "[emulator.sim]\ndepth_update_hz = -1.0\n",
            &["emulator.sim.depth_update_hz", "-1"],
        ),
        (
            "[emulator.sim.tether]\ndiameter_m = -0.003\n",
            &["emulator.sim.tether.diameter_m", "-0.003", "diameter"],
        ),
        (
            "[emulator.sim.tether]\nmin_length_m = inf\n",
            &["emulator.sim.tether.min_length_m", "inf"],
        ),
        (
            "[emulator.sim.current]\nspeed_mps = nan\n",
            &["emulator.sim.current.speed_mps", "NaN"],
        ),
        (
            "[emulator.sim.noise]\nheading_std_deg = -1.0\n",
            &[
                "emulator.sim.noise.heading_std_deg",
                "-1",
                "standard deviation",
            ],
        ),
        (
            "[emulator.sim.noise]\ndepth_std_m = 20.0\n",
            &["emulator.sim.noise.depth_std_m", "20"],
        ),
        ("[emulator.sim]\nbogus = 1\n", &["bogus"]),
        ("[emulator.sim.tether]\nlength_m = 3.0\n", &["length_m"]),
        (
            "[emulator.sim.noise]\nyaw_std_deg = 1.0\n",
            &["yaw_std_deg"],
        ),
        (
            "[emulator.sim]\nmodel = \"7dof\"\n",
            &["7dof", "six-dof", "thesis-4dof"],
        ),
        (
            "[emulator.sim]\nthruster_rise_time_s = \"fast\"\n",
            &["thruster_rise_time_s"],
        ),
    ] {
        let err = FileConfig::parse(text).map(|_| ()).unwrap_err();
        for needle in needles {
            assert!(err.contains(needle), "{text:?} → {err} (wanted {needle:?})");
        }
    }
}

#[test]
fn emulator_sim_errors_reach_the_user_through_resolve() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("n.toml");
    std::fs::write(&path, "[emulator.sim]\nwild_rate = 2.0\n").unwrap();
    let cli = Cli::parse_from([
        "neptunus",
        "--sim",
        "--config",
        path.to_str().unwrap(),
        "--data-dir",
        "/tmp/x",
    ]);
    let err = resolve(&cli.run).map(|_| ()).unwrap_err().to_string();
    assert!(
        err.contains("n.toml") && err.contains("emulator.sim.wild_rate = 2"),
        "{err}"
    );
}

/// The pilot password left the config file: the old key says where it is
/// and what to do instead.
#[test]
fn pilot_password_key_says_how_to_set_the_password() {
    let err = FileConfig::parse("[hmi]\nsysid_min = 200\npilot_password = \"tide-pool-42\"\n")
        .unwrap_err();
    assert!(err.contains("line 3, column 18"), "{err}");
    assert!(err.contains("hmi.pilot_password"), "{err}");
    assert!(err.contains("neptunus hmi set-password"), "{err}");
    assert!(
        !err.contains("tide-pool-42"),
        "the error repeats the password: {err}"
    );
}

#[test]
fn hmi_access_keys_resolve() {
    use neptunus::hmi::auth::OpenControl;
    let cfg = FileConfig::parse(
        "[hmi]\nopen_control = \"private\"\nallowed_origins = [\"HTTPS://Topside.local:8443/\"]\nmax_watchers = 4\n",
    )
    .unwrap();
    assert_eq!(cfg.hmi.open_control, Some(OpenControl::Private));
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("n.toml");
    std::fs::write(&path, toml::to_string(&cfg).unwrap()).unwrap();
    let cli = Cli::parse_from(["neptunus", "--sim", "--config", path.to_str().unwrap()]);
    let s = resolve(&cli.run).unwrap();
    assert_eq!(s.hmi.open_control, OpenControl::Private);
    assert_eq!(s.hmi.allowed_origins, ["https://topside.local:8443"]);
    assert_eq!(s.hmi.max_watchers, 4);
    // The defaults: on the vehicle every browser logs in; in a simulation
    // a browser on the same machine may pilot; 32 watchers.
    let s = resolve(&Cli::parse_from(["neptunus", "--data-dir", "/tmp/x"]).run).unwrap();
    assert_eq!(s.hmi.open_control, OpenControl::None);
    let s = resolve(&Cli::parse_from(["neptunus", "--sim", "--data-dir", "/tmp/x"]).run).unwrap();
    assert_eq!(s.hmi.open_control, OpenControl::Loopback);
    assert_eq!(s.hmi.max_watchers, 32);
    assert!(s.hmi.allowed_origins.is_empty());
}

/// `[hmi]` transport keys: the defaults, the guide's values, and refusals
/// that name the key, the value and the fix.
#[test]
fn hmi_transport_keys_resolve_and_bad_ones_name_the_key() {
    use neptunus::hmi::tls::TlsMode;
    let resolve_text = |text: &str, extra: &[&str]| {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("n.toml");
        std::fs::write(&path, text).unwrap();
        let mut args = vec![
            "neptunus",
            "--sim",
            "--config",
            path.to_str().unwrap(),
            "--data-dir",
            "/tmp/x",
        ];
        args.extend_from_slice(extra);
        resolve(&Cli::parse_from(args).run).map(|s| s.hmi)
    };
    let d = resolve_text("", &[]).unwrap();
    assert_eq!(d.limits.max_connections, 128);
    assert_eq!(d.limits.max_connections_per_address, 32);
    assert_eq!(d.limits.header_timeout, std::time::Duration::from_secs(10));
    assert_eq!(d.tls.mode, TlsMode::Off, "TLS is off by default");
    let s = resolve_text(
        "[hmi]\nmax_connections = 10\nmax_connections_per_address = 4\nheader_timeout_s = 2.5\ntls = \"self-signed\"\ntls_names = [\"rov.local\", \"192.168.2.2\"]\n",
        &[],
    )
    .unwrap();
    assert_eq!(s.limits.max_connections, 10);
    assert_eq!(s.limits.max_connections_per_address, 4);
    assert_eq!(s.limits.header_timeout.as_millis(), 2500);
    assert_eq!(s.tls.mode, TlsMode::SelfSigned);
    assert_eq!(s.tls.names, ["rov.local", "192.168.2.2"]);
    // The flag wins over the file.
    let s = resolve_text("[hmi]\ntls = \"self-signed\"\n", &["--tls", "off"]).unwrap();
    assert_eq!(s.tls.mode, TlsMode::Off);
    for (text, needle) in [
        ("[hmi]\nmax_connections = 0\n", "hmi.max_connections = 0"),
        (
            "[hmi]\nmax_connections = 10\nmax_connections_per_address = 11\n",
            "hmi.max_connections_per_address = 11",
        ),
        (
            "[hmi]\nheader_timeout_s = 0.0\n",
            "hmi.header_timeout_s = 0",
        ),
        ("[hmi]\nheader_timeout_s = nan\n", "hmi.header_timeout_s"),
        ("[hmi]\ntls = \"on\"\n", "tls"),
        ("[hmi]\ntls = \"files\"\n", "tls_cert"),
        ("[hmi]\ntls_cert = \"/x.pem\"\n", "tls = \"files\""),
        ("[hmi]\ntls_names = [\"bad name\"]\n", "bad name"),
    ] {
        let err = resolve_text(text, &[]).map(|_| ()).unwrap_err().to_string();
        assert!(err.contains(needle), "{text:?} → {err}");
    }
}

#[test]
fn the_emulated_firmware_sets_the_framing_unless_told() {
    use neptunus::config::{CliCommand, resolve_emulator};
    use neptunus::firmware::codec::Framing;
    use neptunus::firmware::emulator::FirmwareVersion;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("n.toml");
    std::fs::write(&path, "sim = true\n[emulator]\nfirmware = \"2014-12\"\n").unwrap();
    let file = path.to_str().unwrap();
    // --sim: the link speaks the emulated firmware's framing…
    let s = resolve(&Cli::parse_from(["neptunus", "--config", file]).run).unwrap();
    assert_eq!(s.link.framing, Framing::Plain);
    let BoardSource::Simulated(emu) = s.board else {
        panic!("file sets sim")
    };
    assert_eq!(emu.imitated(), FirmwareVersion::V2014_12);
    // …and asking for crc8 from a firmware without a CRC check is refused.
    let err = resolve(&Cli::parse_from(["neptunus", "--config", file, "--framing", "crc8"]).run)
        .unwrap_err()
        .to_string();
    assert!(err.contains("2014-12") && err.contains("plain"), "{err}");
    // The default firmware, plain framing asked: the 2014-12 board.
    let s = resolve(&Cli::parse_from(["neptunus", "--sim", "--framing", "plain"]).run).unwrap();
    let BoardSource::Simulated(emu) = s.board else {
        panic!("--sim")
    };
    assert_eq!(emu.imitated(), FirmwareVersion::V2014_12);

    // emulate-board --firmware
    let emulate = |args: &[&str]| {
        let cli = Cli::parse_from(["neptunus", "emulate-board"].iter().chain(args));
        let Some(CliCommand::EmulateBoard(a)) = cli.command else {
            panic!("emulate-board")
        };
        resolve_emulator(&a, None)
    };
    let emu = emulate(&["--firmware", "2014-12"]).unwrap();
    assert_eq!(
        (emu.imitated(), emu.effective_framing()),
        (FirmwareVersion::V2014_12, Framing::Plain)
    );
    let emu = emulate(&[]).unwrap();
    assert_eq!(emu.imitated(), FirmwareVersion::V30_0_2);
    assert!(emulate(&["--firmware", "2014-12", "--framing", "crc8"]).is_err());
    let err = Cli::try_parse_from(["neptunus", "emulate-board", "--firmware", "30.0.3"])
        .unwrap_err()
        .to_string();
    assert!(err.contains("30.0.2") && err.contains("2014-12"), "{err}");
}

#[test]
fn webrtc_keys_and_flags_resolve_and_bad_ones_name_the_key() {
    use neptunus::camera::webrtc::SignallingAddr;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("n.toml");
    std::fs::write(
        &path,
        "[camera]\nsource = \"synthetic\"\n[camera.webrtc]\nsignalling = \"off\"\nudp_port = 50000\nmax_viewers = 2\nice_servers = [{ url = \"turn:turn.example.org\", username = \"rov\", credential = \"s\" }]\n",
    )
    .unwrap();
    let file = |extra: &[&str]| {
        let mut args = vec!["neptunus", "--sim", "--config", path.to_str().unwrap()];
        args.extend_from_slice(extra);
        resolve(&Cli::parse_from(args).run).unwrap().camera.webrtc
    };
    let w = file(&[]);
    assert!(w.enabled, "on unless turned off");
    assert_eq!(w.signalling, Some(SignallingAddr::Off));
    assert_eq!((w.udp_port, w.max_viewers), (50000, 2));
    assert_eq!(w.ice_servers[0].username.as_deref(), Some("rov"));
    // Flags over the file; --video-rtp off leaves WebRTC alone.
    let w = file(&[
        "--webrtc-signalling",
        "127.0.0.1:0",
        "--ice-server",
        "stun:stun.example.org:3478",
        "--video-rtp",
        "off",
    ]);
    assert!(w.enabled);
    assert_eq!(
        w.signalling,
        Some(SignallingAddr::At("127.0.0.1:0".parse().unwrap()))
    );
    assert_eq!(w.ice_servers.len(), 1);
    assert!(w.ice_servers[0].is_stun());
    assert!(!file(&["--webrtc", "off"]).enabled);
    // Unset: port 6021 on the HMI's address.
    let s =
        resolve(&Cli::parse_from(["neptunus", "--sim", "--http", "127.0.0.1:8081"]).run).unwrap();
    assert_eq!(s.camera.webrtc.signalling, None);
    assert_eq!(
        SignallingAddr::resolve(s.camera.webrtc.signalling, s.hmi.http),
        Some("127.0.0.1:6021".parse().unwrap())
    );
    for (text, needle) in [
        (
            "[camera.webrtc]\nmax_viewers = 0\n",
            "camera.webrtc.max_viewers",
        ),
        (
            "[camera.webrtc]\nice_servers = [{ url = \"http://x\" }]\n",
            "stun:HOST",
        ),
        ("[camera.webrtc]\nsignalling = \"6021\"\n", "HOST:PORT"),
        ("[camera.webrtc]\nstun = []\n", "stun"),
    ] {
        std::fs::write(&path, text).unwrap();
        let cli = Cli::parse_from(["neptunus", "--sim", "--config", path.to_str().unwrap()]);
        let err = resolve(&cli.run).map(|_| ()).unwrap_err().to_string();
        assert!(err.contains(needle), "{text:?} → {err}");
    }
    for bad in [
        ["--webrtc", "maybe"],
        ["--webrtc-signalling", "here"],
        ["--ice-server", "ftp://x"],
    ] {
        let mut args = vec!["neptunus"];
        args.extend_from_slice(&bad);
        assert!(Cli::try_parse_from(args).is_err(), "{bad:?}");
    }
}
