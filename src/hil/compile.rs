//! Building the genuine firmware: the OpenROV sketch compiled with avr-gcc
//! and Debian's Arduino AVR core for the controller board's ATmega2560, the
//! ELF cached by a hash of everything that went into it.
//!
//! Owns finding the sketch (a checkout of `openrov-software-arduino`, its
//! `OpenROV/` folder, or a ready ELF), the compiler flags the Arduino IDE
//! would use for an Arduino Mega 2560, the cache, and errors that name the
//! Debian packages to install. It never changes a firmware source file.

use std::path::{Path, PathBuf};
use std::process::Command;

use sha2::{Digest, Sha256};

use crate::firmware::codec::Framing;

/// Where Debian's `arduino-core-avr` puts the core (overridden by `ARDUINO_AVR_CORE`).
const DEBIAN_CORE: &str = "/usr/share/arduino/hardware/arduino/avr";
/// Debian packages that build the firmware.
pub const BUILD_PACKAGES: &str = "gcc-avr avr-libc arduino-core-avr";
/// Debian packages that build the simulator this feature links (simavr's
/// C sources, bindgen's libclang, libelf and zstd for ELF loading).
pub const SIMAVR_PACKAGES: &str = "libclang-dev libelf-dev libzstd-dev pkg-config";

const MCU_FLAGS: &[&str] = &[
    "-mmcu=atmega2560",
    "-DF_CPU=16000000L",
    "-DARDUINO=10807",
    "-DARDUINO_AVR_MEGA2560",
    "-DARDUINO_ARCH_AVR",
    "-Os",
    "-g",
    "-flto",
    "-ffunction-sections",
    "-fdata-sections",
];
const C_FLAGS: &[&str] = &["-std=gnu11", "-fno-fat-lto-objects"];
/// What the Arduino IDE passes for C++, plus `DECIMAL_DIG`: gcc-avr 5.4's
/// `<float.h>` lacks it and core 1.8's `Print.h` needs it.
const CXX_FLAGS: &[&str] = &[
    "-std=gnu++11",
    "-fpermissive",
    "-fno-exceptions",
    "-fno-threadsafe-statics",
    "-Wno-error=narrowing",
    "-DDECIMAL_DIG=__DECIMAL_DIG__",
];
const LINK_FLAGS: &[&str] = &[
    "-mmcu=atmega2560",
    "-Os",
    "-g",
    "-flto",
    "-fuse-linker-plugin",
    "-Wl,--gc-sections",
];
/// Bumped whenever the flags or the recipe change, so old cached ELFs are not reused.
const RECIPE: &str = "openrov-mega2560-v1";

/// Why the firmware could not be built or found.
#[derive(Debug, thiserror::Error)]
pub enum BuildError {
    #[error(
        "{path} is neither an OpenROV firmware checkout (with OpenROV/OpenROV.ino), its OpenROV folder, nor an .elf file — clone it with `git clone https://github.com/OpenROV/openrov-software-arduino && git -C openrov-software-arduino checkout 30.0.2`"
    )]
    NotFirmware { path: PathBuf },
    #[error("{tool} is not installed — install the Debian packages {packages}")]
    Toolchain { tool: String, packages: String },
    #[error(
        "the Arduino AVR core is not at {path} — install the Debian package arduino-core-avr, or set ARDUINO_AVR_CORE to a core's folder"
    )]
    Core { path: PathBuf },
    #[error("compiling {file} failed:\n{stderr}")]
    Compile { file: PathBuf, stderr: String },
    #[error("{action} {path}: {source}")]
    Io {
        action: &'static str,
        path: PathBuf,
        source: std::io::Error,
    },
}

fn io_err(action: &'static str, path: &Path) -> impl FnOnce(std::io::Error) -> BuildError {
    let path = path.to_path_buf();
    move |source| BuildError::Io {
        action,
        path,
        source,
    }
}

/// A firmware ready to run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Firmware {
    pub elf: PathBuf,
    /// How it frames commands: a firmware that prints `crc:` checks a CRC-8
    /// byte (March 2015 on); the older one takes plain text.
    pub framing: Framing,
}

