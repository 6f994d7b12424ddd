//! The board emulator, sans-IO: the genuine firmware's replies, byte for
//! byte (`tests/genuine_twin.rs` holds it against the firmware itself in
//! simavr; these pin the details on our own clock, fast).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::time::Duration;

use neptunus::firmware::codec::{Command, Event, Framing, LineDecoder, crc8, encoded};
use neptunus::firmware::emulator::{
    Board, BoardRecord, EmulatorOptions, FaultOptions, FirmwareVersion, FittedSensors,
};

fn ms(v: u64) -> Duration {
    Duration::from_millis(v)
}

/// A board and its clock, woken at its own deadlines like the pty wrapper.
struct Rig {
    board: Board,
    t: Duration,
    out: Vec<u8>,
    version: FirmwareVersion,
}

impl Rig {
    fn new(opts: EmulatorOptions) -> Self {
        let version = opts.imitated();
        let mut board = Board::new(opts);
        board.record(true);
        let mut out = Vec::new();
        board.start(Duration::ZERO, &mut out);
        let mut rig = Self {
            board,
            t: Duration::ZERO,
            out,
            version,
        };
        while !rig.text().contains("boot:1;") {
            assert!(rig.t < Duration::from_secs(5), "{}", rig.text());
            rig.run(1);
        }
        // Its first pass prints every line whose timer ran during set-up;
        // a host that sends now loses bytes while that burst blocks it.
        rig.run(300);
        rig
    }

    fn booted() -> Self {
        Self::new(EmulatorOptions::default())
    }

    /// Runs `d_ms` of board time.
    fn run(&mut self, d_ms: u64) {
        let until = self.t + ms(d_ms);
        while self.t < until {
            self.t = self
                .board
                .next_deadline()
                .max(self.t + Duration::from_micros(1))
                .min(until);
            self.board.tick(self.t, &mut self.out);
        }
    }

    fn raw(&mut self, bytes: &[u8]) {
        self.board.receive(bytes, self.t, &mut self.out);
    }

    /// A command as the firmware expects it, then 60 ms for the motor timer.
    fn send(&mut self, text: &str) -> String {
        let from = self.out.len();
        let bytes = match self.version {
            FirmwareVersion::V30_0_2 => [&[crc8(text.as_bytes())], text.as_bytes()].concat(),
            FirmwareVersion::V2014_12 => text.as_bytes().to_vec(),
        };
        self.raw(&bytes);
        self.run(60);
        String::from_utf8_lossy(&self.out[from..]).into_owned()
    }

    fn text(&self) -> String {
        String::from_utf8_lossy(&self.out).into_owned()
    }

    fn take(&mut self) -> String {
        let t = self.text();
        self.out.clear();
        t
    }

    fn executed(&mut self) -> Vec<String> {
        self.board
            .take_records()
            .into_iter()
            .filter_map(|r| match r {
                BoardRecord::Executed(s) => Some(s),
                BoardRecord::Frame(_) => None,
            })
            .collect()
    }
}

/// Everything but the periodic lines (navigation, the status cycle, the
/// board's analog line, mtarg/mtrmod), which come on their own timers.
fn replies(text: &str) -> String {
    const PERIODIC: &[&str] = &[
        "hdgd:",
        "motorAttached:",
        "servo:",
        "fmem:",
        ";time:",
        "pres:",
        "dlms:",
        "alps:",
        "BRDT:",
        "mtarg:",
        "mtrmod:",
        "log:Failed to read Depth",
    ];
    let mut out = String::new();
    for line in text.split_inclusive('\n') {
        // A reply printed without a line end prefixes the next line: keep
        // what comes before a periodic key.
        match PERIODIC.iter().filter_map(|p| line.find(p)).min() {
            Some(i) => out.push_str(&line[..i]),
            None => out.push_str(line),
        }
    }
    out
}

