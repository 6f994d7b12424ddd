//! mavlink-camera-manager's `GET /streams` on its REST port (6020, beside
//! the signalling on 6021), where Cockpit reads each stream's source,
//! resolution and rate for its video settings: the one stream WebRTC
//! offers, named as in the signalling's `availableStreams` (Cockpit matches
//! them by name), in mavlink-camera-manager's shape (`video_and_stream`,
//! `stream_information.configuration{encode, width, height,
//! frame_interval}`, `video_source`, `running`, `state`).
//!
//! Filled from the stream's state now: `running` and `state` from the
//! encoder (`"running"` while it encodes, `"idle"` while it waits for a
//! viewer or a ground station, as the stream starts on demand), the size
//! and rate from the RTP stream while one is announced, else from the
//! configuration. Reads only; who may ask is decided in front (the HMI's
//! Host rule; the answer carries CORS headers for the origins it admits).

use axum::Json;
use axum::Router;
use axum::extract::State;
use axum::routing::get;
use serde_json::{Value, json};
use tokio::sync::watch;

use super::protocol::Stream;
use crate::camera::rtp::RtpStream;

/// What `/streams` reads.
#[derive(Clone)]
pub struct StreamsState {
    pub stream: Option<Stream>,
    /// The RTP stream announced to ground stations (its true size and rate).
    pub rtp: watch::Receiver<Option<RtpStream>>,
    /// What sends the H.264 while it runs (the encoder, or a camera's own
    /// stream copied or relayed).
    pub sender: watch::Receiver<Option<crate::camera::rtp::Running>>,
}

/// The routes of the REST port.
pub fn routes(state: StreamsState) -> Router {
    Router::new()
        .route("/streams", get(streams))
        .with_state(state)
}

async fn streams(State(s): State<StreamsState>) -> Json<Value> {
    let running = s.sender.borrow().is_some();
    let rtp = s.rtp.borrow().clone();
    Json(Value::Array(
        s.stream
            .iter()
            .map(|st| describe(st, running, rtp.as_ref()))
            .collect(),
    ))
}

/// One stream in mavlink-camera-manager's shape.
pub fn describe(st: &Stream, running: bool, rtp: Option<&RtpStream>) -> Value {
    let (width, height, fps) = match rtp {
        Some(r) => (
            Some(u32::from(r.width)),
            Some(u32::from(r.height)),
            Some(f64::from(r.fps)),
        ),
        None => (
            st.width,
            st.height,
            st.interval
                .as_deref()
                .and_then(|i| i.strip_prefix("1/"))
                .and_then(|d| d.parse::<f64>().ok()),
        ),
    };
    let frame_interval = fps
        .filter(|f| *f > 0.0)
        .map(|f| json!({ "numerator": 1, "denominator": f.round() as u32 }));
    let source = st.source.clone().unwrap_or_else(|| "camera".to_owned());
    json!({
        "id": st.id,
        "running": running,
        "state": if running { "running" } else { "idle" },
        "error": null,
        "video_and_stream": {
            "name": st.name,
            "stream_information": {
                "endpoints": rtp.map(|r| vec![r.uri.clone()]).unwrap_or_default(),
                "configuration": {
                    "type": "video",
                    "encode": st.encode,
                    "width": width,
                    "height": height,
                    "frame_interval": frame_interval,
                },
                "extended_configuration": null,
            },
            // Cockpit shows the name; it looks for an rtsp:// among the
            // source's values (strings only).
            "video_source": {
                "Neptunus": {
                    "name": format!("Neptunus {source} camera"),
                    "source": { "kind": source },
                },
            },
        },
        "mavlink": null,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stream() -> Stream {
        Stream {
            id: "6c3e".into(),
            name: "Neptunus camera".into(),
            encode: Some("H264".into()),
            height: Some(480),
            width: Some(640),
            interval: Some("1/30".into()),
            source: Some("synthetic".into()),
            created: None,
        }
    }

    #[test]
    fn cockpits_fields_from_the_configuration_and_from_the_running_stream() {
        let v = describe(&stream(), false, None);
        let vs = &v["video_and_stream"];
        assert_eq!(vs["name"], "Neptunus camera");
        let c = &vs["stream_information"]["configuration"];
        assert_eq!(
            (
                c["encode"].as_str(),
                c["width"].as_u64(),
                c["height"].as_u64()
            ),
            (Some("H264"), Some(640), Some(480))
        );
        assert_eq!(
            c["frame_interval"],
            json!({"numerator": 1, "denominator": 30})
        );
        assert_eq!(
            (v["running"].as_bool(), v["state"].as_str()),
            (Some(false), Some("idle"))
        );
        assert_eq!(
            vs["video_source"]["Neptunus"]["name"],
            "Neptunus synthetic camera"
        );
        let rtp = RtpStream {
            uri: "udp://192.168.254.2:5600".into(),
            width: 800,
            height: 600,
            fps: 15.0,
            bitrate_kbps: 1500,
        };
        let v = describe(&stream(), true, Some(&rtp));
        let c = &v["video_and_stream"]["stream_information"]["configuration"];
        assert_eq!(
            (c["width"].as_u64(), c["height"].as_u64()),
            (Some(800), Some(600))
        );
        assert_eq!(c["frame_interval"]["denominator"], 15);
        assert_eq!(v["state"], "running");
        assert_eq!(
            v["video_and_stream"]["stream_information"]["endpoints"][0],
            "udp://192.168.254.2:5600"
        );
    }
}
