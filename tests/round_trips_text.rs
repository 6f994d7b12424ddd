//! Round trips of the text parsers, as properties (the fuzz targets
//! `m2r_json`, `hmi_messages`, `webrtc_signalling`, `http_gate` and
//! `config_values` check the same on arbitrary input): what Neptunus writes,
//! or what a client writes in the protocol's shape, parses back to the same
//! value.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::net::{IpAddr, SocketAddr};

use mavlink_core::{MavlinkVersion, Message as _};
use neptunus::camera::rtp::RtpDest;
use neptunus::camera::webrtc::SignallingAddr;
use neptunus::camera::webrtc::protocol::{
    Answer, Bind, BindOffer, EndSession, IceCandidate, IceNegotiation, MediaNegotiation, Message,
    Negotiation, PeerIdAnswer, Question, SessionDescription,
};
use neptunus::dialect::neptunus::MavMessage;
use neptunus::fuzzing::{m2r_wanted, plain_host};
use neptunus::hmi::auth::{COOKIE, Gate, cookie_value, parse_origin, with_port};
use neptunus::hmi::m2r::frame::{self, Header, Reserved};
use neptunus::hmi::protocol::{ClientMsg, HMI_MODES, InputMode, RunMode};
use neptunus::mavlink::encode_v2;
use neptunus::mavlink::endpoint::{EndpointSpec, EndpointUrl};
use proptest::prelude::*;

fn socket_addr() -> impl Strategy<Value = SocketAddr> {
    prop_oneof![
        any::<[u8; 4]>().prop_map(IpAddr::from),
        any::<[u8; 16]>().prop_map(IpAddr::from),
    ]
    .prop_flat_map(|ip| any::<u16>().prop_map(move |port| SocketAddr::new(ip, port)))
}

proptest! {
    /// Any message of the dialect, as the vehicle writes it for mavlink2rest
    /// clients, parses back to the same message (its MAVLink payload
    /// compared, as a float may be NaN), unless it holds a float JSON cannot
    /// hold (written `null`); and as a client's frame it converts.
    #[test]
    fn every_message_survives_mavlink2rest_json(
        index in any::<prop::sample::Index>(),
        payload in prop::collection::vec(any::<u8>(), 0..255),
        header in (1u8..=255, any::<u8>(), any::<u8>()),
    ) {
        let all = MavMessage::all_messages();
        let (_, id) = all[index.index(all.len())];
        let Ok(msg) = MavMessage::parse(MavlinkVersion::V2, id, &payload) else {
            return Ok(());
        };
        let json = frame::message_json(&msg).unwrap();
        let header = Header { system_id: header.0, component_id: header.1, sequence: header.2 };
        let reserved = Reserved { vehicle_sysid: 0, hmi_sysids: (1, 0) };
        match frame::parse(&frame::frame_json(header, &json), reserved) {
            Ok(f) => {
                prop_assert_eq!(f.header, header);
                prop_assert_eq!(encode_v2(1, 1, 0, &f.message), encode_v2(1, 1, 0, &msg));
            }
            Err(e) => prop_assert!(json.contains("null"), "{}: {}", e, json),
        }
    }
}

fn unit() -> impl Strategy<Value = f64> {
    -1.0f64..=1.0
}