#[test]
fn boots_with_the_set_up_chatter_of_a_board_with_its_sensors() {
    let rig = Rig::booted();
    let text = rig.text();
    let chatter = &text[..text.find("boot:1;").unwrap() + "boot:1;\r\n".len()];
    let want = "log:setting dev #0;log:setting dev #1;log:setting dev #2;log:setting dev #3;\
log:setting dev #4;log:setting dev #5;log:pilot setup complete;\r\n\
log:setting dev #6;log:setting dev #7;log:setting dev #8;Loading firmware\r\n\
log:init on primary addresses;\r\n\
log:setting dev #9;log:Depth Sensor setup;\r\n\
MS5803.status: initialized I2C;\r\n\
MS5803.status: reset;\r\n\
Depth: Calibration constants are:\r\n\
Depth.C0:4112;\r\nDepth.C1:46372;\r\nDepth.C2:43981;\r\nDepth.C3:29059;\r\n\
Depth.C4:27842;\r\nDepth.C5:31553;\r\nDepth.C6:28165;\r\nDepth.C7:3;\r\n\
log:setting dev #10;log:setting dev #11;BNO055.Address:40;\r\n\
BNO055.WHO_AM_I:0;\r\nBNO055.IAM_160:255;\r\nBNO055.status:failed;\r\n\
boot:1;\r\n";
    assert_eq!(chatter, want);
}

#[test]
fn a_board_without_sensors_says_so_and_reports_zeros() {
    let mut rig = Rig::new(EmulatorOptions {
        sensors: FittedSensors::none(),
        ..Default::default()
    });
    let text = rig.take();
    assert!(
        text.contains("log:setting dev #8;MPU9150.status:Not found;\r\n"),
        "{text}"
    );
    assert!(text.contains("Depth.C0:0;\r\n"), "{text}");
    rig.run(1200);
    let text = rig.text();
    assert!(text.contains("hdgd:0.00;deap:0.00;pitc:0.00;roll:0.00;yaw:0.00;fthr:0.00;\r\n"));
    assert!(text.contains("pres:0.00;temp:0.00;\r\n"));
    // The depth sensor's failure, once a second, without its `;`.
    assert!(
        text.contains("\r\nlog:Failed to read Depth from I2C\r\n"),
        "{text}"
    );
    assert!(
        rig.send("rcap();")
            .contains("CAPA:206;log:Scanning...;\r\nlog:No I2C devices found\n;\r\n")
    );
}

#[test]
fn the_2014_12_firmware_boots_with_its_own_chatter() {
    let rig = Rig::new(EmulatorOptions {
        firmware: FirmwareVersion::V2014_12,
        sensors: FittedSensors::none(),
        ..Default::default()
    });
    let text = rig.text();
    assert_eq!(
        &text[..text.find("boot:1;\r\n").unwrap() + "boot:1;\r\n".len()],
        "log:pilot setup complete;\r\n\
mpu_init failed with code: -1\r\n\
log:Trying other MPU9150 address to init;\r\n\
log:IMU Address was :1 but is now:0;\r\n\
mpu_init failed with code: -1\r\n\
log:Failed to init on both addresses;\r\n\
Depth Sensor setup.\r\n\
Depth Sensor: initialized I2C\r\n\
Depth Sensor is reset\r\n\
Depth: Calibration constants are:\r\n\
boot:1;\r\n"
    );
}

#[test]
fn a_frame_is_echoed_in_hex_checked_and_run() {
    let mut rig = Rig::booted();
    rig.take();
    let go = Command::Go {
        port_us: 1600,
        vertical_us: 1500,
        starboard_us: 1400,
    };
    let frame = encoded(&go, Framing::Crc8);
    rig.raw(&frame);
    rig.run(60);
    let hex: String = frame.iter().map(|x| format!("{x:X},")).collect();
    let want =
        format!("rawcmd:{hex};\r\ncrc:pass;cmd:go(1600,1500,1400);\r\nmotors:1640,1500,1270;\r\n");
    assert_eq!(replies(&rig.text()), want);
    assert_eq!(rig.board.snapshot().target_us, [1600, 1500, 1400]);
    assert_eq!(rig.board.snapshot().motors_us, [1640, 1500, 1270]);
    assert_eq!(rig.executed(), vec!["go(1600,1500,1400)".to_owned()]);
}

