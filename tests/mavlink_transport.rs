//! MAVLink transport: framing (round trips, noisy chunked streams, bad CRCs,
//! datagrams, fuzzing), endpoint URLs, the router over real sockets on
//! 127.0.0.1 port 0 (udpin, udpout, tcpin, tcpout, serial over a pty),
//! per-endpoint malformed-input counters, and the telemetry log.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use mavlink_core::{MAVLinkV1MessageRaw, MavHeader, MavlinkVersion};
use neptunus::dialect::neptunus::{
    COMMAND_LONG_DATA, FILE_TRANSFER_PROTOCOL_DATA, HEARTBEAT_DATA, MANUAL_CONTROL_DATA,
    MavAutopilot, MavCmd, MavModeFlag, MavParamType, MavState, MavType, PARAM_VALUE_DATA,
    SETUP_SIGNING_DATA,
};
use neptunus::firmware::pty::PtyPair;
use neptunus::mavlink::endpoint::MAX_PEERS;
use neptunus::mavlink::{
    EndpointError, EndpointSpec, EndpointStats, Frame, FrameDecoder, FrameStats, Inbound,
    MavMessage, Outbound, Route, Router, RouterConfig, RouterHandle, TlogConfig, TlogWriter,
    decode_datagram, encode_v2,
};
use proptest::prelude::*;
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpSocket, TcpStream, UdpSocket};
use tokio::sync::mpsc;
use tokio::time::timeout;

const WAIT: Duration = Duration::from_secs(10);

// ---------------------------------------------------------------------------
// messages and helpers
// ---------------------------------------------------------------------------

fn heartbeat(custom_mode: u32) -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode,
        mavtype: MavType::MAV_TYPE_SUBMARINE,
        autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            | MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED,
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

fn command_long(p1: f32) -> MavMessage {
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        param1: p1,
        param2: 21196.0,
        param3: 0.0,
        // MAVSDK sends unused parameters as NaN.
        param4: f32::NAN,
        param5: -1.5,
        param6: 1e9,
        param7: 0.25,
        command: MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        target_system: 1,
        target_component: 0,
        confirmation: 2,
    })
}

fn param_value(index: u16, value: f32) -> MavMessage {
    MavMessage::PARAM_VALUE(PARAM_VALUE_DATA {
        param_value: value,
        param_count: 300,
        param_index: index,
        param_id: "PILOT_GAIN_MAX".into(),
        param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
    })
}

fn manual_control(x: i16, buttons2: u16) -> MavMessage {
    MavMessage::MANUAL_CONTROL(MANUAL_CONTROL_DATA {
        x,
        y: -200,
        z: 500,
        r: 1000,
        buttons: 0x8001,
        target: 1,
        buttons2,
        enabled_extensions: 0b11,
        s: -321,
        t: 123,
        aux1: 1,
        aux2: -2,
        aux3: 3,
        aux4: -4,
        aux5: 5,
        aux6: -6,
    })
}

fn big_message(tag: u32) -> MavMessage {
    let mut payload = [0x5Au8; 251];
    payload[..4].copy_from_slice(&tag.to_le_bytes());
    MavMessage::FILE_TRANSFER_PROTOCOL(FILE_TRANSFER_PROTOCOL_DATA {
        target_network: 0,
        target_system: 255,
        target_component: 190,
        payload,
    })
}

fn setup_signing(key: [u8; 32]) -> MavMessage {
    MavMessage::SETUP_SIGNING(SETUP_SIGNING_DATA {
        initial_timestamp: 0x0102_0304_0506,
        target_system: 1,
        target_component: 1,
        secret_key: key,
    })
}

fn encode_v1(sysid: u8, compid: u8, seq: u8, msg: &MavMessage) -> Vec<u8> {
    let mut raw = MAVLinkV1MessageRaw::new();
    raw.serialize_message(
        MavHeader {
            system_id: u32::from(sysid),
            component_id: compid,
            sequence: seq,
        },
        msg,
    );
    raw.raw_bytes().to_vec()
}

fn decode_all(bytes: &[u8]) -> (Vec<Frame>, FrameStats) {
    let mut decoder = FrameDecoder::new();
    let mut out = Vec::new();
    decoder.push(bytes, &mut out);
    (out, decoder.stats().clone())
}

fn out_all(bytes: Vec<u8>) -> Outbound {
    Outbound {
        route: Route::All,
        bytes: Arc::from(bytes),
    }
}

fn out_to(route: Route, bytes: Vec<u8>) -> Outbound {
    Outbound {
        route,
        bytes: Arc::from(bytes),
    }
}

async fn start(specs: &[&str], cfg: RouterConfig) -> (RouterHandle, mpsc::Receiver<Inbound>) {
    let specs = specs.iter().map(|s| s.parse().unwrap()).collect();
    let (tx, rx) = mpsc::channel(4096);
    let handle = Router::start(specs, cfg, tx).await.unwrap();
    (handle, rx)
}

async fn next_inbound(rx: &mut mpsc::Receiver<Inbound>) -> Inbound {
    timeout(WAIT, rx.recv())
        .await
        .expect("no inbound frame in time")
        .expect("inbound channel closed")
}

