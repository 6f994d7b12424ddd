//! What a session sends the vehicle: MAVLink as a ground station would,
//! built from plain values.
//!
//! Owns the HMI's telemetry-rate request ([`request_rates`]), the session's
//! HEARTBEAT (only while the browser shows life), COMMAND_LONG, MANUAL_CONTROL
//! and per-thruster messages, and the neutral `stop`. Never invents pilot
//! input: only `stop` sends sticks of its own, and only from the station in
//! control.

use mavlink_core::MessageData;

use super::{BROWSER_LIFE, Session};
use crate::dialect::neptunus::*;
use crate::hmi::Shared;
use crate::vehicle::machine::{CAMERA_COMPONENT_ID, COMPONENT_ID, HmiEvent, Input};

/// Telemetry rates this HMI asks the vehicle for on its endpoint (msg id, Hz),
/// once, from the server's own peer (see [`request_rates`]). What the
/// board's navigation line makes goes out as each line arrives, at most at
/// its rate: 10 Hz is the OpenROV board's line rate (faster would only
/// repeat the same values between lines).
const RATES: [(u32, f32); 8] = [
    // Heading, roll, pitch.
    (ATTITUDE_DATA::ID, 10.0),
    // Depth.
    (VFR_HUD_DATA::ID, 10.0),
    // Thrusters.
    (SERVO_OUTPUT_RAW_DATA::ID, 10.0),
    // Health, voltage, current.
    (SYS_STATUS_DATA::ID, 4.0),
    // Lights, gain, tilt.
    (NAMED_VALUE_FLOAT_DATA::ID, 4.0),
    // The emulator's ground truth changes ten times a second.
    (NEPTUNUS_SIM_STATE_DATA::ID, 10.0),
    (NEPTUNUS_ESTIMATE_DATA::ID, 10.0),
    (NEPTUNUS_AUTOPILOT_DATA::ID, 10.0),
];

/// Asks the vehicle for the HMI's telemetry rates on its endpoint, once at
/// start, from the server's own peer (a signed pilot: see
/// [`Shared::server_sender`]). Sessions do not ask: the core refuses rate
/// changes from stations that may not control, and a watcher may not.
pub(crate) async fn request_rates(shared: &Shared) {
    let from = shared.server_sender();
    for (id, hz) in RATES {
        let msg = command_long(
            shared.vehicle_sysid,
            COMPONENT_ID,
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            [id as f32, 1e6 / hz],
        );
        let _ = shared.inputs.send(Input::Mavlink { from, msg }).await;
    }
}

/// COMMAND_LONG to the vehicle with the first params given, the rest 0.
fn command_long<const N: usize>(
    target: u8,
    component: u8,
    command: MavCmd,
    params: [f32; N],
) -> MavMessage {
    let mut p = [0f32; 7];
    p[..N].copy_from_slice(&params);
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        param1: p[0],
        param2: p[1],
        param3: p[2],
        param4: p[3],
        param5: p[4],
        param6: p[5],
        param7: p[6],
        command,
        target_system: target,
        target_component: component,
        confirmation: 0,
    })
}

impl Session {
    /// Hands a message to the vehicle as coming from this session.
    pub(super) async fn to_vehicle(&self, msg: MavMessage) {
        // A watcher with no system id has none to speak with (sysid 0 would be
        // the broadcast address); it only asks for telemetry.
        let sysid = self.sysid().unwrap_or(0);
        let from = self
            .shared
            .sender(self.id, sysid, self.may_pilot(), self.logged_in);
        let _ = self.shared.inputs.send(Input::Mavlink { from, msg }).await;
    }

    /// Asks the camera (component 100) for CAMERA_INFORMATION (can it
    /// record?) and CAMERA_CAPTURE_STATUS (does it now?); the answers come
    /// to this session alone. A vehicle without a camera does not answer.
    pub(super) async fn ask_camera(&self) {
        for id in [CAMERA_INFORMATION_DATA::ID, CAMERA_CAPTURE_STATUS_DATA::ID] {
            self.command_to(
                CAMERA_COMPONENT_ID,
                MavCmd::MAV_CMD_REQUEST_MESSAGE,
                [id as f32],
            )
            .await;
        }
    }

    pub(super) async fn hmi_event(&self, event: HmiEvent) {
        if let Some(sysid) = self.sysid() {
            let _ = self.shared.inputs.send(Input::Hmi { sysid, event }).await;
        }
    }

    pub(super) async fn heartbeat(&self) {
        if self.sysid().is_none() || self.last_life.elapsed() > BROWSER_LIFE {
            return;
        }
        self.to_vehicle(MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            // A ground station has no mode.
            custom_mode: 0,
            mavtype: MavType::MAV_TYPE_GCS,
            autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
            base_mode: MavModeFlag::empty(),
            system_status: MavState::MAV_STATE_ACTIVE,
            mavlink_version: 3,
        }))
        .await;
    }

    /// COMMAND_LONG to the vehicle with the first params given, the rest 0.
    pub(super) async fn command<const N: usize>(&self, command: MavCmd, params: [f32; N]) {
        self.command_to(COMPONENT_ID, command, params).await;
    }

    /// A command to another component of the vehicle (the camera).
    pub(super) async fn command_to<const N: usize>(
        &self,
        component: u8,
        command: MavCmd,
        params: [f32; N],
    ) {
        self.to_vehicle(command_long(
            self.shared.vehicle_sysid,
            component,
            command,
            params,
        ))
        .await;
    }

    pub(super) fn manual_control(
        &self,
        surge: f64,
        sway: f64,
        heave_up: f64,
        yaw: f64,
    ) -> MavMessage {
        let axis = |v: f64| (v.clamp(-1.0, 1.0) * 1000.0).round() as i16;
        let centred = self.sysid().is_some_and(|s| (self.shared.z_centered)(s));
        let z = if centred {
            axis(heave_up)
        } else {
            // ArduSub's 0..1000 with 500 neutral.
            (500.0 + heave_up.clamp(-1.0, 1.0) * 500.0).round() as i16
        };
        MavMessage::MANUAL_CONTROL(MANUAL_CONTROL_DATA {
            x: axis(surge),
            y: axis(sway),
            z,
            r: axis(yaw),
            target: self.shared.vehicle_sysid,
            ..Default::default()
        })
    }

    pub(super) fn thrusters(&self, port: f64, vertical: f64, starboard: f64) -> MavMessage {
        MavMessage::NEPTUNUS_THRUSTERS(NEPTUNUS_THRUSTERS_DATA {
            target_system: self.shared.vehicle_sysid,
            target_component: COMPONENT_ID,
            port: port as f32,
            vertical: vertical as f32,
            starboard: starboard as f32,
        })
    }

    /// Neutral input, sent only by the station in control: from anyone else
    /// it could claim an unowned vehicle, and there is nothing of theirs to stop.
    pub(super) async fn stop(&self) {
        if self.model.in_control() {
            self.to_vehicle(self.manual_control(0.0, 0.0, 0.0, 0.0))
                .await;
            self.to_vehicle(self.thrusters(0.0, 0.0, 0.0)).await;
        }
    }
}
