//! Fuzzes the browser HMI's WebSocket messages (JSON from the page).
//!
//! Any text: never a panic; an error says what was wrong; a message that
//! parses passes its own checks, carries only finite numbers in the ranges
//! the protocol gives, and written back as JSON parses to itself.
#![no_main]

use libfuzzer_sys::fuzz_target;
use neptunus::hmi::auth::MAX_PASSWORD_BYTES;
use neptunus::hmi::protocol::{ClientMsg, HMI_MODES};

fn within(v: f64, lo: f64, hi: f64) -> bool {
    v.is_finite() && (lo..=hi).contains(&v)
}

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    let msg = match ClientMsg::parse(&text) {
        Ok(m) => m,
        Err(e) => {
            assert!(!e.is_empty());
            return;
        }
    };
    assert_eq!(msg.validate(), Ok(()));
    let ok = match &msg {
        ClientMsg::Sticks {
            surge,
            sway,
            heave_up,
            yaw,
        } => [surge, sway, heave_up, yaw]
            .iter()
            .all(|&&v| within(v, -1.0, 1.0)),
        ClientMsg::Thrusters {
            port,
            vertical,
            starboard,
        } => [port, vertical, starboard]
            .iter()
            .all(|&&v| within(v, -1.0, 1.0)),
        ClientMsg::Mode { mode } => HMI_MODES.iter().any(|(m, _)| m.number() == *mode),
        ClientMsg::AutopilotTarget {
            depth_m,
            heading_deg,
        } => {
            (depth_m.is_some() || heading_deg.is_some())
                && depth_m.is_none_or(|d| within(d, 0.0, 1000.0))
                && heading_deg.is_none_or(|h| within(h, 0.0, 360.0))
        }
        ClientMsg::Gain { value } => within(*value, 0.0, 1.0),
        ClientMsg::Lights { level } => within(*level, 0.0, 255.0),
        ClientMsg::Tilt { deg } => within(*deg, -90.0, 90.0),
        ClientMsg::Login { password } => password.len() <= MAX_PASSWORD_BYTES,
        _ => true,
    };
    assert!(ok, "accepted out of range: {msg:?}");
    let again = serde_json::to_string(&msg).expect("a message serialises");
    assert_eq!(ClientMsg::parse(&again), Ok(msg), "{again}");
});
