//! simavr behind a safe face: one simulated ATmega2560 running a firmware
//! ELF, with its UART0, ADC inputs, watched output pins, timer registers,
//! I2C (TWI) slaves and reset reachable from Rust.
//!
//! This is the crate's one module with `unsafe` code: simavr's C API takes
//! raw pointers and calls back into Rust from inside `avr_run`. The rules
//! that keep it sound are local to this file: the `avr_t` and the state the
//! callbacks write live behind pointers this module owns, are freed only in
//! `Drop`, and are read from Rust only between calls into simavr (the
//! callbacks run only inside [`Mcu::run_until`], which holds `&mut self`).
//! Everything above this module (pacing, the pty, pulse measurement) is
//! safe code that owns an [`Mcu`] on one thread; `Mcu` is deliberately not
//! `Send`.
#![allow(
    unsafe_code,
    reason = "simavr is a C library: this module is the crate's one FFI boundary"
)]

use std::cell::RefCell;
use std::ffi::{CString, c_char, c_int, c_void};
use std::path::{Path, PathBuf};
use std::ptr::NonNull;
use std::rc::Rc;

use simavr_ffi as ffi;

/// The controller board's clock (ATmega2560 at 16 MHz).
pub const F_CPU_HZ: u64 = 16_000_000;
/// The board's analog supply and reference (Arduino's DEFAULT reference is AVcc).
const AVCC_MV: u32 = 5000;

/// simavr's ioctl numbers are four characters packed big-endian
/// (`AVR_IOCTL_DEF` in `sim_io.h`, a macro bindgen cannot see).
const fn ioctl(a: u8, b: u8, c: u8, d: u8) -> u32 {
    u32::from_be_bytes([a, b, c, d])
}

/// What can go wrong loading or running the firmware.
#[derive(Debug, Clone, thiserror::Error)]
pub enum AvrError {
    #[error("simavr does not know the MCU {0:?}")]
    UnknownMcu(String),
    #[error("simavr could not initialise the {0} core")]
    Init(String),
    #[error(
        "simavr could not read the firmware {path} — pass an AVR ELF file built for the atmega2560 (or the firmware's source folder, which is built first)"
    )]
    Firmware { path: PathBuf },
    #[error("the simulated {mcu} has no {what}")]
    MissingIo { mcu: &'static str, what: String },
    #[error(
        "the simulated board crashed at cycle {cycle} (an invalid instruction or a jump outside the flash)"
    )]
    Crashed { cycle: u64 },
    #[error("the simulated board stopped (simavr state {state}) at cycle {cycle}")]
    Stopped { state: c_int, cycle: u64 },
}

/// An output pin to watch: its port letter and bit (`('H', 3)` is PH3,
/// Arduino pin 6 on the ATmega2560).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PinId {
    pub port: char,
    pub bit: u8,
}

/// A watched pin changed level at `cycle`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Edge {
    /// Index into the `watch` list given to [`Mcu::load`].
    pub pin: usize,
    pub cycle: u64,
    pub high: bool,
}

/// A device on the board's I2C bus, answering the firmware's TWI master.
/// Called from inside [`Mcu::run_until`] with the cycle of each bus event;
/// only for transfers addressed to it.
pub trait TwiSlave {
    /// The 7-bit bus address it answers (and acknowledges).
    fn address(&self) -> u8;
    /// The master addressed it: `read` is the direction of the transfer.
    fn start(&mut self, read: bool, cycle: u64);
    /// A byte the master wrote; the slave acknowledges every byte.
    fn write(&mut self, byte: u8, cycle: u64);
    /// The master clocks a byte out of the slave.
    fn read(&mut self, cycle: u64) -> u8;
    /// The master ended the transfer.
    fn stop(&mut self, cycle: u64);
}

/// One attached slave's callback parameter.
struct TwiHook {
    avr: *const ffi::avr_t,
    /// The TWI's input IRQ: where the slave's acknowledgements and data go.
    input: *mut ffi::avr_irq_t,
    slave: Rc<RefCell<dyn TwiSlave>>,
    /// The SLA+R/W byte of the transfer addressed to this slave, if any.
    selected: Option<u8>,
}

/// simavr's TWI message (`avr_twi_msg_t`): bit-fields `unused:8, msg:8,
/// addr:8, data:8` from the least significant bit, as GCC lays them out on
/// the little-endian hosts simavr builds for. Replies are built by simavr's
/// own `avr_twi_irq_msg`; `twi_layout_matches_simavr` checks this split.
fn twi_fields(value: u32) -> (u32, u8, u8) {
    let [_, msg, addr, data] = value.to_le_bytes();
    (u32::from(msg), addr, data)
}

