//! The simulated BNO055 driven as the 30.0.2 firmware drives it.

use super::*;

/// `writeByte`: one transfer, register address then value.
fn write_byte(chip: &mut Bno055, addr: u8, value: u8) {
    chip.start(false);
    chip.write(addr);
    chip.write(value);
}

/// `readBytes` as the firmware does it: the address, then two read
/// transfers of `n` bytes; returns both.
fn read_twice(chip: &mut Bno055, addr: u8, n: usize) -> (Vec<u8>, Vec<u8>) {
    chip.start(false);
    chip.write(addr);
    let mut transfer = || {
        chip.start(true);
        (0..n).map(|_| chip.read()).collect::<Vec<u8>>()
    };
    let first = transfer();
    (first, transfer())
}

fn read_byte(chip: &mut Bno055, addr: u8) -> u8 {
    let (a, b) = read_twice(chip, addr, 1);
    assert_eq!(a, b, "both transfers read register {addr:#04x}");
    b[0]
}

/// The set-up `BNO055::device_setup` and `initBNO055` perform.
fn firmware_setup(chip: &mut Bno055) {
    assert_eq!(read_byte(chip, reg::CHIP_ID), 0xA0);
    write_byte(chip, reg::SYS_TRIGGER, 0x20);
    read_byte(chip, reg::SW_REV_ID_LSB);
    read_byte(chip, reg::SW_REV_ID_MSB);
    read_byte(chip, reg::BL_REV_ID);
    read_byte(chip, reg::ST_RESULT);
    write_byte(chip, reg::SYS_TRIGGER, 0x01);
    read_byte(chip, reg::ST_RESULT);
    assert_eq!(read_byte(chip, reg::OPR_MODE), mode::CONFIG);
    write_byte(chip, reg::PAGE_ID, 0);
    write_byte(chip, reg::AXIS_MAP_CONFIG, 0x24);
    write_byte(chip, reg::AXIS_MAP_SIGN, 0x03);
    write_byte(chip, reg::UNIT_SEL, 0x01);
    write_byte(chip, reg::PWR_MODE, 0);
    write_byte(chip, reg::OPR_MODE, mode::NDOF);
    assert_eq!(read_byte(chip, reg::OPR_MODE), mode::NDOF);
}

/// `readEulData` and the arithmetic after it: (hdgd, pitc, roll).
fn firmware_euler(chip: &mut Bno055) -> (f64, f64, f64) {
    let (_, b) = read_twice(chip, reg::EUL_HEADING_LSB, 6);
    let v = |i: usize| f64::from(i16::from_le_bytes([b[i], b[i + 1]]));
    (v(0) / 16.0, v(4) / 16.0, -v(2) / 16.0)
}

fn attitude(heading_deg: f64, pitch_deg: f64, roll_deg: f64) -> Attitude {
    Attitude {
        heading_deg,
        pitch_deg,
        roll_deg,
    }
}

#[test]
fn answers_the_probe_and_ids_on_both_reads() {
    let mut chip = Bno055::new(&Attitude::default());
    assert_eq!(chip.address(), 0x28);
    let (first, second) = read_twice(&mut chip, reg::CHIP_ID, 4);
    assert_eq!(first, [0xA0, 0xFB, 0x32, 0x0F]);
    assert_eq!(second, first);
    assert_eq!(read_byte(&mut chip, reg::SW_REV_ID_MSB), 0x03);
    assert_eq!(read_byte(&mut chip, reg::SW_REV_ID_LSB), 0x11);
    assert_eq!(read_byte(&mut chip, reg::ST_RESULT), 0x0F);
    assert_eq!(read_byte(&mut chip, reg::CALIB_STAT), 0xFF);
}

#[test]
fn writes_count_up_and_read_back() {
    let mut chip = Bno055::new(&Attitude::default());
    chip.start(false);
    chip.write(reg::AXIS_MAP_CONFIG);
    chip.write(0x21);
    chip.write(0x05);
    let (_, b) = read_twice(&mut chip, reg::AXIS_MAP_CONFIG, 2);
    assert_eq!(b, [0x21, 0x05]);
    // Read-only and reserved registers keep their value; counted.
    write_byte(&mut chip, reg::CHIP_ID, 0x55);
    write_byte(&mut chip, 0x7E, 1);
    assert_eq!(read_byte(&mut chip, reg::CHIP_ID), 0xA0);
    assert_eq!(chip.ignored_writes, 2);
    // Two remapped axes from one chip axis: refused.
    write_byte(&mut chip, reg::AXIS_MAP_CONFIG, 0x00);
    assert_eq!(read_byte(&mut chip, reg::AXIS_MAP_CONFIG), 0x21);
    assert_eq!(chip.ignored_writes, 3);
}