#[test]
fn the_echo_prints_arguments_as_typed_and_runs_them_as_atoi_reads_them() {
    let mut rig = Rig::booted();
    let out = replies(&rig.send("ping( 7 , 8x);"));
    assert!(out.contains("crc:pass;cmd:ping(7,8x);\r\npong:2,"), "{out}");
    assert_eq!(rig.executed(), vec!["ping(7,8)".to_owned()]);
    // Matched by prefix: `gox` is a `go`.
    rig.send("gox(1550,1500,1500);");
    assert_eq!(rig.board.snapshot().motors_us, [1595, 1500, 1500]);
}

#[test]
fn a_bad_crc_is_reported_in_hex_without_a_line_end_and_dropped() {
    let mut rig = Rig::booted();
    rig.take();
    let mut frame = encoded(&Command::Lights(200), Framing::Crc8);
    frame[0] ^= 0x55;
    rig.raw(&frame);
    rig.run(300);
    let calc = crc8(&frame[1..]);
    let text = rig.text();
    let fail = format!("crc:fail,{calc:X}/{:X};", frame[0]);
    let at = text
        .find(&fail)
        .unwrap_or_else(|| panic!("{fail} in {text}"));
    assert!(!text[at + fail.len()..].starts_with('\r'), "{text}");
    assert_eq!(rig.board.snapshot().lights, 0);
    assert_eq!(rig.board.snapshot().crc_failures, 1);
    assert!(rig.executed().is_empty());
    // `;` alone: nothing after the CRC byte's place.
    rig.take();
    rig.raw(b";");
    rig.run(20);
    assert!(
        rig.text().contains("rawcmd:3B,;\r\ncrc:fail,0/3B;"),
        "{}",
        rig.text()
    );
}

/// A command whose plain CRC is `;` would be cut by the board; the codec's
/// re-encoding keeps it intact and the board runs it.
#[test]
fn crc_equal_to_semicolon_is_reencoded_and_still_executed() {
    let cmd = (0..=255u8)
        .map(Command::Lights)
        .chain((1000..=2000u16).map(Command::Tilt))
        .find(|c| {
            let mut t = Vec::new();
            c.write_text(&mut t);
            crc8(&t) == b';'
        })
        .expect("some command has CRC 0x3B");
    let mut text = Vec::new();
    cmd.write_text(&mut text);
    let mut raw = vec![b';'];
    raw.extend_from_slice(&text);
    let mut rig = Rig::booted();
    rig.raw(&raw);
    rig.run(20);
    assert!(rig.executed().is_empty(), "an unguarded 0x3B frame is lost");
    rig.raw(&encoded(&cmd, Framing::Crc8));
    rig.run(20);
    assert_eq!(rig.executed().len(), 1, "{}", rig.text());
    let snap = rig.board.snapshot();
    match cmd {
        Command::Lights(n) => assert_eq!(snap.lights, n),
        Command::Tilt(us) => assert_eq!(snap.tilt_target_us, us),
        _ => unreachable!(),
    }
}

#[test]
fn plain_framing_is_the_2014_12_firmware_with_its_cmd_echo_alone() {
    let mut rig = Rig::new(EmulatorOptions {
        framing: Framing::Plain,
        ..Default::default()
    });
    assert_eq!(rig.version, FirmwareVersion::V2014_12);
    let out = replies(&rig.send("claser(255);"));
    assert_eq!(out, "cmd:claser(255);\r\nclaser:255;");
    assert!(!rig.text().contains("crc:"));
    assert!(
        !rig.text().contains("mtrmod:"),
        "2014-12 prints no mtrmod line"
    );
}

