//! Bytes per load of the operator page, before and after compression,
//! caching and the lazy plotting library.
//!
//! `neptunus --sim --http 127.0.0.1:0` runs as a child. The bench fetches
//! the operator page as a browser does: `/`, every file `index.html` links
//! (stylesheets, the module script) and the JavaScript module graph through
//! its static `import … from '…'` lines (a dynamic `import('…')`, the
//! developer view, is not part of the page's load). Each request is a fresh
//! HTTP/1.1 connection with `Connection: close`; the figure is every byte the
//! vehicle sent back (status line, headers, body, chunk framing), so headers
//! and 304s count too.
//!
//! - **before**: the page as it was — every file uncompressed, the plotting
//!   library (`dev.js`, `/vendor/uPlot.esm.js`, `/vendor/uPlot.min.css`)
//!   loaded by the operator page, and no validator, so a reload fetches
//!   everything again. Measured on today's files plus the plotting ones.
//! - **after**: the operator set only, with no `Accept-Encoding`, with gzip,
//!   and with what Chromium sends (`gzip, deflate, br, zstd` → brotli); then
//!   a reload with the ETags from the first load (`If-None-Match` → 304s).
//! - The developer view opened later: `dev.js` and uPlot, brotli.
//!
//! Also the time a whole load takes over loopback (p50 of N loads), which on
//! the vehicle's CPU is mostly compression. Figures are printed, never
//! asserted. The binary is `$NEPTUNUS_BIN`, else `target/release/neptunus`,
//! else `target/debug/neptunus` (with a warning). `cargo bench --bench
//! page_weight` times 30 loads; under `cargo test` (no `--bench`) 3.

#![allow(
    clippy::print_stdout,
    reason = "a bench binary's output is its figures"
)]

#[path = "../tests/common/mod.rs"]
mod common;

use std::collections::BTreeMap;
use std::io::{Read as _, Write as _};
use std::net::{SocketAddr, TcpStream};
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};

/// What Chromium sends with every request.
const CHROMIUM: &str = "gzip, deflate, br, zstd";
/// The developer view's files: fetched only when it is opened.
const PLOTTING: [&str; 3] = [
    "/js/dev.js",
    "/vendor/uPlot.esm.js",
    "/vendor/uPlot.min.css",
];

/// One response as it came off the socket.
struct Fetched {
    status: u16,
    /// Every byte received: head, body and any chunk framing.
    wire: usize,
    head_len: usize,
    headers: BTreeMap<String, String>,
    body: Vec<u8>,
}

fn fetch(addr: SocketAddr, path: &str, extra: &[(&str, &str)]) -> anyhow::Result<Fetched> {
    let mut s = TcpStream::connect(addr)?;
    s.set_read_timeout(Some(Duration::from_secs(20)))?;
    let mut req = format!("GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n");
    for (k, v) in extra {
        req.push_str(&format!("{k}: {v}\r\n"));
    }
    req.push_str("\r\n");
    s.write_all(req.as_bytes())?;
    let mut bytes = Vec::new();
    s.read_to_end(&mut bytes)?;
    let split = bytes
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .with_context(|| format!("{path}: no end of headers"))?;
    let head = String::from_utf8_lossy(&bytes[..split]).into_owned();
    let status = head
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .with_context(|| format!("{path}: no status in {head}"))?;
    let headers: BTreeMap<String, String> = head
        .lines()
        .skip(1)
        .filter_map(|l| {
            let (k, v) = l.split_once(':')?;
            Some((k.trim().to_ascii_lowercase(), v.trim().to_owned()))
        })
        .collect();
    let raw = &bytes[split + 4..];
    let body = if headers
        .get("transfer-encoding")
        .is_some_and(|t| t == "chunked")
    {
        dechunk(raw)
    } else {
        raw.to_vec()
    };
    Ok(Fetched {
        status,
        wire: bytes.len(),
        head_len: split + 4,
        headers,
        body,
    })
}

