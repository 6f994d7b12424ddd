//! `Command.cpp` and the loop's own outputs: the frame buffer, the echo
//! (`rawcmd:`, `crc:`, `cmd:`), the split into a name and `atoi`'d
//! arguments, the internal command ring with its `icmd:` echo and
//! overruns; then `alps`, the status cycle and the navigation line.

use super::{
    BoardRecord, COMMAND_QUEUE_SLOTS, Current, FRAME_BUFFER_BYTES, FirmwareVersion, Hardware,
    MAX_ARGS, Queued, Sketch,
};
use crate::firmware::codec::crc8;
use crate::firmware::emulator::arduino::{self, atoi, float};
use crate::firmware::emulator::uart::Uart;

impl Sketch {
    /// `Command::get`: a complete serial frame, else one queued command.
    pub(super) fn get(&mut self, uart: &mut Uart, hw: &mut dyn Hardware) {
        self.cmd = Current::default();
        if let Some(frame) = self.get_serial_string(uart) {
            self.parse(&frame, uart, hw);
            self.cmd.ready = true;
            return;
        }
        if self.head != self.tail {
            self.tail = (self.tail + 1) % COMMAND_QUEUE_SLOTS;
            let c = self.queue[self.tail].clone();
            let count = c.args.first().copied().unwrap_or(0).max(0) as usize;
            let mut line = format!("icmd:{}(", c.text);
            for i in 1..=count.min(MAX_ARGS - 1) {
                let v = c.args.get(i).copied().unwrap_or(0);
                self.cmd.args[i] = v;
                if i > 1 {
                    line.push(',');
                }
                line.push_str(&v.to_string());
            }
            line.push_str(");");
            self.cmd.args[0] = c.args.first().copied().unwrap_or(0);
            self.cmd.name = c.text.into_bytes();
            self.cmd.ready = true;
            self.println(uart, &line);
        }
    }

    /// `getSerialString`: reads what has arrived up to the first `;`. A
    /// frame that outgrows the buffer is cut: the byte that found it full
    /// is lost and storing starts again at the buffer's start.
    pub(super) fn get_serial_string(&mut self, uart: &mut Uart) -> Option<Vec<u8>> {
        let keeps_end = self.cfg.firmware == FirmwareVersion::V30_0_2;
        while let Some(b) = uart.read(self.clock) {
            if !self.storing {
                self.storing = true;
                self.data.clear();
            }
            if self.data.len() == FRAME_BUFFER_BYTES {
                self.data.clear();
                break;
            }
            if b == b';' {
                if keeps_end {
                    self.data.push(b);
                }
                self.storing = false;
                return Some(self.data.clone());
            }
            self.data.push(b);
        }
        None
    }

    /// `Command::parse`: the echo, the CRC check (30.0.2) and the split
    /// into a name and `atoi`'d arguments; the echo prints each argument
    /// as it came.
    pub(super) fn parse(&mut self, frame: &[u8], uart: &mut Uart, hw: &mut dyn Hardware) {
        let text = match self.cfg.firmware {
            FirmwareVersion::V30_0_2 => {
                let mut line = String::from("rawcmd:");
                for &b in frame {
                    line.push_str(&arduino::hex(b));
                    line.push(',');
                }
                line.push(';');
                self.println(uart, &line);
                hw.record(BoardRecord::Frame(frame.to_vec()));
                let got = frame.first().copied().unwrap_or(0);
                let calc = crc8(frame.get(1..).unwrap_or(&[]));
                if calc != got {
                    self.crc_failures += 1;
                    let fail = format!("crc:fail,{}/{};", arduino::hex(calc), arduino::hex(got));
                    self.print(uart, fail.as_bytes());
                    return;
                }
                self.print(uart, b"crc:pass;");
                frame.get(1..).unwrap_or(&[])
            }
            FirmwareVersion::V2014_12 => {
                let mut received = frame.to_vec();
                received.push(b';');
                hw.record(BoardRecord::Frame(received));
                frame
            }
        };
        self.frames_ok += 1;
        // strtok works on the C string: up to the first NUL.
        let text = match text.iter().position(|&b| b == 0) {
            Some(end) => &text[..end],
            None => text,
        };
        let tokens: Vec<&[u8]> = text
            .split(|b| b" ,();".contains(b))
            .filter(|t| !t.is_empty())
            .collect();
        let mut line = Vec::with_capacity(text.len() + 8);
        if let Some((name, args)) = tokens.split_first() {
            line.extend_from_slice(b"cmd:");
            line.extend_from_slice(name);
            line.push(b'(');
            self.cmd.name = name.to_vec();
            for (i, arg) in args.iter().enumerate() {
                if i > 0 {
                    line.push(b',');
                }
                line.extend_from_slice(arg);
                if let Some(slot) = self.cmd.args.get_mut(i + 1) {
                    *slot = atoi(arg);
                }
            }
            let parsed: Vec<String> = (1..=args.len().min(MAX_ARGS - 1))
                .map(|i| self.cmd.args[i].to_string())
                .collect();
            self.executed += 1;
            hw.record(BoardRecord::Executed(format!(
                "{}({})",
                String::from_utf8_lossy(name),
                parsed.join(",")
            )));
        }
        line.extend_from_slice(b");\r\n");
        self.print(uart, &line);
        // `byte i` counted the tokens; none leaves -1.
        self.cmd.args[0] = tokens.len() as i32 - 1;
    }

