//! Fuzzes what the operator writes (the configuration file and the values
//! of the command line's flags): not network input, but a mistake in it
//! must be an error that says what is wrong, never a panic.
//!
//! The input as a whole configuration file, and cut at newlines into the
//! values of `--video-rtp`, `--ice-server`, `--webrtc-signalling` and an
//! allowed origin: never a panic; a value that parses and can be written
//! back reads back the same; an ICE server's parts are a known scheme, a
//! plain host name and a port.
#![no_main]

use libfuzzer_sys::fuzz_target;
use neptunus::camera::rtp::RtpDest;
use neptunus::camera::webrtc::{IceServer, SignallingAddr};
use neptunus::config::FileConfig;
use neptunus::hmi::auth::parse_origin;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    if let Err(e) = FileConfig::parse(&text) {
        assert!(!e.is_empty());
    }
    for value in text.split('\n') {
        if let Ok(d) = value.parse::<RtpDest>() {
            assert_eq!(d.to_string().parse::<RtpDest>(), Ok(d));
        }
        if let Ok(s) = value.parse::<IceServer>() {
            let (scheme, host, port) = s.parts().expect("a parsed server has parts");
            assert!(matches!(scheme, "stun" | "turn" | "turns"));
            assert!(!host.is_empty() && port > 0);
            assert!(
                host.chars()
                    .all(|c| c.is_ascii_alphanumeric() || ".-:_".contains(c))
            );
            assert_eq!(s.url.parse::<IceServer>(), Ok(s.clone()));
        }
        if let Ok(a) = value.parse::<SignallingAddr>() {
            assert_eq!(a.to_string().parse::<SignallingAddr>(), Ok(a));
        }
        if let Ok(o) = parse_origin(value) {
            assert_eq!(parse_origin(&o), Ok(o.clone()));
        }
    }
});
