//! The fuzz targets' seeds (`fuzz/seeds/TARGET/`) are written by this file
//! from Neptunus' own encoders and samples of what each parser reads, so
//! they are ours and follow the formats when those change:
//! `UPDATE_SEEDS=1 cargo test --test fuzz_seeds` rewrites them, and the
//! test fails while they are out of date. Every target of
//! `fuzz/Cargo.toml` must have seeds.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use jpeg_encoder::{ColorType, Encoder};
use mavlink_core::Message as _;
use neptunus::dialect::neptunus::{
    COMMAND_LONG_DATA, HEARTBEAT_DATA, MANUAL_CONTROL_DATA, MavAutopilot, MavCmd, MavMessage,
    MavModeFlag, MavState, MavType, PARAM_SET_DATA, STATUSTEXT_DATA,
};
use neptunus::fuzzing::{binding_request, stun_binding_success};
use neptunus::mavlink::encode_v2;

type Seeds = BTreeMap<&'static str, Vec<(String, Vec<u8>)>>;

fn seeds_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/seeds")
}

fn add(
    seeds: &mut Seeds,
    target: &'static str,
    name: impl Into<String>,
    bytes: impl Into<Vec<u8>>,
) {
    seeds
        .entry(target)
        .or_default()
        .push((name.into(), bytes.into()));
}

/// A seed that starts with `prefix` (a target's leading option bytes).
fn with(prefix: &[u8], rest: &[u8]) -> Vec<u8> {
    [prefix, rest].concat()
}

fn heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 19,
        mavtype: MavType::MAV_TYPE_SUBMARINE,
        autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            | MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED,
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

fn station_messages() -> Vec<MavMessage> {
    let param = PARAM_SET_DATA {
        param_id: "JS_GAIN_DEFAULT".into(),
        param_value: 0.5,
        target_system: 1,
        ..Default::default()
    };
    let text = STATUSTEXT_DATA {
        text: "Depth hold".into(),
        ..Default::default()
    };
    vec![
        heartbeat(),
        MavMessage::MANUAL_CONTROL(MANUAL_CONTROL_DATA {
            target: 1,
            x: 600,
            z: 500,
            ..Default::default()
        }),
        MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            command: MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            param1: 1.0,
            target_system: 1,
            target_component: 1,
            ..Default::default()
        }),
        MavMessage::PARAM_SET(param),
        MavMessage::STATUSTEXT(text),
    ]
}

fn telemetry_lines(s: &mut Seeds) {
    let nav = "hdgd:123.45;deep:1.23;pitc:-2.10;roll:0.50;yaw:-56.20;fthr:0.00;\r\n";
    let status = "vout:12.10;iout:0.75;pres:1013.25;temp:14.50;time:123456.00;fmem:2048.00;\
                  motorAttached:1;servo:1500;starg:1600;mtarg:1500,1400,1600;motors:1500,1500,1500;\
                  ver:2.5.1-abc;BRDT:25.0;BT1I:0.5;BT2I:0.7;\r\n";
    let events = "log:hello world: ok;boot:1;CAPA:63;crc:pass;crc:fail,9E/CB;\
                  cmd:go(1500,1500,1500);rawcmd:6A,67,6F,;pong:1234;LIGT:128;LIGP:0.50;\
                  claser:255;icmd:stop();\r\n";
    add(s, "telemetry_lines", "nav", with(&[255], nav.as_bytes()));
    add(
        s,
        "telemetry_lines",
        "status_in_chunks",
        with(&[7], status.as_bytes()),
    );
    add(
        s,
        "telemetry_lines",
        "events",
        with(&[3], events.as_bytes()),
    );
    let noisy = [
        &b"\x00\xff#garbage\r"[..],
        nav.as_bytes(),
        b"deep:1.2",
        status.as_bytes(),
    ]
    .concat();
    add(s, "telemetry_lines", "noise_and_torn", with(&[1], &noisy));
}

fn mavlink_frames(s: &mut Seeds) {
    let frames: Vec<u8> = station_messages()
        .iter()
        .enumerate()
        .flat_map(|(i, m)| encode_v2(255, 190, i as u8, m))
        .collect();
    add(s, "mavlink_frames", "station", with(&[255], &frames));
    add(
        s,
        "mavlink_frames",
        "station_in_chunks",
        with(&[5], &frames),
    );
    let mut damaged = frames.clone();
    damaged[20] ^= 0x10;
    add(
        s,
        "mavlink_frames",
        "damaged",
        with(&[13], &[&b"\xfd\x09"[..], &damaged].concat()),
    );
}

