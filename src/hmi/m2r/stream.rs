//! What one "stream" of vehicle messages is, for coalescing: the message
//! type, the system and component that sent it, and the instance the
//! message is about — so a newer message replaces only an older one of the
//! same stream, never another battery's, another NAMED_VALUE_FLOAT's or
//! another component's HEARTBEAT.
//!
//! Owns the instance rules. The dialect marks a field `instance="true"` in
//! its XML where one message type carries several independent values; every
//! such message of our dialect is keyed by that field (a unit test reads the
//! XML the build staged and fails when one is missing). A few messages have
//! instances the XML does not mark; they are listed in [`instance`] with
//! why. Pure: no I/O, no clock.

use mavlink_core::Message as _;

use crate::dialect::neptunus::MavMessage;

/// Which of several values of one message type a message carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Instance {
    /// The type has one value per component.
    One,
    /// A numeric instance field (a battery's `id`, a stream's `stream_id`…);
    /// two fields (a camera's device and its stream) as `high << 16 | low`.
    Id(u32),
    /// A name (NAMED_VALUE_FLOAT's `name`), up to its first NUL.
    Name([u8; 10]),
}

/// One stream of messages: what the newest message of replaces.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct StreamKey {
    pub name: &'static str,
    pub system: u8,
    pub component: u8,
    pub instance: Instance,
}

impl StreamKey {
    /// The stream `msg` from `system`/`component` belongs to.
    pub fn of(system: u8, component: u8, msg: &MavMessage) -> Self {
        Self {
            name: msg.message_name(),
            system,
            component,
            instance: instance(msg),
        }
    }
}

fn id(v: impl Into<u32>) -> Instance {
    Instance::Id(v.into())
}

/// A camera's message about one of its streams: both ids count (a camera
/// component gives `camera_device_id` 0; an autopilot speaking for cameras
/// without MAVLink numbers them).
fn camera_stream(camera_device_id: u8, stream_id: u8) -> Instance {
    Instance::Id(u32::from(camera_device_id) << 16 | u32::from(stream_id))
}

fn name(bytes: &[u8]) -> Instance {
    let mut n = [0u8; 10];
    for (dst, src) in n.iter_mut().zip(bytes.iter().take_while(|b| **b != 0)) {
        *dst = *src;
    }
    Instance::Name(n)
}

