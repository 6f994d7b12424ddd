//! The `neptunus` binary: parses the command line and hands over to [`neptunus::app`].

use std::io::Write as _;

use anyhow::Context as _;
use clap::Parser as _;
use neptunus::config::{self, Cli, CliCommand, HmiCommand, ProfilesCommand, SigningCommand};
use neptunus::vehicle::input::{Profile, Profiles, ZConvention};

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    match real_main(cli) {
        Ok(code) => code,
        Err(e) => {
            // One clear line (plus causes) rather than a backtrace.
            let mut msg = format!("neptunus: {e}");
            for cause in e.chain().skip(1) {
                msg.push_str(&format!(": {cause}"));
            }
            let _ = writeln!(std::io::stderr(), "{msg}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn real_main(cli: Cli) -> anyhow::Result<std::process::ExitCode> {
    let runtime = || {
        // One thread for the vehicle, its sockets and the serial link; the
        // browser side starts its own (see `app::run`). Few blocking
        // threads: the unit's TasksMax is a ceiling, not a target.
        tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .max_blocking_threads(4)
            .build()
            .context("cannot start the async runtime")
    };
    match cli.command {
        Some(CliCommand::Profiles {
            command: ProfilesCommand::Check { dir },
        }) => profiles_check(dir.as_deref())?,
        Some(CliCommand::SimReport { dir, hil }) => sim_report(&dir, hil.as_deref(), &cli.run)?,
        Some(CliCommand::Doctor { json }) => {
            let report = neptunus::doctor::run(&cli.run);
            let mut out = std::io::stdout();
            if json {
                writeln!(out, "{}", serde_json::to_string_pretty(&report)?)?;
            } else {
                write!(out, "{}", report.text())?;
            }
            if !report.ok {
                return Ok(std::process::ExitCode::FAILURE);
            }
        }
        Some(CliCommand::Signing { command }) => {
            let data_dir = config::resolve(&cli.run)?.data_dir;
            signing(&command, &data_dir)?;
        }
        Some(CliCommand::Hmi { command }) => {
            let settings = config::resolve(&cli.run)?;
            hmi(&command, &settings)?;
        }
        Some(CliCommand::EmulateBoard(args)) => {
            let _log = init_logging(None)?;
            let opts = config::resolve_emulator(&args, cli.run.config.as_deref())?;
            runtime()?.block_on(neptunus::app::emulate_board(
                opts,
                args.link.clone(),
                |path| {
                    let mut out = std::io::stdout();
                    let _ = writeln!(out, "{}", path.display());
                    let _ = out.flush();
                },
                shutdown_signal(),
            ))?;
        }
        #[cfg(feature = "hil")]
        Some(CliCommand::GenuineBoard(args)) => {
            let _log = init_logging(None)?;
            genuine_board(&args, &cli.run)?;
        }
        None if cli.run.check => {
            let settings = config::resolve(&cli.run)?;
            check_summary(&cli.run, &settings)?;
        }
        None => {
            let settings = config::resolve(&cli.run)?;
            // A broken data directory degrades (app::run says how, loudly);
            // it never keeps the vehicle from starting.
            // init_logging falls back to stderr alone when the log file cannot be opened.
            let _ = std::fs::create_dir_all(&settings.data_dir);
            let _log = init_logging(Some(&settings.data_dir))?;
            tracing::info!(data_dir = %settings.data_dir.display(), "neptunus {} starting", env!("CARGO_PKG_VERSION"));
            raise_open_file_limit();
            // The vehicle's loop runs as a task, not as the future the
            // runtime blocks on: a task that another task on this thread
            // wakes is queued, while the future blocked on is woken through
            // the runtime's eventfd — a write and an extra poll of the
            // descriptors for every board line and datagram that reaches it.
            runtime()?.block_on(async move {
                match tokio::spawn(neptunus::app::run(settings, shutdown_signal())).await {
                    Ok(ran) => ran.map_err(anyhow::Error::from),
                    Err(e) if e.is_panic() => std::panic::resume_unwind(e.into_panic()),
                    Err(e) => Err(anyhow::anyhow!("the vehicle task ended: {e}")),
                }
            })?;
        }
    }
    Ok(std::process::ExitCode::SUCCESS)
}

/// `genuine-board`: builds (or finds) the firmware, runs it in simavr behind a
/// pty, prints the pty's path, and runs until interrupted.
#[cfg(feature = "hil")]
fn genuine_board(args: &config::GenuineArgs, run: &config::RunArgs) -> anyhow::Result<()> {
    use neptunus::hil::{Analog, GenuineBoard, Wiring, prepare};
    let cache = config::resolve(run)?.data_dir.join("openrov-firmware");
    let firmware = prepare(&args.firmware, &cache)?;
    let framing = firmware.framing;
    if args.build_only {
        let mut out = std::io::stdout();
        writeln!(out, "{}\t{framing}", firmware.elf.display())?;
        out.flush()?;
        return Ok(());
    }
    let analog = Analog {
        battery_v: args.battery_v,
        ..Analog::default()
    };
    let wiring = Wiring {
        analog,
        depth_sensor: !args.no_depth_sensor,
        imu: !args.no_imu,
    };
    let board = GenuineBoard::spawn(firmware, wiring, args.link.clone())?;
    let mut out = std::io::stdout();
    writeln!(out, "{}", board.path().display())?;
    out.flush()?;
    tracing::info!(%framing, elf = %board.firmware().elf.display(), "genuine board running; pass --serial {} --framing {framing} to neptunus", board.path().display());
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("cannot start the async runtime")?;
    rt.block_on(shutdown_signal());
    drop(board);
    Ok(())
}

/// `sim-report` in a build without its plots (the package's): says how to
/// get one, before running anything.
#[cfg(not(feature = "report"))]
fn sim_report(
    _dir: &std::path::Path,
    _hil: Option<&std::path::Path>,
    _run: &config::RunArgs,
) -> anyhow::Result<()> {
    anyhow::bail!(
        "this neptunus was built without the simulator report's plots (the package leaves them out): \
         build it with the `report` feature (`cargo run --features report -- sim-report DIR`)"
    )
}

/// `sim-report [--hil FIRMWARE] DIR`: the scenarios on the simulator, and
/// with the genuine firmware in the loop beside them if asked.
#[cfg(feature = "report")]
fn sim_report(
    dir: &std::path::Path,
    hil: Option<&std::path::Path>,
    run: &config::RunArgs,
) -> anyhow::Result<()> {
    use neptunus::scenario::report;
    let mut out = std::io::stdout();
    let written = match hil {
        None => {
            let outcomes = report::all();
            for o in &outcomes {
                for (name, value, unit) in &o.metrics {
                    writeln!(out, "{:<22} {name:<28} {value:>9.3} {unit}", o.name)?;
                }
            }
            report::write(dir, &outcomes)?
        }
        Some(firmware) => {
            // The firmware first: a build or a board that fails says so at once.
            let genuine = sim_report_hil(firmware, run)?;
            let outcomes = report::all();
            write!(out, "{}", report::comparison_text(&outcomes, &genuine))?;
            report::write_beside(dir, &outcomes, &genuine)?
        }
    };
    writeln!(out, "wrote {} files to {}", written.len(), dir.display())?;
    Ok(())
}

/// The scenarios with the genuine firmware in the loop, and what that took.
#[cfg(feature = "hil")]
fn sim_report_hil(
    firmware: &std::path::Path,
    run: &config::RunArgs,
) -> anyhow::Result<Vec<neptunus::scenario::report::Outcome>> {
    use neptunus::hil::lockstep::GenuineRigs;
    let cache = config::resolve(run)?.data_dir.join("openrov-firmware");
    let firmware = neptunus::hil::prepare(firmware, &cache)?;
    let mut out = std::io::stdout();
    writeln!(
        out,
        "running the scenarios with the genuine firmware {} ({}) in simavr …",
        firmware.elf.display(),
        firmware.framing
    )?;
    let started = std::time::Instant::now();
    let mut rigs = GenuineRigs::new(firmware);
    let outcomes = neptunus::scenario::report::all_on(&mut rigs)?;
    let wall_s = started.elapsed().as_secs_f64();
    let board_s: f64 = outcomes
        .iter()
        .map(|o| o.samples.last().map_or(0.0, |s| s.t_s))
        .chain(rigs.runs().iter().map(|f| f.boot_s))
        .sum();
    writeln!(
        out,
        "{} scenarios, {board_s:.0} s of board time (boot included) in {wall_s:.0} s of wall time ({:.1}× real time)",
        outcomes.len(),
        board_s / wall_s.max(1e-9)
    )?;
    Ok(outcomes)
}

#[cfg(all(feature = "report", not(feature = "hil")))]
fn sim_report_hil(
    _firmware: &std::path::Path,
    _run: &config::RunArgs,
) -> anyhow::Result<Vec<neptunus::scenario::report::Outcome>> {
    anyhow::bail!(config::hil_not_built("sim-report --hil FIRMWARE DIR"))
}

/// `--check`: what the configuration resolves to, for the operator to read.
fn check_summary(args: &config::RunArgs, s: &config::Settings) -> anyhow::Result<()> {
    let mut out = std::io::stdout().lock();
    match &args.config {
        Some(p) => writeln!(out, "configuration {} is valid", p.display())?,
        None => writeln!(
            out,
            "no configuration file: flags and built-in defaults are valid"
        )?,
    }
    match &s.board {
        config::BoardSource::Simulated(_) => writeln!(
            out,
            "board:     simulated (board emulator on a pseudo-terminal)"
        )?,
        config::BoardSource::Genuine { firmware, .. } => writeln!(
            out,
            "board:     the genuine firmware {} in simavr, driving the simulator",
            firmware.display()
        )?,
        config::BoardSource::Serial => writeln!(
            out,
            "board:     {} at {} baud, framing {}",
            s.link.device.display(),
            s.link.baud,
            s.link.framing
        )?,
    }
    writeln!(out, "data:      {}", s.data_dir.display())?;
    for e in &s.mavlink.endpoints {
        writeln!(out, "mavlink:   {e}")?;
    }
    match s.hmi.http {
        Some(a) => writeln!(out, "hmi:       http://{a}/")?,
        None => writeln!(out, "hmi:       off")?,
    }
    writeln!(
        out,
        "camera:    {} (rotation {}°), encode {} ({} on this build)",
        s.camera.source.as_str(),
        s.camera.rotation_deg,
        s.camera.encode.as_str(),
        s.camera.encode.resolve().as_str()
    )?;
    let w = &s.camera.webrtc;
    let signalling = neptunus::camera::webrtc::SignallingAddr::resolve(w.signalling, s.hmi.http);
    match (w.enabled && s.hmi.http.is_some(), signalling) {
        (false, _) => writeln!(out, "webrtc:    off")?,
        (true, Some(a)) => writeln!(
            out,
            "webrtc:    signalling on ws://{a}/ and the HMI's /webrtc, {} ICE servers",
            w.ice_servers.len()
        )?,
        (true, None) => writeln!(
            out,
            "webrtc:    signalling on the HMI's /webrtc, {} ICE servers",
            w.ice_servers.len()
        )?,
    }
    writeln!(
        out,
        "storage:   recordings in {} stop below {} MiB free or at {} MiB of logs and recordings",
        neptunus::camera::record::recordings_dir(&s.data_dir).display(),
        s.storage.min_free_mb,
        s.storage.total_mb
    )?;
    Ok(())
}

/// `neptunus signing set-passphrase|clear|status`.
fn signing(command: &SigningCommand, data_dir: &std::path::Path) -> anyhow::Result<()> {
    use neptunus::mavlink::signing::{SigningKey, SigningStore};
    let store = SigningStore::new(data_dir);
    let path = data_dir.join(SigningStore::KEY_FILE);
    let mut out = std::io::stdout();
    match command {
        SigningCommand::SetPassphrase { passphrase } => {
            let passphrase = match passphrase {
                Some(p) => p.clone(),
                None => {
                    let mut line = String::new();
                    std::io::stdin()
                        .read_line(&mut line)
                        .context("cannot read the passphrase from standard input")?;
                    line.trim_end_matches(['\r', '\n']).to_owned()
                }
            };
            if passphrase.is_empty() {
                anyhow::bail!("the passphrase is empty: give one, or use `neptunus signing clear`");
            }
            std::fs::create_dir_all(data_dir)
                .with_context(|| format!("cannot create data directory {}", data_dir.display()))?;
            store.save_key(Some(&SigningKey::from_passphrase(&passphrase)))?;
            writeln!(
                out,
                "signing key set in {} (mode 0600); restart neptunus",
                path.display()
            )?;
        }
        SigningCommand::Clear => {
            store.save_key(None)?;
            writeln!(out, "signing key removed: signing off at the next start")?;
        }
        SigningCommand::Status => match store.load_key()? {
            Some(_) => writeln!(out, "signing on: key in {}", path.display())?,
            None => writeln!(out, "signing off: no key in {}", path.display())?,
        },
    }
    Ok(())
}

/// `neptunus hmi set-password|clear-password|status|tls-fingerprint`.
fn hmi(command: &HmiCommand, settings: &config::Settings) -> anyhow::Result<()> {
    use neptunus::hmi::auth::PasswordStore;
    use std::io::IsTerminal as _;
    let store = PasswordStore::new(&settings.data_dir);
    let mut out = std::io::stdout();
    match command {
        HmiCommand::SetPassword => {
            let password = if std::io::stdin().is_terminal() {
                let first = rpassword::prompt_password("New HMI pilot password: ")
                    .context("cannot read the password from the terminal")?;
                let again = rpassword::prompt_password("The same again: ")
                    .context("cannot read the password from the terminal")?;
                if first != again {
                    anyhow::bail!(
                        "the two passwords differ: nothing changed — run `neptunus hmi set-password` again"
                    );
                }
                first
            } else {
                let mut line = String::new();
                std::io::stdin()
                    .read_line(&mut line)
                    .context("cannot read the password from standard input")?;
                line.trim_end_matches(['\r', '\n']).to_owned()
            };
            store.set(&password)?;
            writeln!(
                out,
                "HMI pilot password set in {} (argon2 hash, mode 0600); restart neptunus",
                store.path().display()
            )?;
        }
        HmiCommand::ClearPassword => {
            if store.clear()? {
                writeln!(
                    out,
                    "HMI pilot password removed: at the next start only [hmi] open_control addresses may pilot"
                )?;
            } else {
                writeln!(
                    out,
                    "no HMI pilot password was set ({})",
                    store.path().display()
                )?;
            }
        }
        HmiCommand::Status => match store.load()? {
            Some(_) => writeln!(out, "HMI pilot password set: {}", store.path().display())?,
            None => writeln!(
                out,
                "no HMI pilot password: {} does not exist",
                store.path().display()
            )?,
        },
        HmiCommand::TlsFingerprint => {
            let tls = &settings.hmi.tls;
            let (path, fingerprint, generated) =
                neptunus::hmi::tls::served_fingerprint(tls, &settings.data_dir)?;
            if generated {
                writeln!(out, "made a self-signed certificate: {}", path.display())?;
            }
            writeln!(out, "SHA-256 fingerprint of {}:", path.display())?;
            writeln!(out, "{fingerprint}")?;
            if tls.mode == neptunus::hmi::tls::TlsMode::Off {
                writeln!(
                    out,
                    "(TLS is off in this configuration: this is the certificate tls = \"self-signed\" serves)"
                )?;
            }
        }
    }
    Ok(())
}

/// `neptunus profiles check [DIR]`: one line per profile, then the fallback.
fn profiles_check(dir: Option<&std::path::Path>) -> anyhow::Result<()> {
    let (source, profiles) = match dir {
        Some(d) => (d.display().to_string(), Profiles::load_dir(d)?),
        None => ("built-in".to_owned(), Profiles::try_builtin()?),
    };
    let line = |p: &Profile| {
        let sysids = if p.sysids.is_empty() {
            "none".to_owned()
        } else {
            p.sysids
                .iter()
                .map(u8::to_string)
                .collect::<Vec<_>>()
                .join(",")
        };
        let z = match p.z_convention {
            ZConvention::ZeroToThousand => "zero_to_thousand",
            ZConvention::Centered => "centered",
        };
        format!(
            "{:<16} sysids {:<40} z {:<16} deadband {:.2} expo {:.2}",
            p.name, sysids, z, p.deadband, p.expo
        )
    };
    let mut out = std::io::stdout().lock();
    writeln!(out, "{} profiles ({source}):", profiles.profiles().len())?;
    for p in profiles.profiles() {
        writeln!(out, "  {}", line(p))?;
    }
    writeln!(out, "  {} (any other sender)", line(profiles.fallback()))?;
    Ok(())
}

/// Logs to stderr and, for the vehicle, to `neptunus.log` in the data
/// directory, rotated by size (10 MiB × 5 files). A log file that cannot be
/// opened (read-only or full data directory) is said loudly on stderr and
/// the vehicle runs on, logging to stderr only.
///
/// Each destination is written by a thread of its own: the vehicle's loop
/// only queues a line. A destination that stops taking lines (a disk the
/// kernel is flushing, a stalled journal, a terminal nobody reads) holds up
/// to [`LOG_QUEUE_LINES`] of them, then drops and counts the rest — it never
/// stops the loop that feeds the board, which would disarm the vehicle.
/// Keep the returned [`LogWriters`] until the program ends: dropping it
/// writes out what is queued.
fn init_logging(data_dir: Option<&std::path::Path>) -> anyhow::Result<LogWriters> {
    use neptunus::logfile::{DEFAULT_FILES, DEFAULT_MAX_BYTES, RotatingFile};
    use tracing_subscriber::prelude::*;
    let mut writers = LogWriters::default();
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let stderr =
        tracing_subscriber::fmt::layer().with_writer(writers.add("stderr", std::io::stderr()));
    let mut unopened = None;
    let file = match data_dir {
        Some(dir) => {
            let path = dir.join("neptunus.log");
            match RotatingFile::open(&path, DEFAULT_MAX_BYTES, DEFAULT_FILES) {
                Ok(f) => Some(
                    tracing_subscriber::fmt::layer()
                        .with_ansi(false)
                        .with_writer(writers.add("neptunus.log", f)),
                ),
                Err(e) => {
                    unopened = Some((path, e));
                    None
                }
            }
        }
        None => None,
    };
    tracing_subscriber::registry()
        .with(filter)
        .with(stderr)
        .with(file)
        .init();
    if let Some((path, e)) = unopened {
        tracing::error!(
            path = %path.display(), error = %e,
            "CANNOT OPEN THE LOG FILE: logging to stderr only — make the data directory \
             writable (or free space on it), or pass another --data-dir"
        );
    }
    Ok(writers)
}

/// How many lines a log destination that has stopped taking them holds
/// before it drops (about 2 MB of the vehicle's lines).
const LOG_QUEUE_LINES: usize = 10_000;

/// The log's writer threads. Dropped at the end of the program: it says how
/// many lines were dropped, if any, then writes out what is queued (waiting
/// at most a second for a destination that is stuck).
#[derive(Default)]
struct LogWriters {
    guards: Vec<tracing_appender::non_blocking::WorkerGuard>,
    dropped: Vec<(&'static str, tracing_appender::non_blocking::ErrorCounter)>,
}

impl LogWriters {
    fn add(
        &mut self,
        name: &'static str,
        to: impl std::io::Write + Send + 'static,
    ) -> tracing_appender::non_blocking::NonBlocking {
        let (writer, guard) = tracing_appender::non_blocking::NonBlockingBuilder::default()
            .lossy(true)
            .buffered_lines_limit(LOG_QUEUE_LINES)
            .thread_name("neptunus-log")
            .finish(to);
        self.dropped.push((name, writer.error_counter()));
        self.guards.push(guard);
        writer
    }
}

impl Drop for LogWriters {
    fn drop(&mut self) {
        for (name, counter) in &self.dropped {
            let n = counter.dropped_lines();
            if n > 0 {
                tracing::warn!(
                    "{n} log lines were dropped: {name} stopped taking them for a while"
                );
            }
        }
    }
}

/// Raises the soft open-file limit to the hard one: every ground station,
/// browser session and log holds descriptors, and a connection flood should
/// meet the peer table's bound, not EMFILE.
fn raise_open_file_limit() {
    use nix::sys::resource::{Resource, getrlimit, setrlimit};
    // RLIM_INFINITY is not a valid soft limit for descriptors (fs.nr_open caps it).
    // `rlim_t` is 64 bits on x86_64 and arm64 but 32 on armhf: the ceiling
    // is written in the platform's own type.
    const CEILING: nix::libc::rlim_t = 1 << 20;
    match getrlimit(Resource::RLIMIT_NOFILE) {
        Ok((soft, hard)) => {
            let target = hard.min(CEILING);
            if soft >= target {
                tracing::info!(soft, hard, "open-file limit");
                return;
            }
            match setrlimit(Resource::RLIMIT_NOFILE, target, hard) {
                Ok(()) => tracing::info!(from = soft, to = target, hard, "open-file limit raised"),
                Err(e) => {
                    tracing::warn!(soft, hard, error = %e, "cannot raise the open-file limit")
                }
            }
        }
        Err(e) => tracing::warn!(error = %e, "cannot read the open-file limit"),
    }
}

async fn shutdown_signal() {
    let ctrl_c = tokio::signal::ctrl_c();
    #[cfg(unix)]
    {
        let mut term =
            match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
                Ok(s) => s,
                Err(_) => {
                    let _ = ctrl_c.await;
                    return;
                }
            };
        tokio::select! {
            _ = ctrl_c => {}
            _ = term.recv() => {}
        }
    }
    #[cfg(not(unix))]
    {
        let _ = ctrl_c.await;
    }
}