/// What the callbacks write. Reached through a raw pointer from C; read by
/// Rust only between calls into simavr.
struct Io {
    avr: *const ffi::avr_t,
    out: Vec<u8>,
    xon: bool,
    edges: Vec<Edge>,
}

/// The parameter of one pin's callback: which pin, and where to record.
struct PinHook {
    io: *mut Io,
    index: usize,
}

/// One simulated ATmega2560 with a firmware loaded.
pub struct Mcu {
    avr: NonNull<ffi::avr_t>,
    io: NonNull<Io>,
    hooks: NonNull<[PinHook]>,
    uart_in: NonNull<ffi::avr_irq_t>,
    adc: NonNull<ffi::avr_irq_t>,
    /// simavr keeps pointers into the firmware description; it lives as long
    /// as the MCU.
    firmware: NonNull<ffi::elf_firmware_t>,
    /// Millivolts on each ADC input, re-applied after a reset.
    adc_mv: [Option<u32>; 16],
    /// One per attached I2C slave; simavr calls back with these.
    twi_hooks: Vec<NonNull<TwiHook>>,
}

impl std::fmt::Debug for Mcu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Mcu").field("cycle", &self.cycle()).finish()
    }
}

unsafe extern "C" fn on_uart_out(_: *mut ffi::avr_irq_t, value: u32, param: *mut c_void) {
    // Safety: `param` is the `Io` this module registered, alive until `Drop`
    // unregisters nothing but frees the AVR first, so no callback outlives it.
    let io = unsafe { &mut *param.cast::<Io>() };
    io.out.push(value as u8);
}

unsafe extern "C" fn on_uart_xon(_: *mut ffi::avr_irq_t, _: u32, param: *mut c_void) {
    // Safety: as in `on_uart_out`.
    unsafe { (*param.cast::<Io>()).xon = true };
}

unsafe extern "C" fn on_uart_xoff(_: *mut ffi::avr_irq_t, _: u32, param: *mut c_void) {
    // Safety: as in `on_uart_out`.
    unsafe { (*param.cast::<Io>()).xon = false };
}

unsafe extern "C" fn on_pin(_: *mut ffi::avr_irq_t, value: u32, param: *mut c_void) {
    // Safety: `param` is one of the `PinHook`s this module registered; the
    // hook and its `Io` live until `Drop`, after the AVR is gone.
    unsafe {
        let hook = &*param.cast::<PinHook>();
        let io = &mut *hook.io;
        let cycle = (*io.avr).cycle;
        io.edges.push(Edge {
            pin: hook.index,
            cycle,
            high: value & 1 == 1,
        });
    }
}

unsafe extern "C" fn on_twi(_: *mut ffi::avr_irq_t, value: u32, param: *mut c_void) {
    // Safety: `param` is a `TwiHook` this module registered, alive until
    // `Drop` (after the AVR is gone); `avr` and `input` belong to that AVR.
    let hook = unsafe { &mut *param.cast::<TwiHook>() };
    let cycle = unsafe { (*hook.avr).cycle };
    // The runner never holds the slave across `run_until`; if something
    // did, the byte is not acknowledged rather than a panic inside C.
    let Ok(mut slave) = hook.slave.try_borrow_mut() else {
        return;
    };
    let (msg, addr, data) = twi_fields(value);
    let reply = |msg: u32, addr: u8, data: u8| {
        // Safety: `input` is the live AVR's TWI input IRQ; simavr handles
        // the reply synchronously, as the master expects.
        unsafe {
            let v = ffi::avr_twi_irq_msg(msg as u8, addr, data);
            ffi::avr_raise_irq(hook.input, v);
        }
    };
    if msg & ffi::TWI_COND_START != 0 {
        hook.selected = None;
        if addr >> 1 == slave.address() {
            hook.selected = Some(addr);
            slave.start(addr & 1 == 1, cycle);
            reply(ffi::TWI_COND_ACK, addr, 1);
        }
    } else if let Some(sla) = hook.selected {
        if msg & ffi::TWI_COND_WRITE != 0 {
            slave.write(data, cycle);
            reply(ffi::TWI_COND_ACK, sla, 1);
        } else if msg & ffi::TWI_COND_READ != 0 {
            let byte = slave.read(cycle);
            reply(ffi::TWI_COND_READ, sla, byte);
        }
    }
    if msg & ffi::TWI_COND_STOP != 0 && hook.selected.take().is_some() {
        slave.stop(cycle);
    }
}

