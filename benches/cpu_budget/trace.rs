//! Counting the ARM instructions a program executes under qemu-arm, from
//! qemu's own logs (the Debian builds have no TCG plugins, and this machine
//! no hardware counters): `-d in_asm` prints each translated block's guest
//! instructions once, when it is translated; `-d exec` prints a line for
//! every block executed, and with `nochain` every block goes back through
//! the loop that prints it (no block jumps straight into the next one);
//! `-d strace` prints a line for every system call. The log goes to a FIFO
//! that a thread of the bench reads as qemu writes it: the count is the sum,
//! over the executed blocks, of each block's instruction count.
//!
//! What this misses, and says: a block that leaves early (a fault in the
//! middle) is counted whole; a block translated again at the same address
//! with another length is counted with the newest length
//! ([`Counts::resized`] says how often that happened). [`crate`]'s method
//! check compares the count with qemu's one-instruction-per-block mode on a
//! fixed program.

use std::collections::HashMap;
use std::io::BufReader;
use std::os::unix::fs::OpenOptionsExt as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::thread::JoinHandle;

use anyhow::Context as _;

/// The running totals, readable while qemu runs.
#[derive(Default)]
pub struct Totals {
    pub insns: AtomicU64,
    pub blocks: AtomicU64,
    pub syscalls: AtomicU64,
    /// Executed blocks never seen translated (counted as 0 instructions).
    pub unknown: AtomicU64,
    /// Blocks translated again at an address with a different length.
    pub resized: AtomicU64,
}

/// A snapshot of [`Totals`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Counts {
    pub insns: u64,
    pub blocks: u64,
    pub syscalls: u64,
    pub unknown: u64,
    pub resized: u64,
}

impl std::ops::Sub for Counts {
    type Output = Counts;
    fn sub(self, o: Counts) -> Counts {
        Counts {
            insns: self.insns.saturating_sub(o.insns),
            blocks: self.blocks.saturating_sub(o.blocks),
            syscalls: self.syscalls.saturating_sub(o.syscalls),
            unknown: self.unknown.saturating_sub(o.unknown),
            resized: self.resized.saturating_sub(o.resized),
        }
    }
}

impl Totals {
    pub fn counts(&self) -> Counts {
        let l = |a: &AtomicU64| a.load(Ordering::Acquire);
        Counts {
            insns: l(&self.insns),
            blocks: l(&self.blocks),
            syscalls: l(&self.syscalls),
            unknown: l(&self.unknown),
            resized: l(&self.resized),
        }
    }
}

/// The reader of one qemu log FIFO.
pub struct Tracer {
    fifo: PathBuf,
    pub totals: Arc<Totals>,
    thread: Option<JoinHandle<anyhow::Result<()>>>,
}

impl Tracer {
    /// Makes the FIFO `fifo` and a thread that reads it once qemu opens it.
    pub fn start(fifo: &Path) -> anyhow::Result<Self> {
        nix::unistd::mkfifo(
            fifo,
            nix::sys::stat::Mode::S_IRUSR | nix::sys::stat::Mode::S_IWUSR,
        )
        .with_context(|| format!("mkfifo {}", fifo.display()))?;
        let totals = Arc::new(Totals::default());
        let path = fifo.to_path_buf();
        let t = Arc::clone(&totals);
        let thread = std::thread::Builder::new()
            .name("qemu-log".into())
            .spawn(move || {
                let file = std::fs::File::open(&path)
                    .with_context(|| format!("open {}", path.display()))?;
                read_log(BufReader::with_capacity(1 << 20, file), &t)
            })?;
        Ok(Self {
            fifo: fifo.to_path_buf(),
            totals,
            thread: Some(thread),
        })
    }

