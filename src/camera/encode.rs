//! `[camera] encode` ([`EncodeSetting`]) and what it comes to on this
//! build ([`Encode`]): whether Neptunus may encode video itself. Plain
//! data, read by the configuration and by the choice of paths.

use serde::{Deserialize, Serialize};

/// `[camera] encode`: whether Neptunus may encode video itself.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum EncodeSetting {
    /// `never` on a 32-bit ARM build (the BeagleBone: one Cortex-A8, no
    /// video encoder), `when-needed` elsewhere.
    #[default]
    Auto,
    /// Only what the camera encodes itself reaches the viewers.
    Never,
    /// Encode where the camera gives no H.264 (libx264 for RTP and WebRTC)
    /// or no JPEG (a raw camera's page).
    WhenNeeded,
}

/// What `encode` comes to on this build.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Encode {
    Never,
    WhenNeeded,
}

impl EncodeSetting {
    pub fn resolve(self) -> Encode {
        match self {
            EncodeSetting::Never => Encode::Never,
            EncodeSetting::WhenNeeded => Encode::WhenNeeded,
            EncodeSetting::Auto if cfg!(target_arch = "arm") => Encode::Never,
            EncodeSetting::Auto => Encode::WhenNeeded,
        }
    }

    pub fn as_str(self) -> &'static str {
        match self {
            EncodeSetting::Auto => "auto",
            EncodeSetting::Never => "never",
            EncodeSetting::WhenNeeded => "when-needed",
        }
    }
}

impl Encode {
    pub fn as_str(self) -> &'static str {
        match self {
            Encode::Never => "never",
            Encode::WhenNeeded => "when-needed",
        }
    }
}