/// The firmware at `path` (a checkout, its `OpenROV/` folder or an ELF),
/// built into `cache` if it is source and not built yet.
pub fn prepare(path: &Path, cache: &Path) -> Result<Firmware, BuildError> {
    let elf = if path.extension().is_some_and(|e| e == "elf") && path.is_file() {
        path.to_path_buf()
    } else {
        build(&sketch_dir(path)?, cache)?
    };
    let bytes = std::fs::read(&elf).map_err(io_err("cannot read", &elf))?;
    Ok(Firmware {
        framing: framing_of(&bytes),
        elf,
    })
}

/// The sketch folder (the one with `OpenROV.ino`) at or under `path`.
pub fn sketch_dir(path: &Path) -> Result<PathBuf, BuildError> {
    for dir in [path.join("OpenROV"), path.to_path_buf()] {
        if dir.join("OpenROV.ino").is_file() {
            return Ok(dir);
        }
    }
    Err(BuildError::NotFirmware {
        path: path.to_path_buf(),
    })
}

/// The framing a firmware image expects: its CRC report's text is in flash.
fn framing_of(elf: &[u8]) -> Framing {
    if elf.windows(4).any(|w| w == b"crc:") {
        Framing::Crc8
    } else {
        Framing::Plain
    }
}

fn core_dir() -> PathBuf {
    std::env::var_os("ARDUINO_AVR_CORE")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(DEBIAN_CORE))
}

/// `tool --version`'s first line, or which packages to install.
fn tool_version(tool: &str) -> Result<String, BuildError> {
    let missing = || BuildError::Toolchain {
        tool: tool.into(),
        packages: BUILD_PACKAGES.into(),
    };
    let out = Command::new(tool)
        .arg("--version")
        .output()
        .map_err(|_| missing())?;
    if !out.status.success() {
        return Err(missing());
    }
    Ok(String::from_utf8_lossy(&out.stdout)
        .lines()
        .next()
        .unwrap_or_default()
        .to_owned())
}

/// Files of `dir` with one of `exts`, sorted by name.
fn files(dir: &Path, exts: &[&str]) -> Result<Vec<PathBuf>, BuildError> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(io_err("cannot list", dir))?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| {
            p.is_file()
                && p.extension()
                    .and_then(|e| e.to_str())
                    .is_some_and(|e| exts.contains(&e))
        })
        .collect();
    out.sort();
    Ok(out)
}