/// The body of a chunked transfer (sizes in hex, each chunk ends in CRLF).
fn dechunk(mut raw: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    while let Some(eol) = raw.windows(2).position(|w| w == b"\r\n") {
        let size = std::str::from_utf8(&raw[..eol])
            .ok()
            .and_then(|s| usize::from_str_radix(s.split(';').next().unwrap_or("").trim(), 16).ok())
            .unwrap_or(0);
        if size == 0 {
            break;
        }
        let start = eol + 2;
        let Some(chunk) = raw.get(start..start + size) else {
            break;
        };
        out.extend_from_slice(chunk);
        raw = raw.get(start + size + 2..).unwrap_or_default();
    }
    out
}

/// The absolute paths in `attr="/…"` attributes of `index.html`.
fn linked(html: &str) -> Vec<String> {
    let mut out = Vec::new();
    for attr in ["href=\"", "src=\""] {
        let mut rest = html;
        while let Some(i) = rest.find(attr) {
            rest = &rest[i + attr.len()..];
            let end = rest.find('"').unwrap_or(rest.len());
            let v = &rest[..end];
            if v.starts_with('/') && !v.starts_with("//") {
                out.push(v.to_owned());
            }
        }
    }
    out
}

/// The modules a script imports statically (`import … from '/…'`,
/// `import '/…'`, `export … from '/…'`); `import('…')` is lazy, not followed.
fn imports(js: &str) -> Vec<String> {
    js.lines()
        .map(str::trim_start)
        .filter(|l| l.starts_with("import ") || l.starts_with("export "))
        .filter(|l| l.starts_with("import '") || l.starts_with("import \"") || l.contains(" from "))
        .filter_map(|l| {
            let q = l.rfind(['\'', '"'])?;
            let open = l[..q].rfind(['\'', '"'])?;
            let path = &l[open + 1..q];
            path.starts_with('/').then(|| path.to_owned())
        })
        .collect()
}

/// The operator page's files in the order a browser finds them.
fn operator_set(addr: SocketAddr) -> anyhow::Result<Vec<String>> {
    let index = fetch(addr, "/", &[])?;
    if index.status != 200 {
        bail!("GET / answered {}", index.status);
    }
    let mut files = vec!["/".to_owned()];
    let mut queue = linked(&String::from_utf8_lossy(&index.body));
    while let Some(path) = queue.pop() {
        if files.contains(&path) {
            continue;
        }
        let f = fetch(addr, &path, &[])?;
        if f.status != 200 {
            bail!("GET {path} answered {} (linked from the page)", f.status);
        }
        if path.ends_with(".js") {
            queue.extend(imports(&String::from_utf8_lossy(&f.body)));
        }
        files.push(path);
    }
    Ok(files)
}

#[derive(Default, Clone, Copy)]
struct Load {
    files: usize,
    wire: usize,
    head: usize,
}

fn load(addr: SocketAddr, files: &[String], extra: &[(&str, &str)]) -> anyhow::Result<Load> {
    let mut l = Load::default();
    for path in files {
        let f = fetch(addr, path, extra)?;
        if f.status != 200 {
            bail!("GET {path} answered {}", f.status);
        }
        l.files += 1;
        l.wire += f.wire;
        l.head += f.head_len;
    }
    Ok(l)
}

/// A reload: each file with the ETag it came with.
fn reload(addr: SocketAddr, files: &[String]) -> anyhow::Result<(Load, usize)> {
    let mut l = Load::default();
    let mut not_modified = 0;
    for path in files {
        let first = fetch(addr, path, &[("Accept-Encoding", CHROMIUM)])?;
        let tag = first
            .headers
            .get("etag")
            .with_context(|| format!("{path} has no ETag"))?
            .clone();
        let again = fetch(
            addr,
            path,
            &[("Accept-Encoding", CHROMIUM), ("If-None-Match", &tag)],
        )?;
        not_modified += usize::from(again.status == 304);
        l.files += 1;
        l.wire += again.wire;
        l.head += again.head_len;
    }
    Ok((l, not_modified))
}