#[test]
fn an_unknown_command_is_echoed_and_does_nothing() {
    let mut rig = Rig::booted();
    let before = rig.board.snapshot();
    let out = replies(&rig.send("frob(1,2);"));
    assert!(out.ends_with("crc:pass;cmd:frob(1,2);\r\n"), "{out}");
    assert_eq!(rig.board.snapshot().target_us, before.target_us);
}

#[test]
fn go_needs_all_three_strictly_between_999_and_2001() {
    let mut rig = Rig::booted();
    rig.send("go(1700,1700,1700);");
    rig.send("go(1800,2001,1800);");
    assert_eq!(rig.board.snapshot().target_us, [1700, 1700, 1700]);
    rig.send("go(999,1500,1500);");
    assert_eq!(rig.board.snapshot().target_us, [1700, 1700, 1700]);
    rig.send("go(1000,2000,1000);");
    assert_eq!(rig.board.snapshot().target_us, [1000, 2000, 1000]);
}

#[test]
fn the_esc_pulses_skip_the_deadzone_and_double_reverse() {
    let mut rig = Rig::booted();
    // 1540 is just out of neutral: the pulse skips the 50 µs deadzone.
    // 1400 is reverse, doubled: 1300, then mapped onto 1000..1450.
    assert!(
        rig.send("go(1540,1400,1700);")
            .contains("motors:1586,1270,1730;")
    );
    assert!(
        rig.send("go(1000,1460,1551);")
            .contains("motors:1000,1378,1595;")
    );
    assert!(
        rig.send("go(1500,1500,1500);")
            .contains("motors:1500,1500,1500;")
    );
    // The pulses change with the targets only: the same go() prints nothing.
    assert!(!rig.send("go(1500,1500,1500);").contains("motors:"));
}

#[test]
fn thro_yaw_and_lift_are_mixed_on_the_board() {
    let mut rig = Rig::booted();
    for (cmd, motors) in [
        ("thro(33);", "motors:1698,1500,1698;"),
        ("yaw(-20);", "motors:1653,1500,1743;"),
        ("lift(50);", "motors:1653,1775,1743;"),
        ("thro(-60);", "motors:1090,1775,1270;"),
        ("yaw(90);", "motors:1617,1775,1000;"),
    ] {
        let out = rig.send(cmd);
        assert!(out.contains(motors), "{cmd}: {out}");
    }
    assert_eq!(rig.board.snapshot().target_us, [1575, 1750, 1125]);
}

#[test]
fn lights_laser_tilt_ping_and_capabilities_answer_as_the_firmware() {
    let mut rig = Rig::booted();
    assert!(
        rig.send("ligt(51);")
            .contains("cmd:ligt(51);\r\nLIGT:51;LIGP:0.20;\r\n")
    );
    let laser = replies(&rig.send("claser(255);"));
    assert!(
        laser.ends_with("cmd:claser(255);\r\nclaser:255;"),
        "{laser}"
    );
    let pong = replies(&rig.send("ping(0);"));
    let at = pong.find("pong:1,").expect(&pong);
    let millis: u64 = pong[at + 7..]
        .split(';')
        .next()
        .unwrap()
        .parse()
        .expect(&pong);
    assert!(millis > 0 && millis <= rig.t.as_millis() as u64, "{pong}");
    assert!(replies(&rig.send("ping();")).contains("pong:0,"));
    rig.send("tilt(2000);");
    let s = rig.board.snapshot();
    assert_eq!(s.tilt_target_us, 2000);
    // A microsecond a pass, some 3 000 passes a second.
    assert!(
        s.tilt_us > 1600 && s.tilt_us < 1800,
        "tilt slews: {}",
        s.tilt_us
    );
    rig.run(200);
    assert_eq!(rig.board.snapshot().tilt_us, 2000);
    assert!(rig.send("escp(0);").contains("log:escpower=0;\r\n"));
    assert!(!rig.board.snapshot().escs_powered);
}

