//! The component metadata the vehicle serves over MAVLink FTP, made in
//! memory once per run from the code itself: the general metadata file
//! (`general.schema.json`: vendor, model, firmware version, and the
//! metadata types with their `mftp://` URIs and CRCs) and the parameter
//! metadata it names ([`crate::vehicle::params::metadata`]).
//!
//! COMPONENT_METADATA (and the older COMPONENT_INFORMATION) carry the
//! general file's URI and CRC. The files are plain JSON: ground stations
//! accept plain or xz-compressed files, and these are small. Every CRC
//! is MAVLink FTP's ([`crate::mavlink::ftp::crc32`]), so a station can
//! check a file with CalcFileCRC32 without reading it.

use std::sync::{Arc, LazyLock};

use super::tree::MemFile;
use crate::mavlink::ftp::crc32;

/// MAVLink's COMP_METADATA_TYPE_PARAMETER.
const COMP_METADATA_TYPE_PARAMETER: u32 = 1;

/// One file made in memory.
#[derive(Debug, Clone)]
pub struct ComponentFile {
    pub bytes: Arc<[u8]>,
    /// MAVLink FTP's CRC-32 of `bytes`.
    pub crc: u32,
}

impl ComponentFile {
    fn new(text: String) -> Self {
        let bytes: Arc<[u8]> = Arc::from(text.into_bytes());
        let crc = crc32(0, &bytes);
        Self { bytes, crc }
    }
}

/// The `mftp://` URI of a file of the tree (MAVLink's form: the path
/// after the scheme, on the component that sends the message).
pub fn uri(file: MemFile) -> String {
    format!("mftp://{}", file.path().trim_start_matches('/'))
}

static PARAMETERS: LazyLock<ComponentFile> =
    LazyLock::new(|| ComponentFile::new(crate::vehicle::params::metadata::parameters_json()));

static GENERAL: LazyLock<ComponentFile> = LazyLock::new(|| {
    let general = serde_json::json!({
        "version": 1,
        "vendorName": "Neptunus",
        "modelName": "OpenROV 2.x",
        "firmwareVersion": env!("CARGO_PKG_VERSION"),
        "metadataTypes": [{
            "type": COMP_METADATA_TYPE_PARAMETER,
            "uri": uri(MemFile::Parameters),
            "fileCrc": PARAMETERS.crc,
        }],
    });
    ComponentFile::new(serde_json::to_string_pretty(&general).unwrap_or_default())
});

/// A file made in memory.
pub fn file(which: MemFile) -> &'static ComponentFile {
    match which {
        MemFile::General => &GENERAL,
        MemFile::Parameters => &PARAMETERS,
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used)]
mod tests {
    use super::*;

    #[test]
    fn the_general_file_names_the_parameters_with_their_crc() {
        let general: serde_json::Value =
            serde_json::from_slice(&file(MemFile::General).bytes).unwrap();
        let params = &general["metadataTypes"][0];
        assert_eq!(params["type"], 1);
        assert_eq!(params["uri"], "mftp://component/parameters.json");
        assert_eq!(
            params["fileCrc"],
            crc32(0, &file(MemFile::Parameters).bytes)
        );
        assert_eq!(uri(MemFile::General), "mftp://component/general.json");
        // The URI resolves to the file it names (QGroundControl keeps one
        // slash of the scheme's; pymavlink-based clients keep none).
        for path in ["/component/general.json", "component/general.json"] {
            assert_eq!(
                super::super::tree::resolve(path.as_bytes()),
                Some(super::super::tree::Node::Mem(MemFile::General))
            );
        }
    }
}