fn stun_answers(s: &mut Seeds) {
    let id = *b"neptunus-rov";
    let v4 = "192.0.2.1:32853".parse().unwrap();
    let v6 = "[2001:db8::7]:3478".parse().unwrap();
    add(s, "stun_answers", "ipv4", stun_binding_success(id, v4, &[]));
    let software = (0x8022, b"test vector".to_vec());
    add(
        s,
        "stun_answers",
        "ipv6_after_software",
        stun_binding_success(id, v6, &[software]),
    );
    let mut answer = stun_binding_success(id, v4, &[]);
    answer.extend([0x80, 0x28, 0, 4, 0xc0, 0x7d, 0x4c, 0x96]);
    let n = (answer.len() - 20) as u16;
    answer[2..4].copy_from_slice(&n.to_be_bytes());
    add(s, "stun_answers", "ipv4_then_fingerprint", answer);
    add(s, "stun_answers", "request", binding_request(id).to_vec());
    // The layout of the target's second reading: transaction, family,
    // port, address, then (type, length, value) attributes.
    let mut parts = id.to_vec();
    parts.extend([0, 0x80, 0x55, 192, 0, 2, 1]);
    parts.extend([0x80, 0x22, 4, b'n', b'e', b'p', b't']);
    parts.extend([0x80, 0x28, 4, 0xc0, 0x7d, 0x4c, 0x96]);
    add(s, "stun_answers", "parts", parts);
}

const SPS: &[u8] = &[0x67, 0x42, 0xc0, 0x1e, 0xda, 0x02, 0x80];
const PPS: &[u8] = &[0x68, 0xce, 0x3c, 0x80];

fn rtp(seq: u16, ts: u32, marker: bool, payload: &[u8]) -> Vec<u8> {
    let mut p = vec![0x80, if marker { 0xe0 } else { 0x60 }];
    p.extend(seq.to_be_bytes());
    p.extend(ts.to_be_bytes());
    p.extend(0x1234_5678u32.to_be_bytes());
    p.extend(payload);
    p
}

fn rtp_depay(s: &mut Seeds) {
    let mut stap = vec![24];
    for n in [SPS, PPS] {
        stap.extend((n.len() as u16).to_be_bytes());
        stap.extend(n);
    }
    let idr: Vec<u8> = [0x65]
        .into_iter()
        .chain((0..300).map(|i| (i % 251) as u8 | 1))
        .collect();
    let mut packets = vec![rtp(100, 9000, false, &stap)];
    for (i, c) in idr[1..].chunks(120).enumerate() {
        let mut fu = vec![0x7c, 0x05];
        if i == 0 {
            fu[1] |= 0x80;
        }
        if (i + 1) * 120 >= idr.len() - 1 {
            fu[1] |= 0x40;
        }
        fu.extend(c);
        packets.push(rtp(101 + i as u16, 9000, fu[1] & 0x40 != 0, &fu));
    }
    let n = packets.len() as u16;
    packets.push(rtp(100 + n, 12000, true, &[0x41, 0x9a, 0x02, 0x04]));
    let datagrams: Vec<u8> = packets
        .iter()
        .flat_map(|p| [&(p.len() as u16).to_be_bytes()[..], p].concat())
        .collect();
    add(s, "rtp_depay", "keyframe_then_p", datagrams.clone());
    let mut lost = datagrams;
    let second = 2 + packets[0].len();
    lost.drain(second..second + 2 + packets[1].len());
    add(s, "rtp_depay", "a_fragment_lost", lost);
    // The layout of the target's second reading: a stream description.
    add(
        s,
        "rtp_depay",
        "stream",
        vec![
            0, 7, 0, 0, 1, 0, 0, 3, 0, 100, 0x05, 0x65, 40, 9, 0x61, 3, 1, 0, 40, 0x01, 0x41, 2, 7,
        ],
    );
}

fn jpeg(w: u16, h: u16, tweak: impl FnOnce(&mut Encoder<&mut Vec<u8>>)) -> Vec<u8> {
    let rgb: Vec<u8> = (0..usize::from(w) * usize::from(h) * 3)
        .map(|i| (i * 7 % 251) as u8)
        .collect();
    let mut out = Vec::new();
    let mut enc = Encoder::new(&mut out, 60);
    tweak(&mut enc);
    enc.encode(&rgb, w, h, ColorType::Rgb).unwrap();
    out
}