#[test]
fn rcap_reports_scans_the_bus_and_blinds_the_board_for_five_seconds() {
    let mut rig = Rig::booted();
    let out = rig.send("rcap();");
    assert!(
        out.contains(
            "cmd:rcap();\r\nCAPA:254;log:Scanning...;\r\n\
log:I2C device found at address 0x68  !;\r\n\
log:I2C device found at address 0x76  !;\r\n\
log:done\n;\r\n"
        ),
        "{out}"
    );
    rig.take();
    rig.send("ping(0);");
    rig.run(4000);
    assert!(
        rig.text().is_empty(),
        "nothing at all during the delay: {}",
        rig.text()
    );
    rig.run(1000);
    assert!(rig.text().contains("cmd:ping(0);"), "{}", rig.text());
}

#[test]
fn an_overlong_frame_loses_a_byte_and_the_board_parses_its_tail() {
    let mut rig = Rig::booted();
    rig.take();
    let long =
        "go(1500,1500,1500,1500,1500,1500,1500,1500,1500,1500,1500,1500,1500,1500,1500,1500);";
    let mut frame = vec![crc8(long.as_bytes())];
    frame.extend_from_slice(long.as_bytes());
    rig.raw(&frame);
    rig.run(30);
    assert!(
        rig.text()
            .contains("rawcmd:30,30,29,3B,;\r\ncrc:fail,33/30;"),
        "{}",
        rig.text()
    );
}

#[test]
fn dms_counts_arguments_and_the_dead_man_trips_as_the_firmware() {
    let mut rig = Rig::booted();
    rig.send("dms();");
    assert!(!rig.board.snapshot().dead_man_armed);
    rig.send("ping(0);");
    rig.send("dms(0);");
    assert!(rig.board.snapshot().dead_man_armed, "any argument arms");
    rig.send("ping(0);");
    rig.send("go(1700,1500,1700);");
    rig.take();
    rig.run(2200);
    let s = rig.board.snapshot();
    assert!(s.dead_man_tripped);
    assert_eq!(s.motors_us, [1500, 1500, 1500]);
    let out = replies(&rig.take());
    assert!(!out.contains("DeadManSwitchTripped"));
    let expected = [
        "icmd:deptloff();\r\n",
        "log:depth_hold_disabled;\r\n",
        "targetDepth:DISABLED;\r\n",
        "icmd:headloff();\r\n",
        "log:heading_hold_disabled;\r\n",
        "targetHeading:DISABLED;\r\n",
        "icmd:stop();\r\n",
        "icmd:ligt(50);\r\n",
        "LIGT:50;LIGP:0.20;\r\n",
        "icmd:lift(0);\r\n",
        "icmd:yaw(0);\r\n",
    ];
    let without_motors = out.replace("motors:1500,1500,1500;\r\n", "");
    assert_eq!(without_motors, expected.concat(), "{out}");
    // Blinking; go() is still obeyed while tripped.
    rig.run(600);
    assert!(
        rig.take()
            .contains("icmd:ligt(0);\r\nLIGT:0;LIGP:0.00;\r\n")
    );
    rig.send("go(1600,1500,1600);");
    assert_eq!(rig.board.snapshot().motors_us, [1640, 1500, 1640]);
    // A ping: pong, then start.
    let out = replies(&rig.send("ping(0);"));
    assert!(
        out.contains(";icmd:start();\r\n") && out.contains("pong:1,"),
        "{out}"
    );
    assert!(!rig.board.snapshot().dead_man_tripped);
}

#[test]
fn the_dead_man_arms_itself_after_180_s() {
    let mut rig = Rig::booted();
    rig.send("go(1700,1500,1700);");
    rig.run(10_000);
    assert!(!rig.board.snapshot().dead_man_tripped);
    rig.run(175_000);
    assert!(
        rig.board.snapshot().dead_man_tripped,
        "auto-armed after 180 s"
    );
}