/// simavr's logger, for every message: none is printed. With an AVR each
/// message is below the level `load` sets (0) anyway; without one (the ELF
/// loader's "Loaded … bytes" lines) simavr's own logger would print it on
/// our standard output. What matters is reported through `AvrError`.
/// Generic over the `va_list` argument, whose type differs between
/// architectures; it is never read.
unsafe extern "C" fn quiet_logger<VaList>(
    _: *mut ffi::avr_t,
    _: c_int,
    _: *const c_char,
    _: VaList,
) {
}

impl Mcu {
    /// An ATmega2560 at 16 MHz with `elf` in its flash, reset and ready to
    /// run; `watch` lists the output pins whose edges [`Mcu::take_edges`]
    /// reports.
    pub fn load(elf: &Path, watch: &[PinId]) -> Result<Self, AvrError> {
        const MCU: &str = "atmega2560";
        let name = CString::new(MCU).map_err(|_| AvrError::UnknownMcu(MCU.into()))?;
        let path =
            CString::new(elf.as_os_str().as_encoded_bytes()).map_err(|_| AvrError::Firmware {
                path: elf.to_path_buf(),
            })?;
        static QUIET: std::sync::Once = std::sync::Once::new();
        // Safety: sets a process-wide function pointer simavr reads when it
        // logs; the function ignores its arguments.
        QUIET.call_once(|| unsafe { ffi::avr_global_logger_set(Some(quiet_logger)) });
        // Safety: plain C calls on freshly made objects; every pointer is
        // checked before use and owned by the returned `Mcu` (freed in `Drop`).
        unsafe {
            let firmware: Box<ffi::elf_firmware_t> = Box::new(std::mem::zeroed());
            let firmware = NonNull::from(Box::leak(firmware));
            if ffi::elf_read_firmware(path.as_ptr(), firmware.as_ptr()) != 0 {
                drop(Box::from_raw(firmware.as_ptr()));
                return Err(AvrError::Firmware {
                    path: elf.to_path_buf(),
                });
            }
            let Some(avr) = NonNull::new(ffi::avr_make_mcu_by_name(name.as_ptr())) else {
                drop(Box::from_raw(firmware.as_ptr()));
                return Err(AvrError::UnknownMcu(MCU.into()));
            };
            // simavr's own log goes to stdout unless its level is below every
            // message's: the runner reports what matters itself.
            (*avr.as_ptr()).set_log(0);
            if ffi::avr_init(avr.as_ptr()) != 0 {
                libc::free(avr.as_ptr().cast());
                drop(Box::from_raw(firmware.as_ptr()));
                return Err(AvrError::Init(MCU.into()));
            }
            (*avr.as_ptr()).set_log(0);
            ffi::avr_load_firmware(avr.as_ptr(), firmware.as_ptr());
            let a = &mut *avr.as_ptr();
            a.frequency = F_CPU_HZ as u32;
            a.vcc = AVCC_MV;
            a.avcc = AVCC_MV;
            a.aref = AVCC_MV;

            let io = NonNull::from(Box::leak(Box::new(Io {
                avr: avr.as_ptr(),
                out: Vec::with_capacity(4096),
                xon: true,
                edges: Vec::with_capacity(1024),
            })));
            let hooks: Box<[PinHook]> = (0..watch.len())
                .map(|index| PinHook {
                    io: io.as_ptr(),
                    index,
                })
                .collect();
            let hooks = NonNull::from(Box::leak(hooks));
            let mut mcu = Self {
                avr,
                io,
                hooks,
                uart_in: NonNull::dangling(),
                adc: NonNull::dangling(),
                firmware,
                adc_mv: [None; 16],
                twi_hooks: Vec::new(),
            };
            mcu.connect(watch)?;
            Ok(mcu)
        }
    }