fn mjpeg_split(s: &mut Seeds) {
    let part = |j: &[u8]| {
        [
            format!(
                "--boundarydonotcross\r\nContent-Type: image/jpeg\r\nContent-Length: {}\r\n\r\n",
                j.len()
            )
            .as_bytes(),
            j,
            b"\r\n",
        ]
        .concat()
    };
    let plain = jpeg(16, 8, |_| {});
    let progressive = jpeg(8, 8, |e| e.set_progressive(true));
    let restarts = jpeg(16, 16, |e| e.set_restart_interval(1));
    let app = jpeg(8, 8, |e| {
        e.add_app_segment(3, vec![0xFF, 0xD8, 0xFF, 0xD9]).unwrap()
    });
    add(s, "mjpeg_split", "one_frame", with(&[255, 0], &plain));
    add(
        s,
        "mjpeg_split",
        "multipart",
        with(&[17, 0], &[part(&plain), part(&progressive)].concat()),
    );
    add(
        s,
        "mjpeg_split",
        "restarts_and_app",
        with(&[3, 0], &[restarts, app].concat()),
    );
    let truncated = [&plain[..plain.len() / 2], &progressive].concat();
    add(
        s,
        "mjpeg_split",
        "truncated_small_limit",
        with(&[64, 40], &truncated),
    );
}

fn http_gate(s: &mut Seeds) {
    for (name, flags, port, lines) in [
        (
            "own_page",
            0,
            8080u16,
            "192.168.2.2:8080\nhttp://192.168.2.2:8080\n\nrov\nneptunus_login=abc; theme=dark",
        ),
        (
            "rebinding",
            0,
            80,
            "evil.example.com\nhttp://evil.example.com\nhttp://topside.local:8080\nrov\nIf-None-Match: *",
        ),
        (
            "tls_v6",
            1,
            6021,
            "[::1]:6021\nhttps://[::1]:8443\nhttps://Topside.example:8443/\nrov.local\nW/\"00\", *",
        ),
        (
            "m2r_path",
            0,
            8080,
            "ROV.local.\nnull\nftp://x\n\nvehicles/1/components/1/messages/ATTITUDE/message/roll",
        ),
        (
            "redirect",
            1,
            443,
            "localhost:443\nhttps://localhost\n\n\nHost: rov.local:8443\r\nX: y",
        ),
    ] {
        let [hi, lo] = port.to_be_bytes();
        add(
            s,
            "http_gate",
            name,
            with(&[flags, hi, lo], lines.as_bytes()),
        );
    }
}

