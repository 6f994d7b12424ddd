//! Who may use the browser HMI: the pilot password (argon2 PHC string in
//! `DATA_DIR/hmi-password`), which client addresses may pilot without it
//! (`[hmi] open_control`), the Host and Origin checks against foreign web
//! pages and DNS rebinding, the login throttle and the login cookies.
//!
//! Everything here decides from plain values and an explicit `now`, so the
//! rules are unit-tested without sockets or clocks. This module must never
//! log a password or a token, and never do more than a handful of password
//! checks per second for one client address, whatever it is sent.
//!
//! One file per concern: `password` (the hash and its file), `gate` (open
//! control, Host and Origin), `throttle` (failed logins per address), `login`
//! (cookies) and `bursts` (rate-limited logging); everything public is
//! re-exported here.

mod bursts;
mod gate;
mod login;
mod password;
mod throttle;

pub use bursts::{BURST_QUIET, Bursts, loggable};
pub use gate::{Gate, OpenControl, machine_hostname, parse_origin, with_port};
pub use login::{COOKIE, LINK_FIRST_USE, LOGIN_LIFETIME, Tokens, cookie_value};
pub use password::{
    MAX_PASSWORD_BYTES, MIN_PASSWORD_CHARS, PASSWORD_FILE, PasswordError, PasswordStore,
    PilotPassword,
};
pub use throttle::{Admit, Throttle, ThrottleNote, throttle_key};
