//! Configuration: the README's example parses, precedence holds, bad input is refused clearly.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use clap::Parser;
use neptunus::config::{BoardSource, Cli, FileConfig, resolve};

fn readme_example() -> String {
    let readme =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/README.md")).unwrap();
    let start = readme
        .find("```toml\nsim = false")
        .expect("README has the example config");
    let body = &readme[start + "```toml\n".len()..];
    body[..body.find("```").unwrap()].to_owned()
}

#[test]
fn readme_example_config_parses() {
    let cfg = FileConfig::parse(&readme_example()).unwrap();
    assert_eq!(cfg.emulator.wiring_directions, [-1, 1, 1]);
    assert_eq!(cfg.mavlink.endpoints.as_ref().unwrap().len(), 2);
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