    /// Registers the callbacks and looks up the input IRQs.
    ///
    /// # Safety
    /// Called once from `load`, with `self.avr`, `self.io` and `self.hooks` valid.
    unsafe fn connect(&mut self, watch: &[PinId]) -> Result<(), AvrError> {
        let avr = self.avr.as_ptr();
        let missing = |what: String| AvrError::MissingIo {
            mcu: "atmega2560",
            what,
        };
        let irq = |ctl: u32, index: u32| {
            // Safety: `avr` is a live AVR; simavr returns null for unknown ioctls.
            NonNull::new(unsafe { ffi::avr_io_getirq(avr, ctl, index as c_int) })
        };
        // Safety: `avr` is live; the flags ioctl takes a `u32`.
        unsafe { self.uart_stdio_off() };
        let uart = ioctl(b'u', b'a', b'r', b'0');
        let io = self.io.as_ptr().cast::<c_void>();
        let uart_hooks: [(u32, ffi::avr_irq_notify_t); 3] = [
            (ffi::UART_IRQ_OUTPUT, Some(on_uart_out)),
            (ffi::UART_IRQ_OUT_XON, Some(on_uart_xon)),
            (ffi::UART_IRQ_OUT_XOFF, Some(on_uart_xoff)),
        ];
        for (index, hook) in uart_hooks {
            let i = irq(uart, index).ok_or_else(|| missing("UART0".into()))?;
            // Safety: the hook matches simavr's notify signature; `io` lives until Drop.
            unsafe { ffi::avr_irq_register_notify(i.as_ptr(), hook, io) };
        }
        self.uart_in = irq(uart, ffi::UART_IRQ_INPUT).ok_or_else(|| missing("UART0".into()))?;
        self.adc = irq(ioctl(b'a', b'd', b'c', b'0'), ffi::ADC_IRQ_ADC0)
            .ok_or_else(|| missing("ADC".into()))?;
        // Safety: `hooks` has one entry per watched pin and lives until Drop.
        let hooks = unsafe { self.hooks.as_mut() };
        for (pin, hook) in watch.iter().zip(hooks.iter_mut()) {
            let i = irq(ioctl(b'i', b'o', b'g', pin.port as u8), u32::from(pin.bit))
                .ok_or_else(|| missing(format!("pin P{}{}", pin.port, pin.bit)))?;
            let param = (hook as *mut PinHook).cast::<c_void>();
            // Safety: as above.
            unsafe { ffi::avr_irq_register_notify(i.as_ptr(), Some(on_pin), param) };
        }
        Ok(())
    }

    /// Detaches UART0 from simavr's stdout echo.
    ///
    /// # Safety
    /// `self.avr` must be live.
    unsafe fn uart_stdio_off(&mut self) {
        let avr = self.avr.as_ptr();
        let mut flags: u32 = 0;
        // Safety: the UART flag ioctls take a `u32`.
        unsafe {
            if ffi::avr_ioctl(
                avr,
                ioctl(b'u', b'a', b'g', b'0'),
                (&mut flags as *mut u32).cast(),
            ) == 0
            {
                flags &= !ffi::AVR_UART_FLAG_STDIO;
                ffi::avr_ioctl(
                    avr,
                    ioctl(b'u', b'a', b's', b'0'),
                    (&mut flags as *mut u32).cast(),
                );
            }
        }
    }

    /// Clock cycles since power-up (not reset by [`Mcu::reset`]).
    pub fn cycle(&self) -> u64 {
        // Safety: `avr` is live and not being run (we hold `&self`).
        unsafe { (*self.avr.as_ptr()).cycle }
    }

    /// Runs instructions until the cycle counter reaches `end`.
    pub fn run_until(&mut self, end: u64) -> Result<(), AvrError> {
        let avr = self.avr.as_ptr();
        loop {
            // Safety: `avr` is live; the callbacks it triggers only touch `Io`
            // and the hooks, which nothing else borrows while we hold `&mut self`.
            let (state, cycle) = unsafe {
                let state = ffi::avr_run(avr);
                (state, (*avr).cycle)
            };
            if state == ffi::cpu_Crashed as c_int {
                return Err(AvrError::Crashed { cycle });
            }
            if state == ffi::cpu_Done as c_int || state == ffi::cpu_Stopped as c_int {
                return Err(AvrError::Stopped { state, cycle });
            }
            if cycle >= end {
                return Ok(());
            }
        }
    }

    /// Whether UART0's receiver takes another byte now (simavr's receive
    /// FIFO has room; it hands bytes to the MCU at the baud rate).
    pub fn uart_ready(&self) -> bool {
        // Safety: `io` is live and not being written (no simavr call in progress).
        unsafe { self.io.as_ref().xon }
    }

    /// One byte onto UART0's receive line. Lost, as on the wire, while the
    /// firmware has the receiver off (during reset).
    pub fn uart_send(&mut self, byte: u8) {
        // Safety: `uart_in` is UART0's input IRQ of the live AVR.
        unsafe { ffi::avr_raise_irq(self.uart_in.as_ptr(), u32::from(byte)) };
    }

    /// Appends what the firmware transmitted on UART0 since the last call.
    pub fn take_output(&mut self, into: &mut Vec<u8>) {
        // Safety: no simavr call is in progress (we hold `&mut self`).
        let io = unsafe { self.io.as_mut() };
        into.append(&mut io.out);
    }

