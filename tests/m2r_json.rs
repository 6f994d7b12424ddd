//! Golden JSON of the mavlink2rest API (what Cockpit reads and sends), both
//! directions: each message serialises to exactly the golden text, and the
//! golden text parses back to the same message. The shape: messages tagged
//! `{"type":"NAME", …}`, enums `{"type":"ENUM_VALUE"}`, bitflags
//! `{"bits":N}`, char arrays as one-character strings padded with NUL,
//! other arrays as JSON arrays; MAVLink's `type` field spelled `mavtype`.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use neptunus::dialect::neptunus::*;
use neptunus::hmi::m2r::frame::{self, Header, Reserved};

const US: Reserved = Reserved::vehicle(1);

fn golden(msg: MavMessage, text: &str) {
    let json = serde_json::to_string(&msg).unwrap();
    assert_eq!(json, text, "serialised {}", text);
    let back: MavMessage = serde_json::from_str(text).unwrap();
    assert_eq!(back, msg, "parsed back");
}

#[test]
fn heartbeat() {
    golden(
        MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: 19,
            mavtype: MavType::MAV_TYPE_SUBMARINE,
            autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
                | MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED
                | MavModeFlag::MAV_MODE_FLAG_MANUAL_INPUT_ENABLED,
            system_status: MavState::MAV_STATE_ACTIVE,
            mavlink_version: 3,
        }),
        r#"{"type":"HEARTBEAT","custom_mode":19,"mavtype":{"type":"MAV_TYPE_SUBMARINE"},"autopilot":{"type":"MAV_AUTOPILOT_ARDUPILOTMEGA"},"base_mode":{"bits":193},"system_status":{"type":"MAV_STATE_ACTIVE"},"mavlink_version":3}"#,
    );
}

#[test]
fn attitude() {
    golden(
        MavMessage::ATTITUDE(ATTITUDE_DATA {
            time_boot_ms: 123_456,
            roll: 0.5,
            pitch: -0.25,
            yaw: 3.0,
            rollspeed: 0.0,
            pitchspeed: 0.125,
            yawspeed: -1.5,
        }),
        r#"{"type":"ATTITUDE","time_boot_ms":123456,"roll":0.5,"pitch":-0.25,"yaw":3.0,"rollspeed":0.0,"pitchspeed":0.125,"yawspeed":-1.5}"#,
    );
}

#[test]
fn command_long() {
    golden(
        MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            param1: 1.0,
            param2: 21196.0,
            param3: 0.0,
            param4: 0.0,
            param5: 0.0,
            param6: 0.0,
            param7: 0.0,
            command: MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            target_system: 1,
            target_component: 1,
            confirmation: 0,
        }),
        r#"{"type":"COMMAND_LONG","param1":1.0,"param2":21196.0,"param3":0.0,"param4":0.0,"param5":0.0,"param6":0.0,"param7":0.0,"command":{"type":"MAV_CMD_COMPONENT_ARM_DISARM"},"target_system":1,"target_component":1,"confirmation":0}"#,
    );
}

#[test]
fn command_ack() {
    golden(
        MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
            command: MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            result: MavResult::MAV_RESULT_UNSUPPORTED,
            progress: 0,
            result_param2: 0,
            target_system: 255,
            target_component: 240,
        }),
        r#"{"type":"COMMAND_ACK","command":{"type":"MAV_CMD_SET_MESSAGE_INTERVAL"},"result":{"type":"MAV_RESULT_UNSUPPORTED"},"progress":0,"result_param2":0,"target_system":255,"target_component":240}"#,
    );
}

#[test]
fn param_value() {
    golden(
        MavMessage::PARAM_VALUE(PARAM_VALUE_DATA {
            param_value: 4.0,
            param_count: 212,
            param_index: 17,
            param_id: "BTN5_SFUNCTION".into(),
            param_type: MavParamType::MAV_PARAM_TYPE_INT8,
        }),
        r#"{"type":"PARAM_VALUE","param_value":4.0,"param_count":212,"param_index":17,"param_id":["B","T","N","5","_","S","F","U","N","C","T","I","O","N","\u0000","\u0000"],"param_type":{"type":"MAV_PARAM_TYPE_INT8"}}"#,
    );
}

#[test]
fn servo_output_raw() {
    golden(
        MavMessage::SERVO_OUTPUT_RAW(SERVO_OUTPUT_RAW_DATA {
            time_usec: 4_000_000_000,
            servo1_raw: 1500,
            servo2_raw: 1600,
            servo3_raw: 1400,
            port: 0,
            ..Default::default()
        }),
        r#"{"type":"SERVO_OUTPUT_RAW","time_usec":4000000000,"servo1_raw":1500,"servo2_raw":1600,"servo3_raw":1400,"servo4_raw":0,"servo5_raw":0,"servo6_raw":0,"servo7_raw":0,"servo8_raw":0,"port":0,"servo9_raw":0,"servo10_raw":0,"servo11_raw":0,"servo12_raw":0,"servo13_raw":0,"servo14_raw":0,"servo15_raw":0,"servo16_raw":0}"#,
    );
}

#[test]
fn our_own_thrusters_message() {
    golden(
        MavMessage::NEPTUNUS_THRUSTERS(NEPTUNUS_THRUSTERS_DATA {
            port: 0.5,
            vertical: -0.25,
            starboard: 0.5,
            target_system: 1,
            target_component: 1,
        }),
        r#"{"type":"NEPTUNUS_THRUSTERS","port":0.5,"vertical":-0.25,"starboard":0.5,"target_system":1,"target_component":1}"#,
    );
}