#[test]
fn reset_restores_power_up_and_self_test_passes() {
    let mut chip = Bno055::new(&Attitude::default());
    write_byte(&mut chip, reg::AXIS_MAP_SIGN, 0x03);
    write_byte(&mut chip, reg::OPR_MODE, mode::NDOF);
    write_byte(&mut chip, reg::SYS_TRIGGER, 0x20);
    assert_eq!(read_byte(&mut chip, reg::OPR_MODE), mode::CONFIG);
    assert_eq!(read_byte(&mut chip, reg::AXIS_MAP_SIGN), 0x00);
    write_byte(&mut chip, reg::SYS_TRIGGER, 0x01);
    assert_eq!(read_byte(&mut chip, reg::ST_RESULT), 0x0F);
    assert_eq!(read_byte(&mut chip, reg::SYS_TRIGGER), 0);
}

#[test]
fn page_one_holds_its_own_registers() {
    let mut chip = Bno055::new(&Attitude::default());
    write_byte(&mut chip, reg::PAGE_ID, 1);
    write_byte(&mut chip, 0x08, 0x0D);
    assert_eq!(read_byte(&mut chip, 0x08), 0x0D);
    assert_eq!(read_byte(&mut chip, reg::PAGE_ID), 1);
    write_byte(&mut chip, reg::PAGE_ID, 0);
    assert_eq!(read_byte(&mut chip, 0x08), 0);
    assert_eq!(read_byte(&mut chip, reg::CHIP_ID), 0xA0);
}

#[test]
fn euler_registers_only_in_fusion_modes() {
    let mut chip = Bno055::new(&attitude(30.0, 0.0, 0.0));
    write_byte(&mut chip, reg::AXIS_MAP_SIGN, 0x03);
    let (_, b) = read_twice(&mut chip, reg::EUL_HEADING_LSB, 6);
    assert_eq!(b, [0; 6]);
    assert_eq!(read_byte(&mut chip, reg::SYS_STATUS), 0);
    write_byte(&mut chip, reg::OPR_MODE, mode::NDOF);
    assert_eq!(read_byte(&mut chip, reg::SYS_STATUS), 5);
    // Heading 30° = 480 LSB, little-endian, then roll and pitch 0.
    let (_, b) = read_twice(&mut chip, reg::EUL_HEADING_LSB, 6);
    assert_eq!(b, [0xE0, 0x01, 0, 0, 0, 0]);
}

#[test]
fn the_firmware_reads_single_axis_attitudes_back() {
    let mut chip = Bno055::new(&Attitude::default());
    firmware_setup(&mut chip);
    // (set heading, pitch, roll) → printed (hdgd, pitc, roll): the roll
    // comes out negated, everything else as set.
    let cases = [
        ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
        ((30.0, 0.0, 0.0), (30.0, 0.0, 0.0)),
        ((200.0, 0.0, 0.0), (200.0, 0.0, 0.0)),
        ((350.0, 0.0, 0.0), (350.0, 0.0, 0.0)),
        ((-10.0, 0.0, 0.0), (350.0, 0.0, 0.0)),
        ((0.0, 15.0, 0.0), (0.0, 15.0, 0.0)),
        ((0.0, -15.0, 0.0), (0.0, -15.0, 0.0)),
        ((0.0, 0.0, 20.0), (0.0, 0.0, -20.0)),
        ((0.0, 0.0, -20.0), (0.0, 0.0, 20.0)),
        ((120.0, 0.0, -20.0), (120.0, 0.0, 20.0)),
        // Bow up 30° to the south, upside down: the chip's pitch has
        // the full circle, so it reads 150° towards the north.
        ((180.0, 30.0, 180.0), (0.0, 150.0, 0.0)),
    ];
    for ((h, p, r), want) in cases {
        chip.set_attitude(&attitude(h, p, r));
        let got = firmware_euler(&mut chip);
        let close = |a: f64, b: f64| (a - b).abs() <= 1.0 / 32.0 + 1e-9;
        assert!(
            close(got.0, want.0) && close(got.1, want.1) && close(got.2, want.2),
            "heading {h} pitch {p} roll {r}: printed {got:?}, want {want:?}"
        );
    }
}