/// The instance `msg` is about ([`Instance::One`] for a type with one
/// value per component).
// SMART_BATTERY_INFO is deprecated in the XML; a vehicle may still send it.
#[allow(deprecated)]
pub fn instance(msg: &MavMessage) -> Instance {
    use MavMessage as M;
    match msg {
        // Marked `instance="true"` in the dialect's XML.
        M::RAW_IMU(d) => id(d.id),
        M::SERVO_OUTPUT_RAW(d) => id(d.port),
        M::HIGHRES_IMU(d) => id(d.id),
        M::OPTICAL_FLOW_RAD(d) => id(d.sensor_id),
        M::DISTANCE_SENSOR(d) => id(d.id),
        M::BATTERY_STATUS(d) => id(d.id),
        M::MAG_CAL_REPORT(d) => id(d.compass_id),
        M::GPS_INPUT(d) => id(d.gps_id),
        M::DEBUG_VECT(d) => name(&<[u8; 10]>::from(d.name)),
        M::NAMED_VALUE_FLOAT(d) => name(&<[u8; 10]>::from(d.name)),
        M::NAMED_VALUE_INT(d) => name(&<[u8; 10]>::from(d.name)),
        M::STORAGE_INFORMATION(d) => id(d.storage_id),
        M::VIDEO_STREAM_INFORMATION(d) => camera_stream(d.camera_device_id, d.stream_id),
        M::VIDEO_STREAM_STATUS(d) => camera_stream(d.camera_device_id, d.stream_id),
        M::CAMERA_THERMAL_RANGE(d) => camera_stream(d.camera_device_id, d.stream_id),
        M::GIMBAL_MANAGER_INFORMATION(d) => id(d.gimbal_device_id),
        M::GIMBAL_MANAGER_STATUS(d) => id(d.gimbal_device_id),
        M::GIMBAL_MANAGER_SET_ATTITUDE(d) => id(d.gimbal_device_id),
        M::GIMBAL_MANAGER_SET_PITCHYAW(d) => id(d.gimbal_device_id),
        M::GIMBAL_MANAGER_SET_MANUAL_CONTROL(d) => id(d.gimbal_device_id),
        M::ESC_INFO(d) => id(d.index),
        M::ESC_STATUS(d) => id(d.index),
        M::AIRSPEED(d) => id(d.id),
        M::GLOBAL_POSITION_SENSOR(d) => id(d.id),
        M::CELLULAR_STATUS(d) => id(d.id),
        M::DEBUG_FLOAT_ARRAY(d) => id(d.array_id),
        M::SMART_BATTERY_INFO(d) => id(d.id),
        M::FUEL_STATUS(d) => id(d.id),
        M::BATTERY_INFO(d) => id(d.id),
        M::HYGROMETER_SENSOR(d) => id(d.id),
        M::BATTERY_STATUS_V2(d) => id(d.id),
        M::GNSS_INTEGRITY(d) => id(d.id),
        M::TARGET_RELATIVE(d) => id(d.id),
        M::RANGING_BEACON(d) => id(d.beacon_id),
        M::MAG_CAL_PROGRESS(d) => id(d.compass_id),
        M::PID_TUNING(d) => id(d.axis as u8),
        M::ADAP_TUNING(d) => id(d.axis as u8),
        M::OBSTACLE_DISTANCE_3D(d) => id(d.obstacle_id),
        M::WATER_DEPTH(d) => id(d.id),
        M::MCU_STATUS(d) => id(d.id),
        M::NAMED_VALUE_STRING(d) => name(&<[u8; 10]>::from(d.name)),
        M::LOWEHEISER_GOV_EFI(d) => id(d.efi_index),
        // Instances the XML does not mark. A gimbal manager speaking for a
        // gimbal without MAVLink (ours: the camera tilt) numbers it in an
        // extension field.
        M::GIMBAL_DEVICE_ATTITUDE_STATUS(d) => id(d.gimbal_device_id),
        M::GIMBAL_DEVICE_INFORMATION(d) => id(d.gimbal_device_id),
        // The same for cameras without MAVLink.
        M::CAMERA_INFORMATION(d) => camera_stream(d.camera_device_id, 0),
        M::CAMERA_SETTINGS(d) => camera_stream(d.camera_device_id, 0),
        M::CAMERA_CAPTURE_STATUS(d) => camera_stream(d.camera_device_id, 0),
        // One answer per message asked about (GET_MESSAGE_INTERVAL).
        M::MESSAGE_INTERVAL(d) => id(d.message_id),
        // One value per index, as NAMED_VALUE_* per name.
        M::DEBUG(d) => id(d.ind),
        _ => Instance::One,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dialect::neptunus::*;

    /// The XML files the build generated the dialect from.
    const DEFINITIONS: [&str; 10] = [
        include_str!(concat!(env!("OUT_DIR"), "/definitions/minimal.xml")),
        include_str!(concat!(env!("OUT_DIR"), "/definitions/standard.xml")),
        include_str!(concat!(env!("OUT_DIR"), "/definitions/common.xml")),
        include_str!(concat!(env!("OUT_DIR"), "/definitions/development.xml")),
        include_str!(concat!(env!("OUT_DIR"), "/definitions/ardupilotmega.xml")),
        include_str!(concat!(env!("OUT_DIR"), "/definitions/uAvionix.xml")),
        include_str!(concat!(env!("OUT_DIR"), "/definitions/icarous.xml")),
        include_str!(concat!(env!("OUT_DIR"), "/definitions/loweheiser.xml")),
        include_str!(concat!(env!("OUT_DIR"), "/definitions/cubepilot.xml")),
        include_str!(concat!(env!("OUT_DIR"), "/definitions/csAirLink.xml")),
    ];

    /// Names of the messages with a field marked `instance="true"`.
    fn marked_in_xml() -> Vec<String> {
        let mut names = Vec::new();
        for xml in DEFINITIONS {
            for block in xml.split("<message ").skip(1) {
                let block = block.split("</message>").next().unwrap_or_default();
                let name = block
                    .split("name=\"")
                    .nth(1)
                    .and_then(|rest| rest.split('"').next())
                    .unwrap_or_default();
                if block.contains("instance=\"true\"") {
                    names.push(name.to_owned());
                }
            }
        }
        names
    }

    #[test]
    fn every_message_the_dialect_marks_with_an_instance_is_keyed_by_it() {
        let marked = marked_in_xml();
        assert!(
            marked.len() >= 40,
            "the XML scan found only {marked:?}: did the staged definitions move?"
        );
        let missing: Vec<&String> = marked
            .iter()
            .filter(|n| {
                let msg = MavMessage::message_id_from_name(n)
                    .and_then(MavMessage::default_message_from_id);
                msg.is_some_and(|m| instance(&m) == Instance::One)
            })
            .collect();
        assert!(
            missing.is_empty(),
            "messages with instances coalesced as one: {missing:?}"
        );
    }

    fn nvf(n: &str, v: f32) -> MavMessage {
        MavMessage::NAMED_VALUE_FLOAT(NAMED_VALUE_FLOAT_DATA {
            time_boot_ms: 0,
            name: n.into(),
            value: v,
        })
    }

    #[test]
    fn names_ids_and_components_make_streams() {
        let k = |c, m: &MavMessage| StreamKey::of(1, c, m);
        assert_ne!(k(1, &nvf("Lights1", 0.0)), k(1, &nvf("PilotGain", 0.0)));
        assert_eq!(k(1, &nvf("Lights1", 0.0)), k(1, &nvf("Lights1", 1.0)));
        let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA::default());
        assert_ne!(k(1, &hb), k(100, &hb));
        assert_ne!(StreamKey::of(1, 1, &hb), StreamKey::of(2, 1, &hb));
        let battery = |id| {
            MavMessage::BATTERY_STATUS(BATTERY_STATUS_DATA {
                id,
                ..Default::default()
            })
        };
        assert_ne!(k(1, &battery(0)), k(1, &battery(1)));
        let video = |stream_id, camera_device_id| {
            MavMessage::VIDEO_STREAM_INFORMATION(VIDEO_STREAM_INFORMATION_DATA {
                stream_id,
                camera_device_id,
                ..Default::default()
            })
        };
        assert_ne!(k(100, &video(1, 0)), k(100, &video(2, 0)));
        assert_ne!(k(1, &video(1, 1)), k(1, &video(1, 2)));
        let interval = |message_id| {
            MavMessage::MESSAGE_INTERVAL(MESSAGE_INTERVAL_DATA {
                message_id,
                interval_us: 0,
            })
        };
        assert_ne!(k(1, &interval(30)), k(1, &interval(33)));
        // What follows a name's NUL is not part of it.
        let mut raw = [0u8; 10];
        raw[..3].copy_from_slice(b"Abc");
        let mut junk = raw;
        junk[5] = b'x';
        let with = |bytes: [u8; 10]| {
            MavMessage::NAMED_VALUE_FLOAT(NAMED_VALUE_FLOAT_DATA {
                time_boot_ms: 0,
                name: bytes.into(),
                value: 0.0,
            })
        };
        assert_eq!(k(1, &with(raw)), k(1, &with(junk)));
    }
}