#[test]
fn statustext_text_is_an_array_of_characters() {
    let mut s = STATUSTEXT_DATA {
        severity: MavSeverity::MAV_SEVERITY_INFO,
        text: "Armed".into(),
        ..Default::default()
    };
    s.id = 0;
    let v: serde_json::Value = serde_json::to_value(MavMessage::STATUSTEXT(s)).unwrap();
    let text = v["text"].as_array().unwrap();
    assert_eq!(text.len(), 50);
    assert_eq!(text[0], "A");
    assert_eq!(text[5], "\u{0}");
}

/// Cockpit's frames: a header with system 255, component 240; PARAM_SET's
/// `param_id` padded with NUL; MANUAL_CONTROL without the aux extensions.
#[test]
fn cockpit_frames_parse() {
    let f = frame::parse(
        r#"{"header":{"system_id":255,"component_id":240,"sequence":0},"message":{"type":"PARAM_SET","param_value":3,"target_system":1,"target_component":0,"param_id":["B","T","N","5","_","S","F","U","N","C","T","I","O","N","\u0000","\u0000"],"param_type":{"type":"MAV_PARAM_TYPE_INT8"}}}"#,
        US,
    )
    .unwrap();
    assert_eq!(
        f.header,
        Header {
            system_id: 255,
            component_id: 240,
            sequence: 0
        }
    );
    let MavMessage::PARAM_SET(p) = f.message else {
        panic!("not a PARAM_SET");
    };
    assert_eq!(p.param_id.to_str().unwrap(), "BTN5_SFUNCTION");
    assert_eq!(p.param_value, 3.0);

    let f = frame::parse(
        r#"{"header":{"system_id":255,"component_id":240,"sequence":7},"message":{"type":"MANUAL_CONTROL","target":1,"x":600,"y":0,"z":500,"r":0,"s":0,"t":0,"buttons":0,"buttons2":0,"enabled_extensions":0}}"#,
        US,
    )
    .unwrap();
    let MavMessage::MANUAL_CONTROL(m) = f.message else {
        panic!("not a MANUAL_CONTROL");
    };
    assert_eq!((m.x, m.z, m.aux1), (600, 500, 0));
}

#[test]
fn what_does_not_convert() {
    for bad in [
        "not json",
        r#"{"header":{"system_id":255,"component_id":240,"sequence":0},"message":{"type":"NO_SUCH_MESSAGE"}}"#,
        r#"{"header":{"system_id":255,"component_id":240,"sequence":0},"message":{"type":"MANUAL_CONTROL","target":1,"x":"full","y":0,"z":500,"r":0,"buttons":0}}"#,
        r#"{"header":{"system_id":255,"component_id":240,"sequence":0},"message":{"type":"HEARTBEAT","custom_mode":0,"mavtype":{"type":"MAV_TYPE_GCS"},"autopilot":{"type":"MAV_AUTOPILOT_INVALID"},"base_mode":"MAV_MODE_FLAG_SAFETY_ARMED","system_status":{"type":"MAV_STATE_ACTIVE"},"mavlink_version":3}}"#,
        r#"{"message":{"type":"ATTITUDE","time_boot_ms":0,"roll":0,"pitch":0,"yaw":0,"rollspeed":0,"pitchspeed":0,"yawspeed":0}}"#,
        r#"{"header":{"system_id":0,"component_id":240,"sequence":0},"message":{"type":"PARAM_REQUEST_LIST","target_system":1,"target_component":0}}"#,
        r#"{"header":{"system_id":1,"component_id":1,"sequence":0},"message":{"type":"PARAM_REQUEST_LIST","target_system":1,"target_component":0}}"#,
        r#"{"header":{"system_id":255,"component_id":240,"sequence":0},"message":{"type":"PARAM_SET","param_value":3,"target_system":1,"target_component":0,"param_id":["BT","N"],"param_type":{"type":"MAV_PARAM_TYPE_INT8"}}}"#,
    ] {
        assert!(frame::parse(bad, US).is_err(), "accepted: {bad}");
    }
    // Nor may a client speak as a system id the HMI lends its sessions.
    let hmi = Reserved {
        vehicle_sysid: 1,
        hmi_sysids: (200, 209),
    };
    let as_205 = r#"{"header":{"system_id":205,"component_id":190,"sequence":0},"message":{"type":"PARAM_REQUEST_LIST","target_system":1,"target_component":0}}"#;
    assert!(frame::parse(as_205, hmi).is_err());
    assert!(frame::parse(as_205, US).is_ok());
}

/// Every message of the dialect survives JSON both ways (its zeroed example
/// is what `helper/mavlink` serves).
#[test]
fn every_message_round_trips() {
    use mavlink_core::Message as _;
    for (name, id) in MavMessage::all_messages() {
        let msg = MavMessage::default_message_from_id(*id).unwrap();
        let json = serde_json::to_string(&msg).unwrap();
        assert!(
            json.starts_with(&format!("{{\"type\":\"{name}\"")),
            "{json}"
        );
        let back: MavMessage = serde_json::from_str(&json)
            .unwrap_or_else(|e| panic!("{name} does not parse back: {e}\n{json}"));
        assert_eq!(
            serde_json::to_string(&back).unwrap(),
            json,
            "{name} changed on the way back"
        );
    }
}