fn client_msg() -> impl Strategy<Value = ClientMsg> {
    let modes: Vec<u32> = HMI_MODES.iter().map(|(m, _)| m.number()).collect();
    prop_oneof![
        Just(ClientMsg::Alive {}),
        "[ -~]{0,40}".prop_map(|password| ClientMsg::Login { password }),
        (unit(), unit(), unit(), unit()).prop_map(|(surge, sway, heave_up, yaw)| {
            ClientMsg::Sticks {
                surge,
                sway,
                heave_up,
                yaw,
            }
        }),
        (unit(), unit(), unit()).prop_map(|(port, vertical, starboard)| ClientMsg::Thrusters {
            port,
            vertical,
            starboard
        }),
        Just(ClientMsg::Stop {}),
        Just(ClientMsg::FocusLost {}),
        prop::sample::select(vec![
            InputMode::Keyboard,
            InputMode::Touch,
            InputMode::Gamepad,
            InputMode::Headtracking
        ])
        .prop_map(|mode| ClientMsg::InputMode { mode }),
        any::<bool>().prop_map(|arm| ClientMsg::Arm { arm }),
        prop::sample::select(modes).prop_map(|mode| ClientMsg::Mode { mode }),
        prop::sample::select(vec![RunMode::Normal, RunMode::Simulator])
            .prop_map(|mode| ClientMsg::RunMode { mode }),
        (prop::option::of(0.0f64..=1000.0), 0.0f64..=360.0).prop_map(|(depth_m, h)| {
            ClientMsg::AutopilotTarget {
                depth_m,
                heading_deg: Some(h),
            }
        }),
        (0.0f64..=1.0).prop_map(|value| ClientMsg::Gain { value }),
        (0.0f64..=255.0).prop_map(|level| ClientMsg::Lights { level }),
        any::<bool>().prop_map(|on| ClientMsg::Laser { on }),
        (-90.0f64..=90.0).prop_map(|deg| ClientMsg::Tilt { deg }),
        any::<bool>().prop_map(|takeover_allowed| ClientMsg::RequestControl { takeover_allowed }),
        Just(ClientMsg::ReleaseControl {}),
        any::<bool>().prop_map(|accept| ClientMsg::AnswerRequest { accept }),
    ]
}

fn id() -> impl Strategy<Value = String> {
    "[ -~]{0,20}"
}

fn bind() -> impl Strategy<Value = Bind> {
    (id(), id(), id()).prop_map(|(consumer_id, producer_id, session_id)| Bind {
        consumer_id,
        producer_id,
        session_id,
    })
}

fn signalling_msg() -> impl Strategy<Value = Message> {
    let text = ".{0,60}";
    prop_oneof![
        Just(Message::Question(Question::PeerId)),
        Just(Message::Question(Question::AvailableStreams)),
        (id(), id()).prop_map(|(consumer_id, producer_id)| Message::Question(
            Question::StartSession(BindOffer {
                consumer_id,
                producer_id
            })
        )),
        (bind(), text).prop_map(|(bind, reason)| Message::Question(Question::EndSession(
            EndSession { bind, reason }
        ))),
        id().prop_map(|id| Message::Answer(Answer::PeerId(PeerIdAnswer { id }))),
        bind().prop_map(|b| Message::Answer(Answer::StartSession(b))),
        (bind(), text, any::<bool>()).prop_map(|(bind, sdp, offer)| {
            let sdp = if offer {
                SessionDescription::Offer { sdp }
            } else {
                SessionDescription::Answer { sdp }
            };
            Message::Negotiation(Negotiation::MediaNegotiation(MediaNegotiation {
                bind,
                sdp,
            }))
        }),
        (
            bind(),
            prop::option::of(text),
            prop::option::of(id()),
            prop::option::of(any::<u32>()),
            prop::option::of(id())
        )
            .prop_map(
                |(bind, candidate, sdp_mid, sdp_m_line_index, username_fragment)| {
                    Message::Negotiation(Negotiation::IceNegotiation(IceNegotiation {
                        bind,
                        ice: IceCandidate {
                            candidate,
                            sdp_mid,
                            sdp_m_line_index,
                            username_fragment,
                        },
                    }))
                }
            ),
        text.prop_map(Message::Error),
    ]
}

proptest! {
    /// The browser's messages, written as JSON, parse back to themselves.
    #[test]
    fn hmi_messages_round_trip(msg in client_msg()) {
        let text = serde_json::to_string(&msg).unwrap();
        prop_assert_eq!(ClientMsg::parse(&text), Ok(msg));
    }

    /// Signalling messages, written as on the socket, parse back to themselves.
    #[test]
    fn signalling_messages_round_trip(msg in signalling_msg()) {
        prop_assert_eq!(Message::parse(&msg.to_json()), Ok(msg));
    }
}