/// Polls the router's counters until `pred` holds (the router's state is
/// only observable through them).
async fn wait_stats(handle: &RouterHandle, what: &str, pred: impl Fn(&[EndpointStats]) -> bool) {
    let polled = timeout(WAIT, async {
        loop {
            if pred(&handle.stats()) {
                return;
            }
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
    })
    .await;
    assert!(
        polled.is_ok(),
        "timed out waiting for {what}: {:#?}",
        handle.stats()
    );
}

/// A station's UDP socket that hands out the vehicle's frames one at a time
/// (a datagram may carry several, as ArduPilot's do).
struct UdpClient {
    socket: UdpSocket,
    pending: std::sync::Mutex<std::collections::VecDeque<(Frame, SocketAddr)>>,
}

impl std::ops::Deref for UdpClient {
    type Target = UdpSocket;
    fn deref(&self) -> &UdpSocket {
        &self.socket
    }
}

async fn udp_client() -> UdpClient {
    UdpClient {
        socket: UdpSocket::bind("127.0.0.1:0").await.unwrap(),
        pending: std::sync::Mutex::default(),
    }
}

async fn udp_next_frame(client: &UdpClient) -> (Frame, SocketAddr) {
    if let Some(next) = client.pending.lock().unwrap().pop_front() {
        return next;
    }
    let mut buf = vec![0u8; 2048];
    let (n, from) = timeout(WAIT, client.socket.recv_from(&mut buf))
        .await
        .expect("no datagram in time")
        .unwrap();
    let mut stats = FrameStats::default();
    let mut frames = Vec::new();
    decode_datagram(&buf[..n], &mut stats, &mut frames);
    assert!(
        !frames.is_empty()
            && stats.bad_crc == 0
            && stats.bad_payload == 0
            && stats.garbage_bytes == 0,
        "whole frames in a datagram: {stats:?}"
    );
    let mut frames = frames.into_iter().map(|f| (f, from));
    let first = frames.next().unwrap();
    client.pending.lock().unwrap().extend(frames);
    first
}

/// Reads a byte stream into frames, one at a time.
struct StreamReader {
    decoder: FrameDecoder,
    pending: std::collections::VecDeque<Frame>,
}

impl StreamReader {
    fn new() -> Self {
        Self {
            decoder: FrameDecoder::new(),
            pending: Default::default(),
        }
    }

    async fn next<R: AsyncReadExt + Unpin>(&mut self, r: &mut R) -> Frame {
        timeout(WAIT, async {
            loop {
                if let Some(f) = self.pending.pop_front() {
                    return f;
                }
                let mut buf = [0u8; 4096];
                let n = r.read(&mut buf).await.unwrap();
                assert!(n > 0, "stream closed");
                let mut out = Vec::new();
                self.decoder.push(&buf[..n], &mut out);
                self.pending.extend(out);
            }
        })
        .await
        .expect("no frame on the stream in time")
    }
}

// ---------------------------------------------------------------------------
// 1. framing
// ---------------------------------------------------------------------------

#[test]
fn frame_round_trip_of_common_messages() {
    let msgs = [
        heartbeat(19),
        command_long(1.0),
        param_value(7, 0.75),
        manual_control(-1000, 0xBEEF),
    ];
    for (i, msg) in msgs.iter().enumerate() {
        let seq = i as u8 * 50;
        let bytes = encode_v2(255, 190, seq, msg);
        assert_eq!(bytes[0], 0xFD);
        let (frames, stats) = decode_all(&bytes);
        assert_eq!(frames.len(), 1, "{msg:?}: {stats:?}");
        let f = &frames[0];
        assert_eq!(f.version, MavlinkVersion::V2);
        assert_eq!((f.sysid, f.compid, f.seq), (255, 190, seq));
        assert_eq!(f.msg_id, mavlink_core::Message::message_id(msg));
        assert!(!f.signed);
        assert_eq!(f.raw, bytes);
        // NaN != NaN, so compare the re-encoding instead of the values.
        assert_eq!(encode_v2(255, 190, seq, &f.msg), bytes);
        if !matches!(msg, MavMessage::COMMAND_LONG(_)) {
            assert_eq!(&f.msg, msg);
        }
    }
    // The MANUAL_CONTROL extension fields survive the trip.
    let (frames, _) = decode_all(&encode_v2(1, 1, 0, &manual_control(5, 0xBEEF)));
    let MavMessage::MANUAL_CONTROL(mc) = &frames[0].msg else {
        panic!("not MANUAL_CONTROL")
    };
    assert_eq!((mc.buttons2, mc.s, mc.t, mc.aux6), (0xBEEF, -321, 123, -6));
}

#[test]
fn frame_mavlink1_input_is_accepted() {
    let bytes = encode_v1(255, 0, 9, &command_long(1.0));
    assert_eq!(bytes[0], 0xFE);
    let (frames, stats) = decode_all(&bytes);
    assert_eq!(frames.len(), 1);
    assert_eq!(frames[0].version, MavlinkVersion::V1);
    assert_eq!(
        (frames[0].sysid, frames[0].compid, frames[0].seq),
        (255, 0, 9)
    );
    assert_eq!(stats.v1_frames, 1);
}

fn random_message(rng: &mut SmallRng) -> MavMessage {
    match rng.random_range(0..4) {
        0 => heartbeat(rng.random()),
        1 => command_long(rng.random_range(-1.0..1.0)),
        2 => param_value(rng.random(), rng.random_range(-1e6..1e6)),
        _ => manual_control(rng.random(), rng.random()),
    }
}

#[test]
fn frame_noisy_stream_in_random_chunks_decodes_every_frame() {
    for seed in 0..8u64 {
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut stream = Vec::new();
        let mut expected = Vec::new();
        let mut v1 = 0;
        for i in 0..200u32 {
            let garbage_len = rng.random_range(0..40);
            for _ in 0..garbage_len {
                // Plenty of magic bytes in the noise, to exercise resync.
                let b = match rng.random_range(0..8) {
                    0 => 0xFD,
                    1 => 0xFE,
                    _ => rng.random(),
                };
                stream.push(b);
            }
            let msg = random_message(&mut rng);
            let seq = i as u8;
            let bytes = if rng.random_bool(0.3) {
                v1 += 1;
                encode_v1(42, 1, seq, &msg)
            } else {
                encode_v2(42, 1, seq, &msg)
            };
            stream.extend_from_slice(&bytes);
            expected.push(bytes);
        }
        // A stray magic byte near the end may claim up to a full frame:
        // trailing silence (non-magic bytes) lets it be rejected.
        stream.extend(std::iter::repeat_n(0u8, 300));

        let mut decoder = FrameDecoder::new();
        let mut frames = Vec::new();
        let mut at = 0;
        while at < stream.len() {
            let n = rng.random_range(1..=64).min(stream.len() - at);
            decoder.push(&stream[at..at + n], &mut frames);
            at += n;
        }
        let got: Vec<Vec<u8>> = frames.iter().map(|f| f.raw.clone()).collect();
        assert_eq!(got, expected, "seed {seed}");
        assert_eq!(decoder.stats().frames, 200);
        assert_eq!(decoder.stats().v1_frames, v1);
        assert!(decoder.stats().garbage_bytes >= 300);

        // Chunking never changes the result.
        let (whole, whole_stats) = decode_all(&stream);
        let whole: Vec<Vec<u8>> = whole.iter().map(|f| f.raw.clone()).collect();
        assert_eq!(whole, got);
        assert_eq!(&whole_stats, decoder.stats());
    }
}

#[test]
fn frame_flipped_byte_counts_bad_crc_and_the_next_frame_still_decodes() {
    let a = encode_v2(1, 1, 0, &param_value(1, 1.0));
    let mut b = encode_v2(1, 1, 1, &param_value(2, 2.0));
    let c = encode_v2(1, 1, 2, &heartbeat(3));
    b[14] ^= 0x10;
    // b's own CRC bytes may hold a magic byte claiming a long frame: on a
    // stream only more bytes can refute it, as they would on a live link.
    let stream = [a.clone(), b, c.clone(), vec![0; 300]].concat();
    let (frames, stats) = decode_all(&stream);
    let got: Vec<_> = frames.iter().map(|f| f.raw.clone()).collect();
    assert_eq!(got, vec![a, c]);
    assert_eq!(stats.bad_crc, 1);
    assert_eq!(stats.malformed(), 1);
    assert_eq!(stats.frames, 2);
}

#[test]
fn frame_unknown_message_id_is_counted_and_dropped() {
    let mut unknown = encode_v2(1, 1, 0, &heartbeat(0));
    // Message id 0xABCDEF is in no dialect we speak.
    unknown[7..10].copy_from_slice(&[0xEF, 0xCD, 0xAB]);
    let good = encode_v2(1, 1, 1, &heartbeat(1));
    let (frames, stats) = decode_all(&[unknown, good.clone()].concat());
    assert_eq!(frames.len(), 1);
    assert_eq!(frames[0].raw, good);
    assert_eq!(stats.unknown_msg, 1);
    assert_eq!(stats.bad_crc, 0);
}

#[test]
fn frame_signed_flag_is_reported_and_signature_bytes_kept() {
    let mut raw = mavlink_core::MAVLinkV2MessageRaw::new();
    let header = MavHeader {
        system_id: 255,
        component_id: 190,
        sequence: 4,
    };
    raw.serialize_message_for_signing(header, &heartbeat(7));
    let key = [7u8; 32];
    let signing = mavlink_core::SigningData::from_config(mavlink_core::SigningConfig::new(
        key, 0, true, false,
    ));
    signing.sign_message(&mut raw);
    let bytes = raw.raw_bytes().to_vec();
    let (frames, stats) = decode_all(&bytes);
    assert_eq!(frames.len(), 1, "{stats:?}");
    assert!(frames[0].signed);
    assert_eq!(frames[0].raw, bytes);
    assert_eq!(frames[0].msg, heartbeat(7));
}

#[test]
fn frame_datagram_with_two_frames_yields_two_and_a_torn_tail_is_malformed() {
    let a = encode_v2(1, 1, 0, &heartbeat(1));
    let b = encode_v1(1, 1, 1, &manual_control(1, 0));
    let mut stats = FrameStats::default();
    let mut out = Vec::new();
    decode_datagram(&[a.clone(), b.clone()].concat(), &mut stats, &mut out);
    assert_eq!(out.len(), 2);
    assert_eq!((out[0].raw.clone(), out[1].raw.clone()), (a.clone(), b));

    // A frame cut short at the end of a datagram is malformed; its first
    // half does not carry over to the next datagram.
    let mut stats = FrameStats::default();
    let mut out = Vec::new();
    decode_datagram(
        &[a.clone(), a[..10].to_vec()].concat(),
        &mut stats,
        &mut out,
    );
    assert_eq!(out.len(), 1);
    assert_eq!(stats.malformed(), 1);
    decode_datagram(&a[10..], &mut stats, &mut out);
    assert_eq!(out.len(), 1);
    decode_datagram(&a, &mut stats, &mut out);
    assert_eq!(out.len(), 2);
}

proptest! {
    /// The malformed-frame fuzz target over the endpoint input path: any
    /// bytes, in any chunking, as a stream or a datagram, never panic; the
    /// stream result does not depend on chunking.
    #[test]
    fn frame_arbitrary_bytes_never_panic(
        bytes in proptest::collection::vec(any::<u8>(), 0..1500),
        chunk in 1usize..300,
        splice_at in any::<prop::sample::Index>(),
    ) {
        // Splice a real frame into the noise so the valid path is exercised too.
        let mut bytes = bytes;
        let at = if bytes.is_empty() { 0 } else { splice_at.index(bytes.len()) };
        let frame = encode_v2(3, 4, 5, &heartbeat(at as u32));
        bytes.splice(at..at, frame.iter().copied());

        let (whole, whole_stats) = decode_all(&bytes);
        let mut decoder = FrameDecoder::new();
        let mut chunked = Vec::new();
        for piece in bytes.chunks(chunk) {
            decoder.push(piece, &mut chunked);
        }
        // Bytes, not messages: a float field may decode to NaN, and NaN != NaN.
        let raw = |frames: &[Frame]| frames.iter().map(|f| f.raw.clone()).collect::<Vec<_>>();
        prop_assert_eq!(raw(&whole), raw(&chunked));
        prop_assert_eq!(&whole_stats, decoder.stats());
        prop_assert_eq!(whole_stats.frames, whole.len() as u64);

        let mut stats = FrameStats::default();
        let mut out = Vec::new();
        decode_datagram(&bytes, &mut stats, &mut out);
        prop_assert_eq!(stats.frames, out.len() as u64);
        prop_assert!(out.iter().any(|f| f.raw == frame));
    }
}

// ---------------------------------------------------------------------------
// endpoint URLs
// ---------------------------------------------------------------------------

#[test]
fn endpoint_urls_parse_and_round_trip() {
    for url in [
        "udpin:0.0.0.0:14550",
        "udpout:127.0.0.1:14550",
        "tcpin:0.0.0.0:5760",
        "tcpout:192.168.2.1:5760",
        "udpin:[::]:14550",
        "serial:/dev/ttyUSB0:57600",
    ] {
        let spec: EndpointSpec = url.parse().unwrap();
        assert_eq!(spec.to_string(), url);
        assert_eq!(spec.to_string().parse::<EndpointSpec>().unwrap(), spec);
    }
    for url in neptunus::mavlink::DEFAULT_ENDPOINTS {
        url.parse::<EndpointSpec>().unwrap();
    }
    assert_eq!(
        "tcpout:localhost:5760".parse::<EndpointSpec>().unwrap(),
        EndpointSpec::TcpOut("127.0.0.1:5760".parse().unwrap())
    );
    assert_eq!(
        "serial:/dev/ttyO1".parse::<EndpointSpec>().unwrap(),
        EndpointSpec::Serial {
            path: PathBuf::from("/dev/ttyO1"),
            baud: 57_600
        }
    );
    for bad in [
        "udp:1.2.3.4:5",
        "udpin:14550",
        "tcpout:no-such-host.invalid:5760",
        "serial:/dev/ttyUSB0:fast",
        "nonsense",
    ] {
        let err = bad.parse::<EndpointSpec>().unwrap_err().to_string();
        assert!(err.contains(bad), "{err}");
        assert!(err.contains("udpin:ADDR:PORT"), "{err}");
    }
}

#[tokio::test]
async fn bind_failure_names_the_url() {
    let taken = udp_client().await;
    let url = format!("udpin:{}", taken.local_addr().unwrap());
    let (tx, _rx) = mpsc::channel(1);
    let err = Router::start(vec![url.parse().unwrap()], RouterConfig::default(), tx)
        .await
        .err()
        .expect("binding a taken port must fail");
    assert!(matches!(err, EndpointError::Bind { .. }));
    assert!(err.to_string().contains(&url), "{err}");
}

// ---------------------------------------------------------------------------
// 2. udpin
// ---------------------------------------------------------------------------

#[tokio::test]
async fn udpin_serves_two_clients_broadcast_and_per_peer() {
    let (router, mut inbound) = start(&["udpin:127.0.0.1:0"], RouterConfig::default()).await;
    let addr = router.local_addr(0).unwrap();
    let c1 = udp_client().await;
    let c2 = udp_client().await;
    c1.send_to(&encode_v2(201, 190, 0, &heartbeat(0)), addr)
        .await
        .unwrap();
    let in1 = next_inbound(&mut inbound).await;
    c2.send_to(&encode_v1(202, 0, 0, &heartbeat(0)), addr)
        .await
        .unwrap();
    let in2 = next_inbound(&mut inbound).await;
    assert_eq!((in1.frame.sysid, in2.frame.sysid), (201, 202));
    assert_eq!((in1.endpoint, in2.endpoint), (0, 0));
    assert_ne!(in1.peer, in2.peer);
    assert_eq!(router.stats()[0].peers, 2);

    router.send(out_all(encode_v2(1, 1, 0, &heartbeat(100))));
    for c in [&c1, &c2] {
        let (f, from) = udp_next_frame(c).await;
        assert_eq!(f.msg, heartbeat(100));
        assert_eq!(from, addr);
    }
    router.send(out_to(
        Route::Peer(0, in1.peer),
        encode_v2(1, 1, 1, &heartbeat(101)),
    ));
    router.send(out_to(
        Route::Peer(0, in2.peer),
        encode_v2(1, 1, 2, &heartbeat(102)),
    ));
    router.send(out_to(
        Route::Endpoint(0),
        encode_v2(1, 1, 3, &heartbeat(103)),
    ));
    // Each client gets its own reply and then the broadcast, never the other's.
    assert_eq!(udp_next_frame(&c1).await.0.msg, heartbeat(101));
    assert_eq!(udp_next_frame(&c1).await.0.msg, heartbeat(103));
    assert_eq!(udp_next_frame(&c2).await.0.msg, heartbeat(102));
    assert_eq!(udp_next_frame(&c2).await.0.msg, heartbeat(103));
    let s = &router.stats()[0];
    assert_eq!((s.frames_in, s.frames_out), (2, 6));
    router.shutdown().await;
}

#[tokio::test]
async fn udpin_peers_expire_after_silence() {
    let cfg = RouterConfig {
        peer_timeout: Duration::from_millis(300),
        ..RouterConfig::default()
    };
    let (router, mut inbound) = start(&["udpin:127.0.0.1:0"], cfg).await;
    let addr = router.local_addr(0).unwrap();
    let old = udp_client().await;
    old.send_to(&encode_v2(201, 1, 0, &heartbeat(0)), addr)
        .await
        .unwrap();
    next_inbound(&mut inbound).await;
    assert_eq!(router.stats()[0].peers, 1);
    wait_stats(&router, "the silent peer to expire", |s| s[0].peers == 0).await;

    // The expired peer no longer gets broadcasts; a new one does. Queue
    // order proves the first broadcast was handled before the second.
    router.send(out_all(encode_v2(1, 1, 0, &heartbeat(1))));
    let new = udp_client().await;
    new.send_to(&encode_v2(202, 1, 0, &heartbeat(0)), addr)
        .await
        .unwrap();
    next_inbound(&mut inbound).await;
    router.send(out_all(encode_v2(1, 1, 1, &heartbeat(2))));
    assert_eq!(udp_next_frame(&new).await.0.msg, heartbeat(2));
    assert_eq!(router.stats()[0].frames_out, 1);
    router.shutdown().await;
}

// ---------------------------------------------------------------------------
// 3. udpout
// ---------------------------------------------------------------------------

#[tokio::test]
async fn udpout_sends_to_the_target_and_to_whoever_writes_to_it() {
    let target = udp_client().await;
    let url = format!("udpout:{}", target.local_addr().unwrap());
    let (router, mut inbound) = start(&[&url], RouterConfig::default()).await;
    let port = router.local_addr(0).unwrap().port();
    let ours: SocketAddr = ([127, 0, 0, 1], port).into();
    assert_eq!(router.stats()[0].peers, 1, "the target is always a peer");

    router.send(out_all(encode_v2(1, 1, 0, &heartbeat(1))));
    let (f, from) = udp_next_frame(&target).await;
    assert_eq!(f.msg, heartbeat(1));
    assert_eq!(from.port(), port);

    // QGC answers from its 14550 socket, i.e. from the target address.
    target
        .send_to(&encode_v2(255, 190, 0, &heartbeat(0)), ours)
        .await
        .unwrap();
    let from_target = next_inbound(&mut inbound).await;

    let third = udp_client().await;
    third
        .send_to(&encode_v2(245, 190, 0, &heartbeat(0)), ours)
        .await
        .unwrap();
    let from_third = next_inbound(&mut inbound).await;
    assert_ne!(from_target.peer, from_third.peer);
    assert_eq!(router.stats()[0].peers, 2);

    router.send(out_all(encode_v2(1, 1, 1, &heartbeat(2))));
    assert_eq!(udp_next_frame(&target).await.0.msg, heartbeat(2));
    assert_eq!(udp_next_frame(&third).await.0.msg, heartbeat(2));
    router.send(out_to(
        Route::Peer(0, from_target.peer),
        encode_v2(1, 1, 2, &heartbeat(3)),
    ));
    assert_eq!(udp_next_frame(&target).await.0.msg, heartbeat(3));
    router.shutdown().await;
}

// ---------------------------------------------------------------------------
// 4. tcpin
// ---------------------------------------------------------------------------

#[tokio::test]
async fn tcpin_serves_three_clients_survives_a_disconnect() {
    let (router, mut inbound) = start(&["tcpin:127.0.0.1:0"], RouterConfig::default()).await;
    let addr = router.local_addr(0).unwrap();
    let mut clients = Vec::new();
    for _ in 0..3 {
        clients.push((TcpStream::connect(addr).await.unwrap(), StreamReader::new()));
    }
    wait_stats(&router, "three clients", |s| s[0].peers == 3).await;

    let mut peers = Vec::new();
    for (i, (stream, _)) in clients.iter_mut().enumerate() {
        stream
            .write_all(&encode_v2(200 + i as u8, 190, 0, &heartbeat(0)))
            .await
            .unwrap();
        let inb = next_inbound(&mut inbound).await;
        assert_eq!(inb.frame.sysid, 200 + i as u8);
        peers.push(inb.peer);
    }

    router.send(out_all(encode_v2(1, 1, 0, &heartbeat(1))));
    for (stream, reader) in clients.iter_mut() {
        assert_eq!(reader.next(stream).await.msg, heartbeat(1));
    }
    router.send(out_to(
        Route::Peer(0, peers[1]),
        encode_v2(1, 1, 1, &heartbeat(2)),
    ));
    let (stream, reader) = &mut clients[1];
    assert_eq!(reader.next(stream).await.msg, heartbeat(2));

    drop(clients.pop());
    wait_stats(&router, "the disconnect", |s| s[0].peers == 2).await;
    router.send(out_all(encode_v2(1, 1, 2, &heartbeat(3))));
    for (stream, reader) in clients.iter_mut() {
        assert_eq!(reader.next(stream).await.msg, heartbeat(3));
    }
    router.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tcpin_client_that_never_reads_does_not_block_the_others() {
    let (router, _inbound) = start(&["tcpin:127.0.0.1:0"], RouterConfig::default()).await;
    let addr = router.local_addr(0).unwrap();

    // The stuck client: a tiny receive window, and it never reads.
    let socket = TcpSocket::new_v4().unwrap();
    socket.set_recv_buffer_size(4096).unwrap();
    let _stuck = socket.connect(addr).await.unwrap();

    // Two good clients forward every frame's tag to the test.
    let mut good = Vec::new();
    for _ in 0..2 {
        let mut stream = TcpStream::connect(addr).await.unwrap();
        let (tx, rx) = mpsc::unbounded_channel();
        tokio::spawn(async move {
            let mut reader = StreamReader::new();
            loop {
                let f = reader.next(&mut stream).await;
                let MavMessage::FILE_TRANSFER_PROTOCOL(d) = f.msg else {
                    continue;
                };
                let tag = u32::from_le_bytes(d.payload[..4].try_into().unwrap());
                if tx.send(tag).is_err() {
                    return;
                }
            }
        });
        good.push(rx);
    }
    wait_stats(&router, "three clients", |s| s[0].peers == 3).await;

    // Send in batches, each delivered to the good clients before the next,
    // until the stuck client's queue overflows.
    let mut tag = 0u32;
    let mut batches = 0;
    while router.stats()[0].send_errors == 0 {
        batches += 1;
        assert!(batches < 2000, "the stuck client never overflowed");
        for _ in 0..100 {
            router.send(out_all(encode_v2(1, 1, tag as u8, &big_message(tag))));
            tag += 1;
        }
        for rx in good.iter_mut() {
            loop {
                let got = timeout(WAIT, rx.recv()).await.unwrap().unwrap();
                if got == tag - 1 {
                    break;
                }
            }
        }
    }
    // And the good clients still get everything after the overflow.
    for _ in 0..100 {
        router.send(out_all(encode_v2(1, 1, tag as u8, &big_message(tag))));
        tag += 1;
    }
    for rx in good.iter_mut() {
        loop {
            let got = timeout(WAIT, rx.recv()).await.unwrap().unwrap();
            if got == tag - 1 {
                break;
            }
        }
    }
    let s = &router.stats()[0];
    assert_eq!(s.peers, 3);
    // Each good client got every frame; only the stuck one lost frames.
    assert!(s.frames_out >= 2 * u64::from(tag), "{s:?}");
    router.shutdown().await;
}

// ---------------------------------------------------------------------------
// 5. tcpout
// ---------------------------------------------------------------------------

#[tokio::test]
async fn tcpout_reconnects_after_the_server_restarts() {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let server_addr = listener.local_addr().unwrap();
    let url = format!("tcpout:{server_addr}");
    let (router, mut inbound) = start(&[&url], RouterConfig::default()).await;

    let (mut conn, _) = timeout(WAIT, listener.accept()).await.unwrap().unwrap();
    wait_stats(&router, "connection", |s| s[0].peers == 1).await;
    conn.write_all(&encode_v2(255, 190, 0, &heartbeat(0)))
        .await
        .unwrap();
    let first = next_inbound(&mut inbound).await;
    router.send(out_all(encode_v2(1, 1, 0, &heartbeat(1))));
    let mut reader = StreamReader::new();
    assert_eq!(reader.next(&mut conn).await.msg, heartbeat(1));

    // The server goes away...
    drop(conn);
    drop(listener);
    wait_stats(&router, "the disconnect", |s| s[0].peers == 0).await;
    // ...and comes back on the same port.
    let listener = TcpListener::bind(server_addr).await.unwrap();
    let (mut conn, _) = timeout(WAIT, listener.accept()).await.unwrap().unwrap();
    wait_stats(&router, "the reconnection", |s| s[0].peers == 1).await;
    conn.write_all(&encode_v2(255, 190, 1, &heartbeat(0)))
        .await
        .unwrap();
    let second = next_inbound(&mut inbound).await;
    assert_ne!(first.peer, second.peer, "a new connection is a new peer");
    router.send(out_all(encode_v2(1, 1, 1, &heartbeat(2))));
    let mut reader = StreamReader::new();
    assert_eq!(reader.next(&mut conn).await.msg, heartbeat(2));
    router.shutdown().await;
}

// ---------------------------------------------------------------------------
// 6. serial
// ---------------------------------------------------------------------------

#[tokio::test]
async fn serial_endpoint_over_a_pty() {
    let pty = PtyPair::open().unwrap();
    let url = format!("serial:{}:115200", pty.slave_path().display());
    let (router, mut inbound) = start(&[&url], RouterConfig::default()).await;
    wait_stats(&router, "the serial port to open", |s| s[0].peers == 1).await;

    let bytes = [vec![0x55, 0xFD, 0x00], encode_v1(255, 0, 0, &heartbeat(5))].concat();
    assert_eq!(pty.try_write(&bytes).unwrap(), bytes.len());
    let inb = next_inbound(&mut inbound).await;
    assert_eq!(inb.frame.msg, heartbeat(5));
    assert_eq!(inb.frame.version, MavlinkVersion::V1);

    router.send(out_all(encode_v2(1, 1, 0, &param_value(1, 2.5))));
    let mut decoder = FrameDecoder::new();
    let mut frames = Vec::new();
    timeout(WAIT, async {
        let mut buf = [0u8; 512];
        while frames.is_empty() {
            let n = pty.read(&mut buf).await.unwrap();
            decoder.push(&buf[..n], &mut frames);
        }
    })
    .await
    .expect("nothing came out of the serial port");
    assert_eq!(frames[0].msg, param_value(1, 2.5));
    router.shutdown().await;
}

// ---------------------------------------------------------------------------
// 7. malformed input per endpoint
// ---------------------------------------------------------------------------

#[tokio::test]
async fn malformed_input_is_counted_per_endpoint_and_good_frames_delivered() {
    let (router, mut inbound) = start(
        &["udpin:127.0.0.1:0", "tcpin:127.0.0.1:0"],
        RouterConfig::default(),
    )
    .await;
    let udp_addr = router.local_addr(0).unwrap();
    let tcp_addr = router.local_addr(1).unwrap();

    let a = encode_v2(10, 1, 0, &heartbeat(1));
    let mut broken = encode_v2(10, 1, 1, &param_value(3, 3.0));
    broken[12] ^= 0xFF;
    let b = encode_v2(10, 1, 2, &heartbeat(2));
    let datagram = [b"noise".to_vec(), a, broken, b].concat();
    let c = udp_client().await;
    c.send_to(&datagram, udp_addr).await.unwrap();
    assert_eq!(next_inbound(&mut inbound).await.frame.msg, heartbeat(1));
    assert_eq!(next_inbound(&mut inbound).await.frame.msg, heartbeat(2));

    // Noise alone does not make its sender a peer.
    let garbage_before = router.stats()[0].decode.garbage_bytes;
    udp_client()
        .await
        .send_to(b"GET / HTTP/1.0", udp_addr)
        .await
        .unwrap();
    wait_stats(&router, "the noise to be counted", |s| {
        s[0].decode.garbage_bytes >= garbage_before + 14
    })
    .await;
    assert_eq!(router.stats()[0].peers, 1);

    let mut unknown = encode_v2(11, 1, 0, &heartbeat(0));
    unknown[7..10].copy_from_slice(&[0x01, 0x02, 0x03]);
    let mut stream = TcpStream::connect(tcp_addr).await.unwrap();
    stream
        .write_all(&[unknown, encode_v2(11, 1, 1, &heartbeat(3))].concat())
        .await
        .unwrap();
    let inb = next_inbound(&mut inbound).await;
    assert_eq!((inb.endpoint, inb.frame.msg), (1, heartbeat(3)));

    let stats = router.stats();
    let (u, t) = (&stats[0].decode, &stats[1].decode);
    assert_eq!((u.frames, u.bad_crc, u.unknown_msg), (2, 1, 0));
    assert!(u.garbage_bytes >= 5);
    assert_eq!((t.frames, t.bad_crc, t.unknown_msg), (1, 0, 1));
    assert_eq!((stats[0].frames_in, stats[1].frames_in), (2, 1));
    router.shutdown().await;
}

// ---------------------------------------------------------------------------
// 8. telemetry log
// ---------------------------------------------------------------------------

/// Splits a .tlog into (timestamp, frame bytes) records.
fn read_tlog(path: &Path) -> Vec<(u64, Vec<u8>)> {
    let data = std::fs::read(path).unwrap();
    let mut records = Vec::new();
    let mut at = 0;
    while at < data.len() {
        let time = u64::from_be_bytes(data[at..at + 8].try_into().unwrap());
        at += 8;
        let len = match data[at] {
            0xFE => 6 + usize::from(data[at + 1]) + 2,
            0xFD => {
                let signed = data[at + 2] & 1 != 0;
                10 + usize::from(data[at + 1]) + 2 + if signed { 13 } else { 0 }
            }
            other => panic!("record at {at} starts with {other:#x}"),
        };
        records.push((time, data[at..at + len].to_vec()));
        at += len;
    }
    records
}

fn tlog_files(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "tlog"))
        .collect();
    files.sort();
    files
}

