//! Generates the `neptunus` MAVLink dialect from `dialect/*.xml`, and
//! stages the browser HMI's plotting library (uPlot) for embedding: from
//! `NEPTUNUS_UPLOT_DIR` without npm, else from `npm ci` in `web/`.
//!
//! The upstream definitions (development.xml, common.xml, standard.xml,
//! minimal.xml, ardupilotmega.xml and its includes) are taken from the `mavlink` crate's own package, so the
//! repository never carries a copy of them. Both are staged into OUT_DIR
//! because `<include>` paths resolve relative to the including file.

use std::env;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;

const MAVLINK_VERSION: &str = "0.21.0";

fn main() {
    let manifest_dir =
        PathBuf::from(env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let out_dir = PathBuf::from(env::var("OUT_DIR").expect("cargo sets OUT_DIR"));
    web_dependencies(&manifest_dir.join("web"), &out_dir);
    build_date();
    packed_relocations();
    let dialect_dir = manifest_dir.join("dialect");
    println!("cargo:rerun-if-changed={}", dialect_dir.display());
    println!("cargo:rerun-if-env-changed=NEPTUNUS_MAVLINK_XML_DIR");

    let upstream = upstream_definitions_dir().unwrap_or_else(|| {
        panic!(
            "cannot find the MAVLink XML definitions of the mavlink {MAVLINK_VERSION} crate package; \
             set NEPTUNUS_MAVLINK_XML_DIR to its mavlink/message_definitions/v1.0 folder"
        )
    });

    let staging = out_dir.join("definitions");
    let _ = fs::remove_dir_all(&staging);
    fs::create_dir_all(&staging).expect("create staging dir for MAVLink XML");
    for name in [
        "minimal.xml",
        "standard.xml",
        "common.xml",
        "development.xml",
        "ardupilotmega.xml",
        "uAvionix.xml",
        "icarous.xml",
        "loweheiser.xml",
        "cubepilot.xml",
        "csAirLink.xml",
    ] {
        fs::copy(upstream.join(name), staging.join(name))
            .unwrap_or_else(|e| panic!("copy upstream {name} from {}: {e}", upstream.display()));
    }
    let mut ours = Vec::new();
    for entry in fs::read_dir(&dialect_dir).expect("read dialect/") {
        let path = entry.expect("dialect/ entry").path();
        if path.extension().is_some_and(|e| e == "xml") {
            println!("cargo:rerun-if-changed={}", path.display());
            let target = staging.join(path.file_name().expect("file name"));
            fs::copy(&path, &target).expect("stage dialect xml");
            if path.file_stem().is_some_and(|s| s == "neptunus") {
                ours.push(target);
            }
        }
    }
    assert!(!ours.is_empty(), "dialect/neptunus.xml is missing");

    let generated = out_dir.join("dialect");
    fs::create_dir_all(&generated).expect("create generated dialect dir");
    let result =
        mavlink_bindgen::generate(mavlink_bindgen::XmlDefinitions::Files(ours), &generated)
            .unwrap_or_else(|e| panic!("mavlink-bindgen failed on dialect/neptunus.xml: {e}"));
    mavlink_bindgen::format_generated_code(&result);
    json_shape(&generated.join("neptunus.rs"));
}

/// Gives the generated types the JSON shape of mavlink2rest (what Cockpit
/// reads and sends) when the crate's `serde` feature is on: bitflags as
/// `{"bits":N}` (bitflags 2's own serde writes flag names) and char arrays
/// as arrays of one-character strings (mavlink-core writes one string).
/// Both go through `crate::dialect::json_shape`. The rewrite is checked:
/// a generator change that leaves nothing to rewrite stops the build.
fn json_shape(file: &Path) {
    const BITS_DERIVE: &str =
        "# [cfg_attr (feature = \"serde\" , derive (Serialize , Deserialize))] ";
    const CHARS_ATTR: &str =
        "#[cfg_attr(feature = \"serde\", serde(with = \"crate::dialect::json_shape::chars\"))]";
    let text = fs::read_to_string(file).expect("read the generated dialect");
    let mut out = String::with_capacity(text.len() + 64 * 1024);
    let (mut flags, mut chars) = (0usize, 0usize);
    for line in text.lines() {
        if line.starts_with("bitflags! {") && line.contains(BITS_DERIVE) {
            out.push_str(&line.replacen(BITS_DERIVE, "", 1));
            out.push('\n');
            // `pub struct NAME : TYPE {`
            let decl = line
                .split("pub struct ")
                .nth(1)
                .and_then(|rest| rest.split(" {").next())
                .and_then(|d| d.split_once(" : "))
                .unwrap_or_else(|| {
                    panic!("unexpected bitflags line in the generated dialect: {line}")
                });
            out.push_str(&format!(
                "crate::dialect::json_shape::bits_serde!({}, {});\n",
                decl.0.trim(),
                decl.1.trim()
            ));
            flags += 1;
            continue;
        }
        let trimmed = line.trim_start();
        if trimmed.starts_with("pub ") && trimmed.contains(": CharArray<") {
            out.push_str(CHARS_ATTR);
            out.push('\n');
            chars += 1;
        }
        out.push_str(line);
        out.push('\n');
    }
    assert!(
        flags > 0 && chars > 0,
        "the generated dialect has no bitflags ({flags}) or char arrays ({chars}) to give the mavlink2rest JSON shape: \
         mavlink-bindgen's output changed — update build.rs::json_shape"
    );
    fs::write(file, out).expect("write the generated dialect");
}

/// The `mavlink/message_definitions/v1.0` folder of the mavlink crate package.
fn upstream_definitions_dir() -> Option<PathBuf> {
    if let Ok(dir) = env::var("NEPTUNUS_MAVLINK_XML_DIR") {
        return Some(PathBuf::from(dir));
    }
    let rel = Path::new("mavlink")
        .join("message_definitions")
        .join("v1.0");
    // The registry cache first: no subprocess, works offline.
    let cargo_home = env::var("CARGO_HOME").map(PathBuf::from).ok().or_else(|| {
        env::var("HOME")
            .ok()
            .map(|h| PathBuf::from(h).join(".cargo"))
    });
    if let Some(home) = cargo_home
        && let Ok(registries) = fs::read_dir(home.join("registry").join("src"))
    {
        for reg in registries.flatten() {
            let candidate = reg
                .path()
                .join(format!("mavlink-{MAVLINK_VERSION}"))
                .join(&rel);
            if candidate.join("development.xml").is_file() {
                return Some(candidate);
            }
        }
    }
    // Otherwise ask cargo where the package lives (vendored sources, custom registries).
    let cargo = env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let manifest = env::var("CARGO_MANIFEST_DIR").ok()?;
    let out = Command::new(cargo)
        .args([
            "metadata",
            "--format-version",
            "1",
            "--offline",
            "--manifest-path",
        ])
        .arg(Path::new(&manifest).join("Cargo.toml"))
        .output()
        .ok()?;
    let text = String::from_utf8_lossy(&out.stdout);
    let needle = format!("mavlink-{MAVLINK_VERSION}");
    text.split('"')
        .filter(|s| s.contains(&needle) && s.ends_with("Cargo.toml"))
        .map(|s| Path::new(s).parent().map(|p| p.join(&rel)))
        .find_map(|p| p.filter(|p| p.join("development.xml").is_file()))
}

/// The files of the page's plotting library (uPlot) that the HMI embeds.
const UPLOT_FILES: [&str; 2] = ["uPlot.esm.js", "uPlot.min.css"];

/// Stages uPlot's two distributed files in `OUT_DIR/uplot/`, which the HMI
/// embeds (rust-embed): from `NEPTUNUS_UPLOT_DIR` when set — a folder with
/// the files, as a package build that has no npm and no network gives them
/// (it never runs npm then) — else from `web/node_modules/uplot/dist`,
/// installed from `web/package-lock.json` with `npm ci` when missing. Either
/// way the file must be the version `web/package.json` pins.
fn web_dependencies(web: &Path, out_dir: &Path) {
    println!("cargo:rerun-if-env-changed=NEPTUNUS_UPLOT_DIR");
    println!(
        "cargo:rerun-if-changed={}",
        web.join("package-lock.json").display()
    );
    let given = env::var_os("NEPTUNUS_UPLOT_DIR").filter(|v| !v.is_empty());
    let source = match &given {
        Some(dir) => PathBuf::from(dir),
        None => {
            let dist = web.join("node_modules").join("uplot").join("dist");
            npm_ci_unless(web, &dist.join(UPLOT_FILES[0]));
            dist
        }
    };
    let pinned = uplot_pin(web);
    let staged = out_dir.join("uplot");
    fs::create_dir_all(&staged).expect("create OUT_DIR/uplot");
    for name in UPLOT_FILES {
        let from = source.join(name);
        println!("cargo:rerun-if-changed={}", from.display());
        let text = fs::read_to_string(&from).unwrap_or_else(|e| {
            panic!(
                "cannot read {} ({e}): the browser HMI needs uPlot {pinned}'s {name}{}",
                from.display(),
                if given.is_some() {
                    " — NEPTUNUS_UPLOT_DIR must name a folder holding uPlot.esm.js and uPlot.min.css \
                     (the `dist` folder of the npm package)"
                } else {
                    ""
                }
            )
        });
        if name.ends_with(".js") {
            assert!(
                text.contains(&format!("(v{pinned})")),
                "{} is not uPlot {pinned}, the version web/package.json pins",
                from.display()
            );
        }
        fs::write(staged.join(name), text).expect("stage uPlot in OUT_DIR");
    }
}

/// The uPlot version `web/package.json` pins (`"uplot": "1.6.32"`).
fn uplot_pin(web: &Path) -> String {
    let manifest = web.join("package.json");
    println!("cargo:rerun-if-changed={}", manifest.display());
    let text = fs::read_to_string(&manifest).expect("read web/package.json");
    text.split("\"uplot\"")
        .nth(1)
        .and_then(|rest| rest.split('"').nth(1))
        .map(str::to_owned)
        .expect("web/package.json pins uplot")
}

/// `npm ci` in `web/` when `marker` (an installed file) is missing.
fn npm_ci_unless(web: &Path, marker: &Path) {
    println!("cargo:rerun-if-changed={}", marker.display());
    if marker.is_file() {
        return;
    }
    let npm = env::var("NPM").unwrap_or_else(|_| "npm".into());
    let status = Command::new(&npm)
        .args(["ci", "--no-audit", "--no-fund", "--ignore-scripts"])
        .current_dir(web)
        .status();
    match status {
        Ok(s) if s.success() && marker.is_file() => {}
        Ok(s) => panic!(
            "`npm ci` in {} failed ({s}): the browser HMI needs its plotting library (uPlot) — \
             check the network to the npm registry, run `npm ci` in web/ yourself, or set \
             NEPTUNUS_UPLOT_DIR to a folder with uPlot's dist files",
            web.display()
        ),
        Err(e) => panic!(
            "cannot run `{npm} ci` in {} ({e}): the browser HMI's plotting library (uPlot) is \
             installed with npm — install Node.js and npm (Debian: apt-get install npm), set NPM, \
             or set NEPTUNUS_UPLOT_DIR to a folder with uPlot's dist files",
            web.display()
        ),
    }
}

/// The program's relative relocations packed (DT_RELR): the loader reads
/// them all at start, and as a plain table (24 bytes each on x86_64) they are
/// most of a megabyte of the resident set; packed, a few kilobytes. Only
/// where it is safe to know: a native build (not a cross build, whose C
/// library this script cannot see) against a glibc that reads them (2.36
/// and later say so with the version `GLIBC_ABI_DT_RELR`, which the program
/// then needs). Elsewhere the table stays as it was.
fn packed_relocations() {
    let var = |k: &str| env::var(k).unwrap_or_default();
    if var("CARGO_CFG_TARGET_OS") != "linux"
        || var("CARGO_CFG_TARGET_ENV") != "gnu"
        || var("HOST") != var("TARGET")
    {
        return;
    }
    let libc = Command::new("cc")
        .arg("-print-file-name=libc.so.6")
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_owned());
    let reads_relr = libc
        .and_then(|path| fs::read(path).ok())
        .is_some_and(|bytes| bytes.windows(17).any(|w| w == b"GLIBC_ABI_DT_RELR"));
    if reads_relr {
        println!("cargo:rustc-link-arg-bins=-Wl,-z,pack-relative-relocs");
    }
}

/// `NEPTUNUS_BUILD_UNIX_S` for `wallclock::BUILD_UNIX_S`: a vehicle clock
/// before it is certainly wrong. `SOURCE_DATE_EPOCH` wins (reproducible
/// builds); otherwise the time this script ran, which is never after the build.
fn build_date() {
    println!("cargo:rerun-if-env-changed=SOURCE_DATE_EPOCH");
    let secs = env::var("SOURCE_DATE_EPOCH")
        .ok()
        .and_then(|s| s.trim().parse::<u64>().ok())
        .unwrap_or_else(|| {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_secs())
        });
    println!("cargo:rustc-env=NEPTUNUS_BUILD_UNIX_S={secs}");
}