    /// Waits for qemu to close the log (it has exited) and returns the totals.
    pub fn finish(mut self) -> anyhow::Result<Counts> {
        // A reader still waiting for qemu to open the FIFO (qemu never
        // started) is let go by a writer that opens and closes it; with
        // qemu's end open, this adds nothing.
        let _ = std::fs::OpenOptions::new()
            .write(true)
            .custom_flags(nix::fcntl::OFlag::O_NONBLOCK.bits())
            .open(&self.fifo);
        if let Some(t) = self.thread.take() {
            t.join()
                .map_err(|_| anyhow::anyhow!("the qemu log reader panicked"))??;
        }
        Ok(self.totals.counts())
    }
}

/// The state of the parser between lines.
#[derive(Default)]
struct Parser {
    /// Instructions per translated block, by guest address.
    sizes: HashMap<u64, u32>,
    /// The block being listed after an `IN:` line: its address and length.
    listing: Option<(Option<u64>, u32)>,
}

impl Parser {
    fn end_listing(&mut self, totals: &Totals) {
        if let Some((Some(pc), n)) = self.listing.take()
            && let Some(old) = self.sizes.insert(pc, n)
            && old != n
        {
            totals.resized.fetch_add(1, Ordering::Relaxed);
        }
    }

    fn line(&mut self, line: &[u8], totals: &Totals) {
        // A system call's line may be cut by another thread's block line
        // (the call is printed, the result after it returns), so a block
        // line is looked for anywhere in the line.
        if let Some(at) = find(line, b"Trace ") {
            if at > 0 {
                self.syscall(&line[..at], totals);
            }
            self.end_listing(totals);
            self.exec(&line[at..], totals);
            return;
        }
        if line.starts_with(b"IN:") {
            self.end_listing(totals);
            self.listing = Some((None, 0));
            return;
        }
        if let Some((start, n)) = &mut self.listing {
            if let Some(pc) = guest_address(line) {
                if start.is_none() {
                    *start = Some(pc);
                }
                *n += 1;
                return;
            }
            if line.iter().all(u8::is_ascii_whitespace) {
                self.end_listing(totals);
                return;
            }
        }
        self.syscall(line, totals);
    }

    /// `Trace 0: 0x7f… [cs_base/pc/flags/cflags] symbol`
    fn exec(&mut self, line: &[u8], totals: &Totals) {
        let pc = find(line, b"[").and_then(|open| {
            let fields = &line[open + 1..];
            let first = find(fields, b"/")?;
            let rest = &fields[first + 1..];
            let end = find(rest, b"/")?;
            u64::from_str_radix(std::str::from_utf8(&rest[..end]).ok()?, 16).ok()
        });
        totals.blocks.fetch_add(1, Ordering::Relaxed);
        match pc.and_then(|pc| self.sizes.get(&pc)) {
            Some(n) => {
                totals.insns.fetch_add(u64::from(*n), Ordering::Relaxed);
            }
            None => {
                totals.unknown.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// `PID name(args…)`: qemu's strace line of one system call.
    fn syscall(&mut self, line: &[u8], totals: &Totals) {
        let digits = line.iter().take_while(|b| b.is_ascii_digit()).count();
        if digits > 0
            && line.get(digits) == Some(&b' ')
            && line[digits + 1..]
                .iter()
                .take_while(|b| b.is_ascii_alphanumeric() || **b == b'_')
                .count()
                > 0
            && find(&line[digits + 1..], b"(").is_some()
        {
            totals.syscalls.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// `0x00400530:  b500  push {lr}` -> 0x400530.
fn guest_address(line: &[u8]) -> Option<u64> {
    let rest = line.strip_prefix(b"0x")?;
    let colon = find(rest, b":")?;
    u64::from_str_radix(std::str::from_utf8(&rest[..colon]).ok()?, 16).ok()
}

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

fn read_log(mut r: impl std::io::BufRead, totals: &Totals) -> anyhow::Result<()> {
    let mut parser = Parser::default();
    let mut line = Vec::with_capacity(256);
    loop {
        line.clear();
        if r.read_until(b'\n', &mut line)? == 0 {
            parser.end_listing(totals);
            return Ok(());
        }
        if line.last() == Some(&b'\n') {
            line.pop();
        }
        parser.line(&line, totals);
    }
}