fn now_us() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_micros() as u64
}

#[tokio::test]
async fn tlog_records_frames_in_and_out_once_with_the_signing_key_zeroed() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = RouterConfig {
        tlog: Some(TlogConfig::new(dir.path())),
        ..RouterConfig::default()
    };
    let started = now_us();
    let (router, mut inbound) = start(&["udpin:127.0.0.1:0", "udpin:127.0.0.1:0"], cfg).await;
    let key = [0xAB; 32];
    let gcs_in = encode_v2(255, 190, 0, &setup_signing(key));
    let hb_in = encode_v1(255, 0, 1, &heartbeat(0));
    let c1 = udp_client().await;
    let c2 = udp_client().await;
    c1.send_to(&gcs_in, router.local_addr(0).unwrap())
        .await
        .unwrap();
    next_inbound(&mut inbound).await;
    c2.send_to(&hb_in, router.local_addr(1).unwrap())
        .await
        .unwrap();
    next_inbound(&mut inbound).await;

    // Two endpoints with a peer each: still one record per send.
    let out = encode_v2(1, 1, 0, &heartbeat(9));
    router.send(out_all(out.clone()));
    udp_next_frame(&c1).await;
    udp_next_frame(&c2).await;
    let out_signing = encode_v2(1, 1, 1, &setup_signing(key));
    router.send(out_to(Route::Endpoint(0), out_signing.clone()));
    udp_next_frame(&c1).await;
    router.shutdown().await;
    let finished = now_us();

    let files = tlog_files(dir.path());
    assert_eq!(files.len(), 1, "{files:?}");
    let name = files[0].file_name().unwrap().to_string_lossy().into_owned();
    assert!(
        name.starts_with("neptunus-") && name.ends_with(".tlog"),
        "{name}"
    );
    let records = read_tlog(&files[0]);
    assert_eq!(records.len(), 4);
    for (time, _) in &records {
        assert!(
            (started..=finished).contains(time),
            "{time} not big-endian µs?"
        );
    }
    assert!(records.windows(2).all(|w| w[0].0 <= w[1].0));

    let zeroed = |raw: &[u8]| {
        let mut raw = raw.to_vec();
        raw[20..52].fill(0);
        raw
    };
    let frames: Vec<Vec<u8>> = records.into_iter().map(|(_, f)| f).collect();
    assert_eq!(
        frames,
        vec![zeroed(&gcs_in), hb_in, out, zeroed(&out_signing)]
    );
    let file = std::fs::read(&files[0]).unwrap();
    assert!(
        !file.windows(8).any(|w| w == [0xAB; 8]),
        "the signing key reached the log"
    );
}

