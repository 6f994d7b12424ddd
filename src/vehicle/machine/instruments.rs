//! What an ArduSub ground station's instruments read beyond the core
//! telemetry: AHRS2 (Cockpit's depth indicator), EKF_STATUS_REPORT (the
//! estimator's health) and SCALED_PRESSURE (the first barometer slot).
//!
//! Built from the same fresh readings and estimates as the rest of the
//! telemetry: nothing is sent when there is nothing honest to send.

use super::{Now, Vehicle};
use crate::dialect::neptunus::*;

impl Vehicle {
    pub(super) fn build_instruments(&self, id: u32, now: Now) -> Option<MavMessage> {
        use mavlink_core::MessageData;
        match id {
            AHRS2_DATA::ID => self.ahrs2(now),
            EKF_STATUS_REPORT_DATA::ID => Some(self.ekf_status_report(now)),
            // The board has one pressure sensor, the depth sensor: ArduSub
            // reports it as SCALED_PRESSURE2 (the external sensor, Cockpit's
            // water temperature) and, when it is the only one, as SCALED_PRESSURE.
            SCALED_PRESSURE_DATA::ID if self.fresh(&self.board.water, now) => {
                let (pres, temp) = self.board.water.value;
                Some(MavMessage::SCALED_PRESSURE(SCALED_PRESSURE_DATA {
                    time_boot_ms: self.boot_ms(now),
                    press_abs: pres as f32,
                    press_diff: 0.0,
                    temperature: temp.map_or(0, |t| (t * 100.0).round() as i16),
                    temperature_press_diff: 0,
                }))
            }
            _ => None,
        }
    }

    /// AHRS2: attitude and altitude (−depth, m) — only with a fresh depth
    /// (Cockpit's depth indicator reads it); the angles are NaN while the
    /// heading is stale. No position: lat/lng 0, as ArduSub without GPS.
    fn ahrs2(&self, now: Now) -> Option<MavMessage> {
        if !self.fresh(&self.board.depth_m, now) {
            return None;
        }
        let e = self.holds.est.estimate(now.mono);
        let depth_m = if self.holds.est.depth_filter().initialised() {
            e.depth_m
        } else {
            self.board.depth_m.value
        };
        let (roll, pitch, yaw) = if self.fresh(&self.board.heading_deg, now) {
            let heading_deg = if self.holds.est.heading_filter().initialised() {
                e.heading_deg
            } else {
                self.board.heading_deg.value
            };
            (
                self.board.roll_deg.value.to_radians() as f32,
                self.board.pitch_deg.value.to_radians() as f32,
                ((heading_deg + 180.0).rem_euclid(360.0) - 180.0).to_radians() as f32,
            )
        } else {
            (f32::NAN, f32::NAN, f32::NAN)
        };
        Some(MavMessage::AHRS2(AHRS2_DATA {
            roll,
            pitch,
            yaw,
            altitude: -depth_m as f32,
            lat: 0,
            lng: 0,
        }))
    }

    /// EKF_STATUS_REPORT from the depth and heading filters: ATTITUDE while
    /// the heading estimate is valid, VELOCITY_VERT and POS_VERT_ABS while
    /// the depth estimate is; CONST_POS_MODE always once running (no
    /// horizontal position, as ArduSub without a positioning system);
    /// UNINITIALIZED until a filter has started. The variances are the
    /// filters' own (m², m²/s², rad²), not ArduPilot's normalised test
    /// ratios: small numbers read as healthy either way.
    fn ekf_status_report(&self, now: Now) -> MavMessage {
        use EkfStatusFlags as F;
        let e = self.holds.est.estimate(now.mono);
        let depth = self.holds.est.depth_filter();
        let heading = self.holds.est.heading_filter();
        let mut flags = F::empty();
        if e.heading_valid {
            flags |= F::EKF_ATTITUDE;
        }
        if e.depth_valid {
            flags |= F::EKF_VELOCITY_VERT | F::EKF_POS_VERT_ABS;
        }
        if depth.initialised() || heading.initialised() {
            flags |= F::EKF_CONST_POS_MODE;
        } else {
            flags |= F::EKF_UNINITIALIZED;
        }
        let var = |v: f64, ok: bool| if ok { v as f32 } else { 0.0 };
        MavMessage::EKF_STATUS_REPORT(EKF_STATUS_REPORT_DATA {
            velocity_variance: var(depth.rate_variance(), depth.initialised()),
            pos_horiz_variance: 0.0,
            pos_vert_variance: var(e.depth_std_m.powi(2), depth.initialised()),
            compass_variance: var(
                e.heading_std_deg.to_radians().powi(2),
                heading.initialised(),
            ),
            terrain_alt_variance: 0.0,
            flags,
            airspeed_variance: 0.0,
        })
    }
}