    /// `Command::pushCommand`: onto the internal ring, the oldest waiting
    /// command lost when it is full.
    pub(super) fn push(&mut self, uart: &mut Uart, text: &str, args: &[i32]) {
        self.head = (self.head + 1) % COMMAND_QUEUE_SLOTS;
        if self.head == self.tail {
            self.println(uart, "log: CommandBufferOverrun;");
            self.overruns += 1;
            self.tail = (self.tail + 1) % COMMAND_QUEUE_SLOTS;
        }
        self.queue[self.head] = Queued {
            text: text.to_owned(),
            args: args.to_vec(),
        };
    }

    pub(super) fn end_of_pass(&mut self, uart: &mut Uart, hw: &mut dyn Hardware) {
        self.loops_per_sec = self.loops_per_sec.saturating_add(1);
        let ms = self.millis();
        if self.out1000.elapsed(ms, self.cfg.status_period_ms) {
            self.shared_data(uart, hw);
            let alps = format!("alps:{};", self.loops_per_sec);
            self.telemetry(uart, hw, alps);
            self.loops_per_sec = 0;
        }
        let ms = self.millis();
        if self.out100.elapsed(ms, self.cfg.nav_period_ms) {
            let line = format!(
                "hdgd:{};deap:{};pitc:{};roll:{};yaw:{};fthr:{};",
                float(self.hdgd),
                float(self.deap),
                float(self.pitc),
                float(self.roll),
                float(self.yaw),
                float(self.fthr)
            );
            self.telemetry(uart, hw, line);
        }
    }

    /// `OutputSharedData`: six lines, one of them (`cmpd`) broken before
    /// its `;`, which starts the `time` line.
    pub(super) fn shared_data(&mut self, uart: &mut Uart, hw: &mut dyn Hardware) {
        self.telemetry(uart, hw, format!("motorAttached:{};", u8::from(self.matc)));
        self.telemetry(
            uart,
            hw,
            format!("servo:{};starg:{};", self.cmnt, self.cmtg),
        );
        let status = format!(
            "fmem:{};vout:{};iout:{};atmp:{};ver:{};cmpd:{}",
            float(self.fmem),
            float(self.vout),
            float(self.iout),
            float(0.0),
            self.cfg.version,
            self.build.compiled
        );
        self.println(uart, &status);
        let time = format!(";time:{};", float(self.utim));
        self.println(uart, &time);
        self.telemetry(
            uart,
            hw,
            format!("pres:{};temp:{};", float(self.pres), float(self.temp)),
        );
        let mut dlms = String::from("dlms:");
        for (i, us) in self.device_time_us.iter().enumerate() {
            dlms.push_str(&format!("{i}|{}", us / 1000));
        }
        dlms.push(';');
        self.telemetry(uart, hw, dlms);
    }
}