#[test]
fn tlog_rotates_by_size_and_never_overwrites() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = TlogConfig {
        dir: dir.path().join("logs"),
        max_bytes: 100,
        total_bytes: u64::MAX,
        clock: neptunus::wallclock::WallClock::system(),
    };
    let frame = encode_v2(1, 1, 0, &heartbeat(0)); // 21 bytes: 29 per record
    assert_eq!(frame.len(), 21);
    let mut writer = TlogWriter::create(&cfg, "dive").unwrap();
    assert_eq!(writer.path(), cfg.dir.join("dive.tlog"));
    for i in 0..10u64 {
        writer.write_frame(1_000_000 + i, &frame).unwrap();
    }
    writer.flush().unwrap();
    assert_eq!(writer.path(), cfg.dir.join("dive-4.tlog"));
    let files = tlog_files(&cfg.dir);
    let names: Vec<String> = files
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    assert_eq!(
        names,
        ["dive-2.tlog", "dive-3.tlog", "dive-4.tlog", "dive.tlog"]
    );
    let mut times = Vec::new();
    for name in ["dive.tlog", "dive-2.tlog", "dive-3.tlog", "dive-4.tlog"] {
        let path = cfg.dir.join(name);
        assert!(std::fs::metadata(&path).unwrap().len() <= 100);
        for (time, raw) in read_tlog(&path) {
            assert_eq!(raw, frame);
            times.push(time);
        }
    }
    assert_eq!(times, (1_000_000..1_000_010).collect::<Vec<_>>());

    // Same session name again: a new file, the old ones untouched.
    let again = TlogWriter::create(&cfg, "dive").unwrap();
    assert_eq!(again.path(), cfg.dir.join("dive-5.tlog"));
}