/// The chip rolls before it pitches; the aviation angles pitch first.
/// Independent of the matrices above: the starboard axis sinks by
/// asin(sin φ cos θ) (the chip's roll), the bow rises by θ = asin(sin p
/// cos r), and the chip's heading is the starboard axis's bearing less 90°.
#[test]
fn combined_attitudes_follow_the_chips_heading_roll_pitch_order() {
    for (h, p, r) in [
        (200.0, 15.0, 20.0),
        (30.0, -15.0, -20.0),
        (350.0, 15.0, -20.0),
        (75.0, -30.0, 40.0),
    ] {
        let got = firmware_reading(&attitude(h, p, r));
        let (psi, th, ph): (f64, f64, f64) =
            (f64::to_radians(h), f64::to_radians(p), f64::to_radians(r));
        let chip_roll = (ph.sin() * th.cos()).asin();
        let chip_pitch = (th.sin() / chip_roll.cos()).asin();
        let north = psi.cos() * th.sin() * ph.sin() - psi.sin() * ph.cos();
        let east = psi.sin() * th.sin() * ph.sin() + psi.cos() * ph.cos();
        let chip_heading = (east.atan2(north).to_degrees() - 90.0).rem_euclid(360.0);
        let tol = 1.0 / 32.0 + 1e-9;
        assert!((got.hdgd_deg - chip_heading).abs() <= tol, "{h}: {got:?}");
        assert_eq!(got.yaw_deg, got.hdgd_deg);
        assert!(
            (got.pitc_deg - chip_pitch.to_degrees()).abs() <= tol,
            "{p}: {got:?}"
        );
        assert!(
            (got.roll_deg + chip_roll.to_degrees()).abs() <= tol,
            "{r}: {got:?}"
        );
    }
    // The module docs' example, as figures.
    let got = firmware_reading(&attitude(200.0, 15.0, 20.0));
    assert!((got.hdgd_deg - 194.618).abs() < 0.04, "{got:?}");
    assert!((got.pitc_deg - 15.915).abs() < 0.04, "{got:?}");
    assert!((got.roll_deg + 19.291).abs() < 0.04, "{got:?}");
}

#[test]
fn units_orientation_and_remap_follow_the_registers() {
    let mut chip = Bno055::new(&attitude(90.0, 10.0, 0.0));
    write_byte(&mut chip, reg::AXIS_MAP_SIGN, 0x03);
    write_byte(&mut chip, reg::OPR_MODE, mode::NDOF);
    assert_eq!(chip.euler_registers(), [90 * 16, 0, 10 * 16]);
    // Radians: 900 LSB per radian.
    write_byte(&mut chip, reg::UNIT_SEL, UNIT_EULER_RADIANS);
    let [h, _, p] = chip.euler_registers();
    assert_eq!(h, (PI / 2.0 * 900.0).round() as i16);
    assert_eq!(p, (10f64.to_radians() * 900.0).round() as i16);
    // Android orientation turns the pitch round.
    write_byte(&mut chip, reg::UNIT_SEL, UNIT_ANDROID);
    assert_eq!(chip.euler_registers(), [90 * 16, 0, -10 * 16]);
    // Without the firmware's remap the chip reads its own axes: upside
    // down (pitch ±180°) and facing aft.
    write_byte(&mut chip, reg::UNIT_SEL, 0);
    write_byte(&mut chip, reg::OPR_MODE, mode::CONFIG);
    write_byte(&mut chip, reg::AXIS_MAP_SIGN, 0x00);
    write_byte(&mut chip, reg::OPR_MODE, mode::NDOF);
    chip.set_attitude(&Attitude::default());
    let [h, r, p] = chip.euler_registers();
    assert_eq!((h, r, p.abs()), (0, 0, 180 * 16));
}

#[test]
fn a_read_transfer_sees_one_attitude() {
    let mut chip = Bno055::new(&attitude(10.0, 0.0, 0.0));
    write_byte(&mut chip, reg::AXIS_MAP_SIGN, 0x03);
    write_byte(&mut chip, reg::OPR_MODE, mode::NDOF);
    chip.start(false);
    chip.write(reg::EUL_HEADING_LSB);
    chip.start(true);
    let lsb = chip.read();
    chip.set_attitude(&attitude(300.0, 0.0, 0.0));
    let msb = chip.read();
    assert_eq!(i16::from_le_bytes([lsb, msb]), 160);
    chip.start(true);
    let b = [chip.read(), chip.read()];
    assert_eq!(i16::from_le_bytes(b), 300 * 16);
}

#[test]
fn heading_wraps_below_a_full_turn() {
    let got = firmware_reading(&attitude(359.99, 0.0, 0.0));
    assert_eq!(got.hdgd_deg, 0.0);
    let got = firmware_reading(&attitude(359.9, 0.0, 0.0));
    assert!((got.hdgd_deg - 359.875).abs() < 1e-9, "{got:?}");
}