#[test]
fn a_burst_into_the_scan_delay_overruns_the_internal_queue() {
    let mut rig = Rig::booted();
    rig.send("rcap();");
    let burst: Vec<u8> = (0..5)
        .flat_map(|_| [&[crc8(b"headloff();")][..], b"headloff();"].concat())
        .collect();
    rig.raw(&burst);
    rig.take();
    rig.run(5500);
    let out = replies(&rig.text());
    assert_eq!(
        out.matches("log: CommandBufferOverrun;\r\n").count(),
        1,
        "{out}"
    );
    assert_eq!(out.matches("icmd:yaw(0);\r\n").count(), 4, "{out}");
    assert_eq!(rig.board.snapshot().overruns, 1);
    assert_eq!(rig.board.snapshot().rx_lost, 0);
}

#[test]
fn the_receive_ring_loses_what_does_not_fit_while_the_board_is_busy() {
    let mut rig = Rig::booted();
    rig.send("rcap();");
    // Nine pings (72 bytes) into the 63-byte ring.
    let burst: Vec<u8> = (0..9)
        .flat_map(|_| [&[crc8(b"ping(0);")][..], b"ping(0);"].concat())
        .collect();
    rig.raw(&burst);
    rig.run(5500);
    assert_eq!(rig.board.snapshot().rx_lost, 81 - 63);
}

#[test]
fn the_status_cycle_and_navigation_lines_come_as_the_firmware_prints_them() {
    let mut rig = Rig::booted();
    rig.take();
    rig.run(10_000);
    let text = rig.text();
    let nav = text.matches("\r\nhdgd:").count();
    assert!((97..=100).contains(&nav), "nav {nav}: every ~101 ms");
    let cycle = regex::Regex::new(
        "motorAttached:1;\r\nservo:1500;starg:1500;\r\n\
fmem:3572.00;vout:[0-9]+\\.[0-9]{2};iout:[0-9]+\\.[0-9]{2};atmp:0.00;ver:CUSTOM_BUILD;\
cmpd:Aug 31 2015, 10:21:44, 4.8.1\r\n\
;time:[0-9]+\\.00;\r\n\
pres:[0-9]+\\.[0-9]{2};temp:[0-9]+\\.[0-9]{2};\r\n\
dlms:(([0-9]|1[01])\\|[0-9]+){12};\r\n\
alps:[0-9]+;\r\n",
    )
    .unwrap();
    let cycles = cycle.find_iter(&text).count();
    assert!((9..=10).contains(&cycles), "{cycles} cycles in\n{text}");
    assert!(text.contains("mtrmod:1.00,1.00,1.00,2.00,2.00,2.00;\r\n"));
    assert!(regex::Regex::new("BRDT:25.06;SC1I:0.00;SC2I:0.00;SC3I:0.00;BRDI:0.30;BT1I:[0-9.]+;BT2I:[0-9.]+;BRDV:[0-9.]+;AVCC:5001;\r\n")
        .unwrap()
        .is_match(&text));
    // The codec decodes all of it.
    let mut dec = LineDecoder::new();
    let mut ev = Vec::new();
    dec.push(text.as_bytes(), &mut ev);
    let status = ev
        .iter()
        .filter(|e| matches!(e, Event::Status(s) if s.time_ms.is_some()))
        .count();
    assert!((9..=10).contains(&status), "status {status}");
    assert_eq!(dec.stats().rejected_total(), 0, "{:?}", dec.stats());
}

#[test]
fn an_idle_board_wakes_for_its_lines_not_for_its_loop() {
    let mut rig = Rig::booted();
    let mut wakes = 0;
    let until = rig.t + Duration::from_secs(10);
    while rig.t < until {
        rig.t = rig
            .board
            .next_deadline()
            .max(rig.t + Duration::from_micros(1));
        let mut out = Vec::new();
        rig.board.tick(rig.t, &mut out);
        wakes += 1;
    }
    // The navigation line, the 1 s lines and timers: some 15 a second,
    // against the loop's 3 000 passes.
    assert!(wakes <= 200, "{wakes} wake-ups in 10 s");
    assert!(wakes >= 100, "{wakes}: the navigation line alone is 10 Hz");
}