// ---------------------------------------------------------------------------
// 7. under attack: full peer tables, idle connections, floods, disk bounds
// ---------------------------------------------------------------------------

/// Sends one frame from `sysid` on `sock` and returns its inbound record.
async fn udp_hello(
    sock: &UdpSocket,
    addr: SocketAddr,
    sysid: u8,
    inbound: &mut mpsc::Receiver<Inbound>,
) -> Inbound {
    sock.send_to(&encode_v2(sysid, 190, 0, &heartbeat(0)), addr)
        .await
        .unwrap();
    next_inbound(inbound).await
}

#[tokio::test]
async fn udpin_full_table_evicts_strangers_never_a_station_that_may_control() {
    let (router, mut inbound) = start(&["udpin:127.0.0.1:0"], RouterConfig::default()).await;
    let addr = router.local_addr(0).unwrap();
    // The pilot's station first, marked by the vehicle side as it would be.
    let pilot = udp_client().await;
    udp_hello(&pilot, addr, 255, &mut inbound)
        .await
        .standing
        .set_may_control(true);
    // Strangers fill the table and keep coming.
    let mut strangers = Vec::new();
    for i in 0..(MAX_PEERS + 10) {
        let s = udp_client().await;
        udp_hello(&s, addr, 100 + (i % 100) as u8, &mut inbound).await;
        strangers.push(s);
    }
    let s = &router.stats()[0];
    assert_eq!(s.peers, MAX_PEERS);
    assert_eq!(s.peers_evicted, 11, "{s:#?}");
    assert_eq!(s.inbound_dropped, 0, "nobody refused: {s:#?}");
    // The pilot is still a peer: it gets the broadcast; the oldest strangers do not.
    router.send(out_all(encode_v2(1, 1, 0, &heartbeat(7))));
    assert_eq!(udp_next_frame(&pilot).await.0.msg, heartbeat(7));
    assert_eq!(
        udp_next_frame(strangers.last().unwrap()).await.0.msg,
        heartbeat(7)
    );
    let mut buf = [0u8; 64];
    assert!(
        timeout(Duration::from_millis(200), strangers[0].recv_from(&mut buf))
            .await
            .is_err(),
        "an evicted stranger still gets telemetry"
    );
    router.shutdown().await;
}

