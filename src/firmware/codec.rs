//! Sans-IO codec for the OpenROV board's serial protocol.
//!
//! Host → board: `name(arg,...);` ASCII commands, optionally preceded by a
//! Dallas/Maxim CRC-8 byte (`crc8` framing, 2015 firmware) or plain (`plain`
//! framing, December 2014 firmware).
//! Board → host: `\r\n`-terminated lines of `key:value;` pairs, decoded into
//! typed [`Event`]s.
//!
//! This module owns the byte-exact format and the first line of defence
//! against garbage: a value that is not a number or lies outside the
//! physical range of its sensor is counted and dropped here, never passed on.
//! It never does I/O and never reads a clock.

// IMPLEMENTATION NOTE: the bodies are filled in by the codec work item.