fn host_name() -> impl Strategy<Value = String> {
    "[a-z0-9]([a-z0-9-]{0,10}[a-z0-9])?(\\.[a-z0-9]{1,8}){0,3}"
}

proptest! {
    /// Endpoint URLs (IP literals and serial devices: a name would be
    /// looked up) written back read the same.
    #[test]
    fn endpoint_urls_round_trip(
        kind in 0usize..5,
        addr in socket_addr(),
        path in "/dev/[a-zA-Z0-9_./-]{1,20}",
        baud in 1u32..4_000_000,
        trusted in any::<bool>(),
    ) {
        let spec = match kind {
            0 => EndpointSpec::UdpIn(addr),
            1 => EndpointSpec::UdpOut(addr),
            2 => EndpointSpec::TcpIn(addr),
            3 => EndpointSpec::TcpOut(addr),
            _ => EndpointSpec::Serial { path: path.into(), baud },
        };
        let url = EndpointUrl { spec, trusted };
        prop_assert_eq!(url.to_string().parse::<EndpointUrl>().unwrap(), url);
    }

    /// RTP destinations and the signalling address written back read the same.
    #[test]
    fn video_addresses_round_trip(host in host_name(), v6 in any::<[u8; 16]>(), port in 1u16..) {
        for host in [host, std::net::Ipv6Addr::from(v6).to_string()] {
            let d = RtpDest::Udp { host, port };
            prop_assert_eq!(d.to_string().parse::<RtpDest>(), Ok(d));
        }
        let a = SignallingAddr::At(SocketAddr::from((v6, port)));
        prop_assert_eq!(a.to_string().parse::<SignallingAddr>(), Ok(a));
    }

    /// An origin as a user writes it parses to its normal form, which parses
    /// to itself, and admits its host and its page.
    #[test]
    fn origins_and_hosts_round_trip(
        tls in any::<bool>(),
        host in host_name(),
        port in prop::option::of(any::<u16>()),
        upper in any::<bool>(),
        other_port in any::<u16>(),
    ) {
        let scheme = if tls { "https" } else { "http" };
        let hostport = port.map_or(host.clone(), |p| format!("{host}:{p}"));
        let written = format!("{scheme}://{hostport}/");
        let written = if upper { written.to_ascii_uppercase() } else { written };
        let origin = parse_origin(&written).unwrap();
        prop_assert_eq!(parse_origin(&origin), Ok(origin.clone()));
        let gate = Gate::new(std::slice::from_ref(&origin), None);
        prop_assert!(gate.host_ok(&hostport));
        prop_assert!(gate.origin_ok(written.trim_end_matches('/'), None, tls));
        prop_assert!(plain_host(&hostport));
        let moved = with_port(&hostport, other_port, tls).unwrap();
        prop_assert!(gate.host_ok(&moved));
        let page = format!("{scheme}://{moved}");
        prop_assert!(gate.origin_ok(&page, Some(&moved), tls));
    }

    /// The login cookie as the vehicle sets it is read back among others.
    #[test]
    fn the_login_cookie_reads_back(token in "[0-9a-f]{64}", before in "[a-z]{1,8}=[a-z0-9]{0,8}") {
        let header = format!("{before}; {COOKIE}={token}; theme=dark");
        prop_assert_eq!(cookie_value(&header, COOKIE), Some(token.as_str()));
    }

    /// A REST path names the message it was written with.
    #[test]
    fn mavlink2rest_paths_name_their_message(s in any::<u8>(), c in any::<u8>(), name in "[A-Z_0-9]{1,30}", field in "(/message/[a-z_]{1,10})?") {
        let path = format!("vehicles/{s}/components/{c}/messages/{name}{field}");
        prop_assert_eq!(m2r_wanted(&path, 1), (s, c, name.as_str()));
    }
}