/// Compiles the sketch in `sketch` (cached in `cache`); returns the ELF.
pub fn build(sketch: &Path, cache: &Path) -> Result<PathBuf, BuildError> {
    let core = core_dir();
    let cores = core.join("cores/arduino");
    if !cores.join("Arduino.h").is_file() {
        return Err(BuildError::Core { path: core });
    }
    let gcc = tool_version("avr-gcc")?;
    tool_version("avr-g++")?;
    let sources = files(sketch, &["cpp", "c", "h", "ino"])?;

    let mut hash = Sha256::new();
    hash.update(RECIPE);
    hash.update(&gcc);
    hash.update(std::fs::read(core.join("platform.txt")).unwrap_or_default());
    for f in &sources {
        hash.update(
            f.file_name()
                .map(|n| n.as_encoded_bytes())
                .unwrap_or_default(),
        );
        hash.update(std::fs::read(f).map_err(io_err("cannot read", f))?);
    }
    let key: String = hash
        .finalize()
        .iter()
        .take(12)
        .map(|b| format!("{b:02x}"))
        .collect();
    let dir = cache.join(&key);
    let elf = dir.join("openrov.elf");
    if elf.is_file() {
        return Ok(elf);
    }
    std::fs::create_dir_all(cache).map_err(io_err("cannot create", cache))?;
    let work = cache.join(format!("{key}.building-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&work);
    std::fs::create_dir_all(&work).map_err(io_err("cannot create", &work))?;
    let result = compile_into(sketch, &core, &work);
    if let Err(e) = result {
        let _ = std::fs::remove_dir_all(&work);
        return Err(e);
    }
    // Another process may have built the same key meanwhile: either copy will do.
    if std::fs::rename(&work, &dir).is_err() {
        let _ = std::fs::remove_dir_all(&work);
    }
    if elf.is_file() {
        Ok(elf)
    } else {
        Err(BuildError::Io {
            action: "cannot store the built firmware in",
            path: dir,
            source: std::io::Error::other("the cache entry has no openrov.elf"),
        })
    }
}

fn run(cmd: &mut Command, file: &Path) -> Result<(), BuildError> {
    let out = cmd.output().map_err(|_| BuildError::Toolchain {
        tool: cmd.get_program().to_string_lossy().into_owned(),
        packages: BUILD_PACKAGES.into(),
    })?;
    if out.status.success() {
        Ok(())
    } else {
        let stderr = String::from_utf8_lossy(&out.stderr);
        let stderr: String = stderr.lines().take(30).collect::<Vec<_>>().join("\n");
        Err(BuildError::Compile {
            file: file.to_path_buf(),
            stderr,
        })
    }
}

fn compile_into(sketch: &Path, core: &Path, work: &Path) -> Result<(), BuildError> {
    let cores = core.join("cores/arduino");
    let libraries = core.join("libraries");
    let includes: Vec<String> = [
        cores.clone(),
        core.join("variants/mega"),
        libraries.join("Wire/src"),
        libraries.join("SPI/src"),
        libraries.join("EEPROM/src"),
        sketch.to_path_buf(),
    ]
    .iter()
    .map(|p| format!("-I{}", p.display()))
    .collect();

    // The sketch's `.ino` is C++ once it includes Arduino.h (the IDE adds it).
    let ino = work.join("OpenROV.ino.cpp");
    let mut text = b"#include <Arduino.h>\n".to_vec();
    let ino_src = sketch.join("OpenROV.ino");
    text.extend(std::fs::read(&ino_src).map_err(io_err("cannot read", &ino_src))?);
    std::fs::write(&ino, text).map_err(io_err("cannot write", &ino))?;

    let mut c_files = files(&cores, &["c"])?;
    c_files.push(libraries.join("Wire/src/utility/twi.c"));
    let asm_files = files(&cores, &["S"])?;
    let mut cpp_files = files(&cores, &["cpp"])?;
    cpp_files.push(libraries.join("Wire/src/Wire.cpp"));
    cpp_files.push(libraries.join("SPI/src/SPI.cpp"));
    cpp_files.extend(files(sketch, &["cpp"])?);
    cpp_files.push(ino);

    let mut objects = Vec::new();
    let mut object = |src: &Path, n: usize| {
        let name = src.file_name().map(|s| s.to_string_lossy().into_owned());
        let o = work.join(format!("{n:03}-{}.o", name.unwrap_or_default()));
        objects.push(o.clone());
        o
    };
    let mut n = 0;
    for src in &c_files {
        n += 1;
        let o = object(src, n);
        run(
            Command::new("avr-gcc")
                .arg("-c")
                .args(MCU_FLAGS)
                .args(C_FLAGS)
                .args(&includes)
                .arg(src)
                .arg("-o")
                .arg(&o),
            src,
        )?;
    }
    for src in &asm_files {
        n += 1;
        let o = object(src, n);
        run(
            Command::new("avr-gcc")
                .args(["-c", "-x", "assembler-with-cpp"])
                .args(MCU_FLAGS)
                .args(&includes)
                .arg(src)
                .arg("-o")
                .arg(&o),
            src,
        )?;
    }
    for src in &cpp_files {
        n += 1;
        let o = object(src, n);
        run(
            Command::new("avr-g++")
                .arg("-c")
                .args(MCU_FLAGS)
                .args(CXX_FLAGS)
                .args(&includes)
                .arg(src)
                .arg("-o")
                .arg(&o),
            src,
        )?;
    }
    let elf = work.join("openrov.elf");
    run(
        Command::new("avr-gcc")
            .args(LINK_FLAGS)
            .arg("-o")
            .arg(&elf)
            .args(&objects)
            .arg("-lm"),
        &elf,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn framing_from_the_crc_report_in_flash() {
        assert_eq!(framing_of(b"\0\0rawcmd:\0crc:\0pass;"), Framing::Crc8);
        assert_eq!(framing_of(b"\0cmd:\0boot:1;"), Framing::Plain);
    }

    #[test]
    fn not_a_firmware_folder_says_how_to_get_one() {
        let dir = std::env::temp_dir();
        let e = sketch_dir(&dir).expect_err("no sketch in the temp dir");
        assert!(e.to_string().contains("checkout 30.0.2"), "{e}");
    }
}