fn kb(bytes: usize) -> String {
    format!("{:.1} KB", bytes as f64 / 1000.0)
}

fn main() -> anyhow::Result<()> {
    let full = std::env::args().any(|a| a == "--bench");
    let runs = if full { 30 } else { 3 };
    let bin = common::neptunus_bin()?;
    println!("neptunus binary: {}", bin.display());
    let dir = tempfile::tempdir()?;
    let mut vehicle = common::Vehicle::spawn(
        &bin,
        &["--sim", "--mavlink", "udpin:127.0.0.1:0"],
        dir.path(),
        "",
    )?;
    let addr = vehicle.http_addr(Duration::from_secs(30))?;
    vehicle.check_running()?;

    let operator = operator_set(addr)?;
    if let Some(p) = operator.iter().find(|p| PLOTTING.contains(&p.as_str())) {
        bail!(
            "the operator page loads {p}: the plotting library should load with the developer view only"
        );
    }
    println!(
        "operator page: {} files: {}",
        operator.len(),
        operator.join(" ")
    );
    let mut before_files = operator.clone();
    before_files.extend(PLOTTING.iter().map(|p| (*p).to_owned()));

    let before = load(addr, &before_files, &[])?;
    let identity = load(addr, &operator, &[])?;
    let gzip = load(addr, &operator, &[("Accept-Encoding", "gzip")])?;
    let br = load(addr, &operator, &[("Accept-Encoding", CHROMIUM)])?;
    let (cached, not_modified) = reload(addr, &operator)?;
    let plotting: Vec<String> = PLOTTING.iter().map(|p| (*p).to_owned()).collect();
    let dev_plain = load(addr, &plotting, &[])?;
    let dev_br = load(addr, &plotting, &[("Accept-Encoding", CHROMIUM)])?;

    let mut time = |extra: &[(&str, &str)]| -> anyhow::Result<Vec<Duration>> {
        let mut t = Vec::with_capacity(runs);
        for _ in 0..runs {
            let start = Instant::now();
            load(addr, &operator, extra)?;
            t.push(start.elapsed());
        }
        vehicle.check_running()?;
        t.sort();
        Ok(t)
    };
    let t_identity = time(&[])?;
    let t_br = time(&[("Accept-Encoding", CHROMIUM)])?;
    drop(vehicle);

    println!();
    println!("| load | files | bytes on the wire | of which headers | vs before |");
    println!("|---|---|---|---|---|");
    let row = |name: &str, l: &Load| {
        let vs = if l.wire == before.wire {
            "1.0×".to_owned()
        } else {
            format!("{:.1}× less", before.wire as f64 / l.wire.max(1) as f64)
        };
        println!(
            "| {name} | {} | {} | {} | {vs} |",
            l.files,
            kb(l.wire),
            kb(l.head)
        );
    };
    row(
        "before: operator page with uPlot, uncompressed (every load)",
        &before,
    );
    row("after: operator page, no Accept-Encoding", &identity);
    row("after: operator page, gzip", &gzip);
    row("after: operator page, Chromium (brotli)", &br);
    row(
        &format!("after: reload with ETags ({not_modified} × 304)"),
        &cached,
    );
    println!(
        "| developer view opened (dev.js + uPlot), uncompressed / brotli | {} | {} / {} | | |",
        dev_plain.files,
        kb(dev_plain.wire),
        kb(dev_br.wire)
    );
    println!();
    println!(
        "whole operator-page load over loopback, {runs} loads: uncompressed p50 {:.1} ms, brotli p50 {:.1} ms (p99 {:.1} / {:.1} ms)",
        common::pct_ms(&t_identity, 0.50),
        common::pct_ms(&t_br, 0.50),
        common::pct_ms(&t_identity, 0.99),
        common::pct_ms(&t_br, 0.99),
    );
    Ok(())
}