fn m2r_json(s: &mut Seeds) {
    for (name, text) in [
        (
            "cockpit_param_set",
            r#"{"header":{"system_id":255,"component_id":240,"sequence":0},"message":{"type":"PARAM_SET","param_value":3,"target_system":1,"target_component":0,"param_id":["B","T","N","5","_","S","F","U","N","C","T","I","O","N","\u0000","\u0000"],"param_type":{"type":"MAV_PARAM_TYPE_INT8"}}}"#,
        ),
        (
            "cockpit_manual_control",
            r#"{"header":{"system_id":255,"component_id":240,"sequence":7},"message":{"type":"MANUAL_CONTROL","target":1,"x":600,"y":0,"z":500,"r":0,"s":0,"t":0,"buttons":0,"buttons2":0,"enabled_extensions":0}}"#,
        ),
        (
            "cockpit_heartbeat",
            r#"{"header":{"system_id":255,"component_id":240,"sequence":1},"message":{"type":"HEARTBEAT","custom_mode":0,"mavtype":{"type":"MAV_TYPE_GCS"},"autopilot":{"type":"MAV_AUTOPILOT_INVALID"},"base_mode":{"bits":192},"system_status":{"type":"MAV_STATE_ACTIVE"},"mavlink_version":3}}"#,
        ),
        (
            "command_long",
            r#"{"header":{"system_id":255,"component_id":240,"sequence":2},"message":{"type":"COMMAND_LONG","target_system":1,"target_component":1,"command":{"type":"MAV_CMD_COMPONENT_ARM_DISARM"},"confirmation":0,"param1":1.0,"param2":0.0,"param3":0.0,"param4":0.0,"param5":0.0,"param6":0.0,"param7":0.0}}"#,
        ),
        ("login", r#"{"password":"correct horse"}"#),
    ] {
        add(s, "m2r_json", name, with(&[0], text.as_bytes()));
    }
    // A message as its id's place among the dialect's messages and its payload.
    let all = MavMessage::all_messages();
    for m in station_messages().iter().chain([&heartbeat()]) {
        let index = all
            .iter()
            .position(|(_, id)| *id == m.message_id())
            .unwrap() as u16;
        let raw = encode_v2(1, 1, 0, m);
        let payload = &raw[10..raw.len() - 2];
        add(
            s,
            "m2r_json",
            format!("payload_{}", m.message_name().to_ascii_lowercase()),
            with(&[1, (index >> 8) as u8, index as u8], payload),
        );
    }
}

fn hmi_messages(s: &mut Seeds) {
    for (name, text) in [
        (
            "sticks",
            r#"{"type":"sticks","surge":0.5,"sway":0,"heave_up":-0.25,"yaw":1}"#,
        ),
        (
            "thrusters",
            r#"{"type":"thrusters","port":0.1,"vertical":-1,"starboard":0.1}"#,
        ),
        (
            "autopilot_target",
            r#"{"type":"autopilot_target","depth_m":2.5,"heading_deg":null}"#,
        ),
        ("mode", r#"{"type":"mode","mode":19}"#),
        ("login", r#"{"type":"login","password":"correct horse"}"#),
        (
            "request_control",
            r#"{"type":"request_control","takeover_allowed":true}"#,
        ),
        ("input_mode", r#"{"type":"input_mode","mode":"gamepad"}"#),
        ("out_of_range", r#"{"type":"tilt","deg":1e999}"#),
    ] {
        add(s, "hmi_messages", name, text.as_bytes());
    }
}

fn webrtc_signalling(s: &mut Seeds) {
    let session = r#""consumer_id":"id1","producer_id":"cam","session_id":"id2""#;
    let lines = [
        r#"{"type":"question","content":{"type":"peerId"}}"#.to_owned(),
        r#"{"type":"question","content":{"type":"availableStreams"}}"#.to_owned(),
        r#"{"type":"question","content":{"type":"startSession","content":{"consumer_id":"id1","producer_id":"cam"}}}"#.to_owned(),
        format!(r#"{{"type":"negotiation","content":{{"type":"mediaNegotiation","content":{{{session},"sdp":{{"type":"answer","sdp":"v=0\r\n"}}}}}}}}"#),
        format!(r#"{{"type":"negotiation","content":{{"type":"iceNegotiation","content":{{{session},"ice":{{"candidate":"candidate:1 1 udp 2130706431 192.168.2.1 50000 typ host","sdpMid":"0","sdpMLineIndex":0,"usernameFragment":"u"}}}}}}}}"#),
        format!(r#"{{"type":"question","content":{{"type":"endSession","content":{{{session},"reason":"done"}}}}}}"#),
    ];
    add(s, "webrtc_signalling", "cockpit_session", lines.join("\n"));
    add(
        s,
        "webrtc_signalling",
        "foreign_session",
        [lines[2].as_str(), &lines[4].replace("id2", "id9")].join("\n"),
    );
}

fn config_values(s: &mut Seeds) {
    let file = "sim = false\ndata_dir = \"/var/lib/neptunus\"\n\n[board]\nserial = \"/dev/ttyO1\"\nbaud = 115200\n\
                framing = \"crc8\"\n\n[mavlink]\nendpoints = [\"udpout:127.0.0.1:14550\", \"tcpin:0.0.0.0:5760\"]\n\
                sysid = 1\npeer_timeout_s = 10.0\n\n[hmi]\nhttp = \"0.0.0.0:8080\"\nallowed_origins = [\"https://topside.local:8443\"]\n\
                tls = \"off\"\n\n[emulator.faults]\ngarbage = 0.01\n\n[camera]\nsource = \"synthetic\"\n";
    add(s, "config_values", "file", file.as_bytes());
    let values = "udp://192.168.2.1:5600\nudp://[fe80::1]:5600\nauto\nstun:stun.example.org:19302\n\
                  turns:[2001:db8::1]?transport=tcp\n0.0.0.0:6021\noff\nhttps://Topside.local:8443/";
    add(s, "config_values", "values", values.as_bytes());
}

/// One MAVLink FTP request payload (251 bytes): the header (sequence,
/// session, opcode, size, offset) and its data.
fn ftp_request(seq: u16, session: u8, opcode: u8, offset: u32, data: &[u8]) -> Vec<u8> {
    let mut p = vec![0u8; neptunus::mavlink::ftp::PAYLOAD_LEN];
    p[0..2].copy_from_slice(&seq.to_le_bytes());
    p[2] = session;
    p[3] = opcode;
    p[4] = u8::try_from(data.len()).unwrap();
    p[8..12].copy_from_slice(&offset.to_le_bytes());
    p[12..12 + data.len()].copy_from_slice(data);
    p
}

fn ftp_requests(s: &mut Seeds) {
    use neptunus::mavlink::ftp::op;
    let list = ftp_request(0, 0, op::LIST_DIRECTORY, 0, b"/");
    add(s, "ftp_requests", "list_root", list.clone());
    let fetch = [
        ftp_request(1, 0, op::OPEN_FILE_RO, 0, b"/component/general.json"),
        ftp_request(2, 0, op::BURST_READ_FILE, 0, &[]),
        ftp_request(3, 0, op::READ_FILE, 239, &[]),
        ftp_request(4, 0, op::CALC_FILE_CRC32, 0, b"/component/general.json"),
        ftp_request(5, 0, op::TERMINATE_SESSION, 0, &[]),
    ]
    .concat();
    add(s, "ftp_requests", "fetch_metadata", fetch);
    let tricks = [
        ftp_request(6, 0, op::LIST_DIRECTORY, 0, b"/logs/../component"),
        ftp_request(7, 0, op::OPEN_FILE_RO, 0, b"/recordings/.hidden"),
        ftp_request(8, 9, op::READ_FILE, 1 << 30, &[]),
        ftp_request(9, 0, op::REMOVE_FILE, 0, b"/logs/x.tlog"),
        ftp_request(10, 0, op::RESET_SESSIONS, 0, &[]),
    ]
    .concat();
    add(s, "ftp_requests", "tricks", tricks);
}

/// One settings-bag operation as the target reads it: path length, writer,
/// body length, the path, the body.
fn bag_op(path: &str, who: u8, body: &[u8]) -> Vec<u8> {
    let mut v = vec![
        u8::try_from(path.len()).unwrap(),
        who,
        u8::try_from(body.len()).unwrap(),
    ];
    v.extend_from_slice(path.as_bytes());
    v.extend_from_slice(body);
    v
}

fn bag_paths(s: &mut Seeds) {
    add(
        s,
        "bag_paths",
        "cockpit_start",
        [
            bag_op("cockpit/cockpit-vehicle-id", 0, br#""3b9a1c2e""#),
            bag_op(
                "cockpit/settings-v2/pilot/theme",
                0,
                br#"{"dark":true,"size":1.5}"#,
            ),
            bag_op("cockpit/settings-v2/guest/theme", 1, br#"{"dark":false}"#),
        ]
        .concat(),
    );
    add(
        s,
        "bag_paths",
        "tricks",
        [
            bag_op("cockpit/../etc/passwd", 0, b"1"),
            bag_op("cockpit//x", 2, b"{"),
            bag_op("cockpit/settings-v2/guest/big", 3, &[b'7'; 200]),
        ]
        .concat(),
    );
}

fn generate() -> Seeds {
    let mut s = Seeds::new();
    telemetry_lines(&mut s);
    mavlink_frames(&mut s);
    stun_answers(&mut s);
    rtp_depay(&mut s);
    mjpeg_split(&mut s);
    http_gate(&mut s);
    m2r_json(&mut s);
    hmi_messages(&mut s);
    webrtc_signalling(&mut s);
    config_values(&mut s);
    ftp_requests(&mut s);
    bag_paths(&mut s);
    s
}

/// The targets `fuzz/Cargo.toml` lists: name and source.
fn targets() -> Vec<(String, String)> {
    let manifest =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/Cargo.toml"))
            .unwrap();
    let doc: toml::Table = manifest.parse().unwrap();
    doc["bin"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| {
            let field = |k: &str| b[k].as_str().unwrap().to_owned();
            (field("name"), field("path"))
        })
        .collect()
}

#[test]
fn the_seeds_are_what_this_file_writes() {
    let update = std::env::var_os("UPDATE_SEEDS").is_some();
    let mut stale = Vec::new();
    for (target, files) in generate() {
        let dir = seeds_dir().join(target);
        if update {
            std::fs::create_dir_all(&dir).unwrap();
        }
        for (name, bytes) in files {
            let path = dir.join(&name);
            if std::fs::read(&path).ok().as_deref() != Some(&bytes[..]) {
                if update {
                    std::fs::write(&path, &bytes).unwrap();
                } else {
                    stale.push(format!("{target}/{name}"));
                }
            }
        }
    }
    assert!(
        stale.is_empty(),
        "fuzz/seeds is out of date ({}): run UPDATE_SEEDS=1 cargo test --test fuzz_seeds",
        stale.join(", ")
    );
}

#[test]
fn every_fuzz_target_has_seeds() {
    let targets = targets();
    assert!(targets.len() >= 10, "{targets:?}");
    for (t, source) in targets {
        let dir = seeds_dir().join(&t);
        let n = std::fs::read_dir(&dir).map(|d| d.count()).unwrap_or(0);
        assert!(n > 0, "fuzz target {t} has no seeds in {}", dir.display());
        let source = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("fuzz")
            .join(source);
        assert!(source.exists(), "{}", source.display());
    }
}