/// The thesis' exact physics (`tests/sim_models.rs` covers the realistic
/// model, where the reversed port ESC at full reverse gives half thrust).
#[test]
fn forward_thrust_moves_the_simulated_vehicle() {
    let mut rig = Rig::new(EmulatorOptions::ideal_thesis());
    // Port wired reversed: full forward is port 1000, starboard 2000.
    rig.send("go(1000,1500,2000);");
    assert_eq!(rig.board.snapshot().motors_us, [1000, 1500, 2000]);
    rig.run(30_000);
    let s = rig.board.snapshot().sim;
    assert!(s.surge_mps > 1.4, "surge {}", s.surge_mps);
    assert!(s.north_m > 30.0, "north {}", s.north_m);
}

#[test]
fn unpowered_escs_push_nothing() {
    let mut rig = Rig::new(EmulatorOptions::ideal_thesis());
    rig.send("escp(0);");
    rig.send("go(1000,1500,2000);");
    rig.run(5_000);
    assert_eq!(rig.board.snapshot().sim.surge_mps, 0.0);
}

/// With faults injected, every line the decoder accepts carries either the
/// clean value or an in-range wild point the emulator recorded, and the
/// rejection counters equal what the emulator injected.
#[test]
fn fault_injection_is_accounted_for_exactly() {
    let faults = FaultOptions {
        garbage: 0.05,
        torn: 0.05,
        wild: 0.05,
        dropped: 0.0,
        seed: 7,
    };
    let run = |faults: FaultOptions| {
        let mut b = Board::new(EmulatorOptions {
            faults,
            ..Default::default()
        });
        let mut out = Vec::new();
        b.start(Duration::ZERO, &mut out);
        b.receive(
            &encoded(
                &Command::Go {
                    port_us: 1300,
                    vertical_us: 1600,
                    starboard_us: 1800,
                },
                Framing::Crc8,
            ),
            ms(1500),
            &mut out,
        );
        let mut t = Duration::ZERO;
        while t < Duration::from_secs(300) {
            t += ms(10);
            b.tick(t, &mut out);
        }
        (b, out)
    };
    let (faulty, fo) = run(faults);
    let (_, co) = run(FaultOptions::default());
    let f_lines: Vec<&[u8]> = fo.split(|&b| b == b'\n').collect();
    let c_lines: Vec<&[u8]> = co.split(|&b| b == b'\n').collect();
    assert_eq!(f_lines.len(), c_lines.len());
    let mut whole = LineDecoder::new();
    let mut all = Vec::new();
    let mut differing_accepted = 0;
    let (mut fd, mut cd) = (LineDecoder::new(), LineDecoder::new());
    for (f, c) in f_lines.iter().zip(&c_lines) {
        let (mut fe, mut ce) = (Vec::new(), Vec::new());
        let mut f = f.to_vec();
        f.push(b'\n');
        let mut c = c.to_vec();
        c.push(b'\n');
        let rejected = fd.stats().rejected_total();
        fd.push(&f, &mut fe);
        cd.push(&c, &mut ce);
        // A line that ends in `;` on the clean side is whole: decide a torn
        // one now rather than with the next line. (The status cycle's
        // `cmpd` line waits for its `;` on the next.)
        if c.ends_with(b";\r\n") {
            fd.flush(&mut fe);
            cd.flush(&mut ce);
        }
        whole.push(&f, &mut all);
        if fd.stats().rejected_total() == rejected && fe != ce {
            differing_accepted += 1;
        }
    }
    let injected = faulty.snapshot().faults;
    assert!(
        injected.torn_lines > 50 && injected.wild_out_of_range > 20 && injected.garbage_bursts > 50,
        "{injected:?}"
    );
    assert_eq!(
        whole.stats().rejected_total(),
        injected.expected_rejections(),
        "{:?} vs {injected:?}",
        whole.stats()
    );
    // Accepted lines that differ from the clean ones are exactly the in-range wild points.
    assert_eq!(differing_accepted, injected.wild_in_range);
    assert_eq!(whole.stats().garbage_bytes, injected.garbage_bytes);
}