#[tokio::test]
async fn udpin_table_full_of_stations_that_may_control_refuses_newcomers() {
    let (router, mut inbound) = start(&["udpin:127.0.0.1:0"], RouterConfig::default()).await;
    let addr = router.local_addr(0).unwrap();
    let mut keep = Vec::new();
    for _ in 0..MAX_PEERS {
        let s = udp_client().await;
        udp_hello(&s, addr, 255, &mut inbound)
            .await
            .standing
            .set_may_control(true);
        keep.push(s);
    }
    let late = udp_client().await;
    late.send_to(&encode_v2(255, 190, 0, &heartbeat(0)), addr)
        .await
        .unwrap();
    wait_stats(&router, "the newcomer refused", |s| {
        s[0].inbound_dropped == 1
    })
    .await;
    let s = &router.stats()[0];
    assert_eq!((s.peers, s.peers_evicted), (MAX_PEERS, 0));
    router.shutdown().await;
}

#[tokio::test]
async fn tcpin_idle_clients_are_closed_after_the_peer_timeout_talking_ones_are_not() {
    let cfg = RouterConfig {
        peer_timeout: Duration::from_millis(300),
        ..RouterConfig::default()
    };
    let (router, mut inbound) = start(&["tcpin:127.0.0.1:0"], cfg).await;
    let addr = router.local_addr(0).unwrap();
    let mut idle = TcpStream::connect(addr).await.unwrap();
    let mut talker = TcpStream::connect(addr).await.unwrap();
    wait_stats(&router, "two clients", |s| s[0].peers == 2).await;
    // The talker sends a frame every 100 ms until the idle one is gone.
    let talking = async {
        for seq in 0u8.. {
            talker
                .write_all(&encode_v2(255, 190, seq, &heartbeat(0)))
                .await
                .unwrap();
            next_inbound(&mut inbound).await;
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    };
    let closed = async {
        let mut buf = [0u8; 64];
        loop {
            match idle.read(&mut buf).await {
                Ok(0) | Err(_) => return,
                Ok(_) => {}
            }
        }
    };
    tokio::select! {
        () = talking => unreachable!(),
        r = timeout(WAIT, closed) => r.expect("the idle client was never closed"),
    }
    wait_stats(&router, "one client left", |s| s[0].peers == 1).await;
    // The talker still works.
    router.send(out_all(encode_v2(1, 1, 0, &heartbeat(5))));
    let mut reader = StreamReader::new();
    assert_eq!(reader.next(&mut talker).await.msg, heartbeat(5));
    router.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tcpin_full_table_evicts_idle_strangers_for_newcomers_and_keeps_the_pilot() {
    let (router, mut inbound) = start(&["tcpin:127.0.0.1:0"], RouterConfig::default()).await;
    let addr = router.local_addr(0).unwrap();
    let mut pilot = TcpStream::connect(addr).await.unwrap();
    pilot
        .write_all(&encode_v2(255, 190, 0, &heartbeat(0)))
        .await
        .unwrap();
    next_inbound(&mut inbound)
        .await
        .standing
        .set_may_control(true);
    // 70 connections that never say anything.
    let mut idle = Vec::new();
    for _ in 0..70 {
        idle.push(TcpStream::connect(addr).await.unwrap());
    }
    wait_stats(&router, "the evictions", |s| s[0].peers_evicted == 7).await;
    // A new station gets in and is heard.
    let mut newcomer = TcpStream::connect(addr).await.unwrap();
    newcomer
        .write_all(&encode_v2(254, 190, 0, &heartbeat(0)))
        .await
        .unwrap();
    assert_eq!(next_inbound(&mut inbound).await.frame.sysid, 254);
    let s = &router.stats()[0];
    assert_eq!((s.peers, s.peers_evicted), (MAX_PEERS, 8), "{s:#?}");
    // Both the pilot and the newcomer get telemetry.
    router.send(out_all(encode_v2(1, 1, 0, &heartbeat(6))));
    assert_eq!(StreamReader::new().next(&mut pilot).await.msg, heartbeat(6));
    assert_eq!(
        StreamReader::new().next(&mut newcomer).await.msg,
        heartbeat(6)
    );
    // The first idle connections were the ones closed.
    let mut buf = [0u8; 64];
    let n = timeout(WAIT, idle[0].read(&mut buf))
        .await
        .unwrap()
        .unwrap_or(0);
    assert_eq!(n, 0, "the oldest idle connection was not closed");
    router.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tlog_takes_strangers_frames_through_a_rate_limit_and_every_frame_of_a_station_that_may_control()
 {
    let dir = tempfile::tempdir().unwrap();
    let cfg = RouterConfig {
        tlog: Some(TlogConfig::new(dir.path())),
        ..RouterConfig::default()
    };
    let (router, mut inbound) = start(&["tcpin:127.0.0.1:0"], cfg).await;
    let addr = router.local_addr(0).unwrap();
    let mut pilot = TcpStream::connect(addr).await.unwrap();
    pilot
        .write_all(&encode_v2(255, 190, 0, &heartbeat(0)))
        .await
        .unwrap();
    next_inbound(&mut inbound)
        .await
        .standing
        .set_may_control(true);
    let started = std::time::Instant::now();
    // The flood: 20 000 frames from a stranger in big writes, while the pilot
    // sends 200.
    let mut stranger = TcpStream::connect(addr).await.unwrap();
    let flood: Vec<u8> = (0..20_000u32)
        .flat_map(|i| encode_v2(66, 1, i as u8, &heartbeat(i)))
        .collect();
    let flooding = tokio::spawn(async move {
        stranger.write_all(&flood).await.unwrap();
        stranger
    });
    let mut got_pilot = 0;
    let mut got_stranger = 0u64;
    for seq in 1..=200u32 {
        pilot
            .write_all(&encode_v2(255, 190, seq as u8, &heartbeat(1000 + seq)))
            .await
            .unwrap();
    }
    let _stranger = flooding.await.unwrap();
    // Drain until every pilot frame and the whole flood went through the router.
    wait_stats(&router, "the flood decoded", |s| s[0].frames_in >= 20_201).await;
    while let Ok(Some(inb)) = timeout(Duration::from_millis(200), inbound.recv()).await {
        if inb.frame.sysid == 255 {
            got_pilot += 1;
        } else {
            got_stranger += 1;
        }
    }
    let elapsed = started.elapsed().as_secs_f64();
    assert_eq!(
        got_pilot, 200,
        "the pilot's frames must all reach the vehicle"
    );
    assert!(got_stranger > 0);
    let s = router.stats()[0].clone();
    router.shutdown().await;

    let records: Vec<Vec<u8>> = tlog_files(dir.path())
        .iter()
        .flat_map(|p| read_tlog(p))
        .map(|(_, raw)| raw)
        .collect();
    let pilot_logged = records.iter().filter(|r| r[5] == 255).count();
    let stranger_logged = records.iter().filter(|r| r[5] == 66).count() as f64;
    assert_eq!(pilot_logged, 201, "every frame of the pilot is logged");
    let bound = 40.0 + neptunus::mavlink::endpoint::TLOG_STRANGER_RATE_HZ * elapsed + 1.0;
    assert!(
        stranger_logged <= bound,
        "{stranger_logged} stranger frames logged in {elapsed:.2} s (bound {bound:.0})"
    );
    assert_eq!(s.tlog_dropped, 20_000 - stranger_logged as u64, "{s:#?}");
}

#[test]
fn tlog_total_cap_deletes_the_oldest_of_our_files_first_and_nothing_else() {
    let dir = tempfile::tempdir().unwrap();
    let tlogs = dir.path().join("tlogs");
    std::fs::create_dir_all(&tlogs).unwrap();
    let kib = |n: usize| vec![0u8; n * 1024];
    for (name, size) in [
        ("neptunus-20260101-000000.tlog", 300),
        ("neptunus-20260101-000000-2.tlog", 300),
        ("neptunus-20260101-000000-10.tlog", 300),
        ("neptunus-20260102-000000.tlog", 300),
        ("notes.txt", 2000),
        ("other.tlog", 2000),
    ] {
        std::fs::write(tlogs.join(name), kib(size)).unwrap();
    }
    let cfg = TlogConfig {
        dir: tlogs.clone(),
        max_bytes: 64 * 1024 * 1024,
        total_bytes: 1024 * 1024,
        clock: neptunus::wallclock::WallClock::system(),
    };
    // Files rotate at half the total: room for the live one is kept.
    assert_eq!(cfg.file_bytes(), 512 * 1024);
    let mut w = TlogWriter::create(&cfg, "neptunus-20260103-000000").unwrap();
    let names = |dir: &Path| -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    };
    // 4 × 300 KiB + 512 KiB > 1 MiB: the three oldest (index order, not
    // string order: -2 before -10) go; other files are not ours to touch.
    assert_eq!(
        names(&tlogs),
        [
            "neptunus-20260102-000000.tlog",
            "neptunus-20260103-000000.tlog",
            "notes.txt",
            "other.tlog"
        ]
    );
    // Writing 3 MiB keeps our files under the cap at every rotation.
    let frame = encode_v2(1, 1, 0, &big_message(0));
    let ours = |dir: &Path| -> u64 {
        std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap())
            .filter(|e| {
                neptunus::mavlink::tlog::parse_file_name(&e.file_name().to_string_lossy()).is_some()
            })
            .map(|e| e.metadata().unwrap().len())
            .sum()
    };
    let mut written = 0;
    while written < 3 * 1024 * 1024 {
        w.write_frame(1, &frame).unwrap();
        written += frame.len() + 8;
        w.flush().unwrap();
        assert!(ours(&tlogs) <= 1024 * 1024, "{} bytes", ours(&tlogs));
    }
    assert!(!tlogs.join("neptunus-20260102-000000.tlog").exists());
    assert!(tlogs.join("notes.txt").exists() && tlogs.join("other.tlog").exists());
}

#[tokio::test]
async fn tlog_takes_replies_to_strangers_through_the_rate_limit_and_all_replies_to_the_pilot() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = RouterConfig {
        tlog: Some(TlogConfig::new(dir.path())),
        ..RouterConfig::default()
    };
    let (router, mut inbound) = start(&["udpin:127.0.0.1:0"], cfg).await;
    let addr = router.local_addr(0).unwrap();
    let pilot = udp_client().await;
    let pilot_in = udp_hello(&pilot, addr, 255, &mut inbound).await;
    pilot_in.standing.set_may_control(true);
    let stranger = udp_client().await;
    let stranger_in = udp_hello(&stranger, addr, 66, &mut inbound).await;
    let started = std::time::Instant::now();
    for i in 0..500u32 {
        let to_pilot = encode_v2(1, 1, 0, &heartbeat(10_000 + i));
        router.send(out_to(Route::Peer(0, pilot_in.peer), to_pilot));
        let to_stranger = encode_v2(1, 1, 0, &heartbeat(20_000 + i));
        router.send(out_to(Route::Peer(0, stranger_in.peer), to_stranger));
    }
    // Queue order: once the last frame reached the pilot, all were dispatched.
    let mut last = 0;
    while last != 10_499 {
        if let MavMessage::HEARTBEAT(h) = udp_next_frame(&pilot).await.0.msg {
            last = h.custom_mode;
        }
    }
    router.shutdown().await;
    let elapsed = started.elapsed().as_secs_f64();
    let modes: Vec<u32> = tlog_files(dir.path())
        .iter()
        .flat_map(|p| read_tlog(p))
        .filter_map(|(_, raw)| match decode_all(&raw).0.pop()?.msg {
            MavMessage::HEARTBEAT(h) if raw[5] == 1 => Some(h.custom_mode),
            _ => None,
        })
        .collect();
    let to_pilot = modes
        .iter()
        .filter(|m| (10_000..20_000).contains(*m))
        .count();
    let to_stranger = modes.iter().filter(|m| **m >= 20_000).count();
    assert_eq!(to_pilot, 500, "every reply to the pilot is logged");
    // The burst (40, less the stranger's own hello) and the refill.
    let bound = 40.0 + neptunus::mavlink::endpoint::TLOG_STRANGER_RATE_HZ * elapsed;
    assert!(
        (to_stranger as f64) <= bound,
        "{to_stranger} replies to the stranger logged in {elapsed:.2} s"
    );
}
