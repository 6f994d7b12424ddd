//! A path in the settings bag, as it arrives in a request's URI
//! (`/bag/v1.0/get/cockpit/settings-v2/pilot/…`): segments split on `/`
//! *before* they are percent-decoded, so an encoded slash (`%2F`) can never
//! make two segments of one.
//!
//! Owns [`BagPath`] and its checks. Nothing here touches a file: the bag
//! keeps every value in one document, so no path is ever joined onto the
//! file system; the checks exist so that a request that tries (`..`, an
//! absolute path, a NUL, an encoded slash) is told so plainly and changes
//! nothing.

use std::fmt;

/// Longest path, in bytes as received (still percent-encoded).
pub const MAX_PATH_BYTES: usize = 512;
/// Most segments in one path.
pub const MAX_SEGMENTS: usize = 16;
/// Longest segment, in bytes once decoded.
pub const MAX_SEGMENT_BYTES: usize = 128;

/// A checked bag path: 1 to [`MAX_SEGMENTS`] segments, each a non-empty
/// UTF-8 text without `/`, `\`, control characters (NUL included), and
/// neither `.` nor `..`.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct BagPath(Vec<String>);

/// Why a path was refused; each says what is wrong and how a path looks.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PathError {
    #[error("no path: name a value, e.g. cockpit/cockpit-vehicle-id")]
    Empty,
    #[error(
        "an absolute path (it starts with /): bag paths are relative, e.g. cockpit/cockpit-vehicle-id"
    )]
    Absolute,
    #[error("an empty segment (two / in a row, or a / at the end)")]
    EmptySegment,
    #[error("a segment \".\" or \"..\": bag paths name values, not folders")]
    Dot,
    #[error("an encoded slash or backslash (%2F, %5C) inside a segment")]
    EncodedSlash,
    #[error("a control character (NUL included) in a segment")]
    Control,
    #[error("a segment that is not valid percent-encoded UTF-8")]
    Encoding,
    #[error("a path longer than {MAX_PATH_BYTES} bytes")]
    TooLong,
    #[error("more than {MAX_SEGMENTS} segments")]
    TooDeep,
    #[error("a segment longer than {MAX_SEGMENT_BYTES} bytes")]
    LongSegment,
}

impl BagPath {
    /// A path from the part of a URI's path after the route's prefix, still
    /// percent-encoded as the client sent it.
    pub fn parse(raw: &str) -> Result<BagPath, PathError> {
        if raw.len() > MAX_PATH_BYTES {
            return Err(PathError::TooLong);
        }
        if raw.is_empty() {
            return Err(PathError::Empty);
        }
        if raw.starts_with('/') {
            return Err(PathError::Absolute);
        }
        let mut segments = Vec::new();
        for piece in raw.split('/') {
            if segments.len() == MAX_SEGMENTS {
                return Err(PathError::TooDeep);
            }
            segments.push(segment(piece)?);
        }
        Ok(BagPath(segments))
    }

    /// A path from segments already decoded (the file's records).
    pub fn from_segments(segments: Vec<String>) -> Result<BagPath, PathError> {
        if segments.is_empty() {
            return Err(PathError::Empty);
        }
        if segments.len() > MAX_SEGMENTS {
            return Err(PathError::TooDeep);
        }
        for s in &segments {
            check_decoded(s)?;
        }
        Ok(BagPath(segments))
    }

    pub fn segments(&self) -> &[String] {
        &self.0
    }

    /// Whether `self` is `other` or lies under it.
    pub fn within(&self, other: &BagPath) -> bool {
        self.0.starts_with(&other.0)
    }

    /// Bytes of the decoded segments (what the path costs the bag).
    pub fn byte_len(&self) -> usize {
        self.0.iter().map(|s| s.len() + 1).sum()
    }
}

impl fmt::Display for BagPath {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0.join("/"))
    }
}

fn segment(piece: &str) -> Result<String, PathError> {
    if piece.is_empty() {
        return Err(PathError::EmptySegment);
    }
    let decoded = percent_encoding::percent_decode_str(piece)
        .decode_utf8()
        .map_err(|_| PathError::Encoding)?;
    // A lone `%` or `%zz` is left as it is by the decoder: refuse it, so
    // that what is stored is what the client meant.
    if has_bad_escape(piece) {
        return Err(PathError::Encoding);
    }
    if decoded.contains(['/', '\\']) {
        return Err(PathError::EncodedSlash);
    }
    check_decoded(&decoded)?;
    Ok(decoded.into_owned())
}

fn check_decoded(s: &str) -> Result<(), PathError> {
    if s.is_empty() {
        return Err(PathError::EmptySegment);
    }
    if s.len() > MAX_SEGMENT_BYTES {
        return Err(PathError::LongSegment);
    }
    if s == "." || s == ".." {
        return Err(PathError::Dot);
    }
    if s.contains(['/', '\\']) {
        return Err(PathError::EncodedSlash);
    }
    if s.chars().any(char::is_control) {
        return Err(PathError::Control);
    }
    Ok(())
}

/// A `%` not followed by two hex digits.
fn has_bad_escape(piece: &str) -> bool {
    let b = piece.as_bytes();
    b.iter().enumerate().any(|(i, &c)| {
        c == b'%'
            && !(b.get(i + 1).is_some_and(u8::is_ascii_hexdigit)
                && b.get(i + 2).is_some_and(u8::is_ascii_hexdigit))
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn cockpits_paths_parse() {
        let p = BagPath::parse("cockpit/settings-v2/John%20Doe/cockpit-views").unwrap();
        assert_eq!(
            p.segments(),
            ["cockpit", "settings-v2", "John Doe", "cockpit-views"]
        );
        assert_eq!(p.to_string(), "cockpit/settings-v2/John Doe/cockpit-views");
        let parent = BagPath::parse("cockpit/settings-v2").unwrap();
        assert!(p.within(&parent) && parent.within(&parent) && !parent.within(&p));
        assert_eq!(BagPath::parse("caf%C3%A9").unwrap().segments(), ["café"]);
    }

    #[test]
    fn tricks_are_refused_with_the_reason() {
        for (raw, want) in [
            ("", PathError::Empty),
            ("/etc/passwd", PathError::Absolute),
            ("a//b", PathError::EmptySegment),
            ("a/", PathError::EmptySegment),
            ("../x", PathError::Dot),
            ("a/./b", PathError::Dot),
            ("a/%2e%2e/b", PathError::Dot),
            ("a%2Fb", PathError::EncodedSlash),
            ("a%2fb", PathError::EncodedSlash),
            ("a%5Cb", PathError::EncodedSlash),
            ("a\\b", PathError::EncodedSlash),
            ("a%00b", PathError::Control),
            ("a%0Ab", PathError::Control),
            ("a%ZZ", PathError::Encoding),
            ("a%", PathError::Encoding),
            ("%FF", PathError::Encoding),
        ] {
            assert_eq!(BagPath::parse(raw), Err(want.clone()), "{raw:?}");
            assert!(!want.to_string().is_empty());
        }
        assert_eq!(
            BagPath::parse(&format!("{}z", "a/".repeat(MAX_SEGMENTS))),
            Err(PathError::TooDeep)
        );
        assert_eq!(
            BagPath::parse(&"x".repeat(MAX_SEGMENT_BYTES + 1)),
            Err(PathError::LongSegment)
        );
        assert_eq!(
            BagPath::parse(&"x".repeat(MAX_PATH_BYTES + 1)),
            Err(PathError::TooLong)
        );
        assert_eq!(
            BagPath::from_segments(vec!["..".into()]),
            Err(PathError::Dot)
        );
    }
}