    /// Appends the watched pins' edges since the last call, oldest first.
    pub fn take_edges(&mut self, into: &mut Vec<Edge>) {
        // Safety: as in `take_output`.
        let io = unsafe { self.io.as_mut() };
        into.append(&mut io.edges);
    }

    /// Puts `mv` millivolts on ADC input `channel` (0..=15); kept across resets.
    pub fn set_adc_mv(&mut self, channel: u8, mv: u32) {
        let channel = usize::from(channel.min(15));
        self.adc_mv[channel] = Some(mv);
        // Safety: the ADC input IRQs are consecutive from ADC0 (`ADC_IRQ_ADC0..ADC15`).
        unsafe { ffi::avr_raise_irq(self.adc.as_ptr().add(channel), mv) };
    }

    /// Puts `slave` on the I2C bus from now on (kept across resets: the
    /// board's reset line does not reach its sensors). Several slaves share
    /// the bus: each hears every transfer and answers only its own address.
    /// The caller keeps its own `Rc` to change the slave between runs.
    pub fn attach_twi(&mut self, slave: Rc<RefCell<dyn TwiSlave>>) -> Result<(), AvrError> {
        let avr = self.avr.as_ptr();
        // simavr names the ATmega2560's one TWI 0 (`AVR_IOCTL_TWI_GETIRQ`).
        let ctl = ioctl(b't', b'w', b'i', 0);
        // Safety: `avr` is live; simavr returns null for an unknown ioctl.
        let (output, input) = unsafe {
            (
                ffi::avr_io_getirq(avr, ctl, ffi::TWI_IRQ_OUTPUT as c_int),
                ffi::avr_io_getirq(avr, ctl, ffi::TWI_IRQ_INPUT as c_int),
            )
        };
        if output.is_null() || input.is_null() {
            return Err(AvrError::MissingIo {
                mcu: "atmega2560",
                what: "TWI (I2C)".into(),
            });
        }
        let hook = NonNull::from(Box::leak(Box::new(TwiHook {
            avr,
            input,
            slave,
            selected: None,
        })));
        self.twi_hooks.push(hook);
        // Safety: the hook matches simavr's notify signature and lives until Drop.
        unsafe { ffi::avr_irq_register_notify(output, Some(on_twi), hook.as_ptr().cast()) };
        Ok(())
    }

    /// One byte of the MCU's data space (registers and RAM), e.g. a timer's
    /// compare register.
    pub fn data(&self, addr: u16) -> u8 {
        // Safety: `data` spans the whole data space (`ramend + 1` bytes);
        // addresses beyond it read as 0.
        unsafe {
            let a = &*self.avr.as_ptr();
            if u32::from(addr) <= u32::from(a.ramend) {
                *a.data.add(usize::from(addr))
            } else {
                0
            }
        }
    }

    /// A hardware reset (the reset line pulled, as the BeagleBone does to
    /// flash the board): registers and RAM as at power-up, the firmware
    /// starts again from its reset vector. The ADC inputs keep their voltages.
    pub fn reset(&mut self) {
        // Safety: `avr` is live and not running.
        unsafe {
            ffi::avr_reset(self.avr.as_ptr());
            self.uart_stdio_off();
        }
        for (channel, mv) in self.adc_mv.into_iter().enumerate() {
            if let Some(mv) = mv {
                self.set_adc_mv(channel as u8, mv);
            }
        }
    }
}

impl Drop for Mcu {
    fn drop(&mut self) {
        // Safety: the AVR goes first so no callback can run afterwards; then
        // what the callbacks pointed at. `avr_terminate` frees simavr's
        // insides, the `avr_t` itself was `malloc`ed by `avr_make_mcu_by_name`.
        unsafe {
            ffi::avr_terminate(self.avr.as_ptr());
            libc::free(self.avr.as_ptr().cast());
            drop(Box::from_raw(self.hooks.as_ptr()));
            for hook in self.twi_hooks.drain(..) {
                drop(Box::from_raw(hook.as_ptr()));
            }
            drop(Box::from_raw(self.io.as_ptr()));
            drop(Box::from_raw(self.firmware.as_ptr()));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn twi_layout_matches_simavr() {
        // Safety: a pure C function packing three bytes.
        let v = unsafe { ffi::avr_twi_irq_msg(0x12, 0x34, 0x56) };
        assert_eq!(twi_fields(v), (0x12, 0x34, 0x56));
    }
}
