//! The page's files, embedded in the binary (debug builds too), with their
//! MIME types, their cache validators and their compression. Nothing is
//! fetched from elsewhere at run time.
//!
//! `web/` holds our own files; the plotting library (uPlot) is the two files
//! the page loads, which `build.rs` stages in `OUT_DIR/uplot/` from
//! `NEPTUNUS_UPLOT_DIR` or from npm's install in `web/node_modules`,
//! embedded under `vendor/`.
//!
//! Caching: every file carries an ETag made from the SHA-256 rust-embed
//! computed at build time, with `Cache-Control: no-cache`. A browser
//! revalidates at each load and gets a body-less 304 while the file is
//! unchanged, and the new file at once after the vehicle's software is
//! upgraded (no stale page against a newer vehicle). The tag is weak
//! (`W/"…"`) because [`compression`] sends the same content in different
//! bytes per encoding, which a strong tag must not cover.
//!
//! Compression is tower-http's layer ([`compression`]), put by
//! `rest::routes` around the asset handlers only: the camera's MJPEG
//! stream, the WebSocket upgrade, log downloads and the API never pass
//! through it.

use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use rust_embed::RustEmbed;
use tower_http::compression::CompressionLayer;

#[derive(RustEmbed)]
#[folder = "web/"]
#[exclude = "node_modules/*"]
#[exclude = "package.json"]
#[exclude = "package-lock.json"]
#[exclude = "README.md"]
struct Web;

#[derive(RustEmbed)]
#[folder = "$OUT_DIR/uplot/"]
#[include = "uPlot.esm.js"]
#[include = "uPlot.min.css"]
struct Uplot;

fn find(path: &str) -> Option<rust_embed::EmbeddedFile> {
    match path.strip_prefix("vendor/") {
        Some(rest) => Uplot::get(rest),
        None => Web::get(path),
    }
}

/// The embedded file at `path` (no leading slash), or 404; a 304 with no
/// body when the request's `If-None-Match` names the file's current tag.
/// The 404 never repeats the path: a body echoing the request is a
/// reflection an attacker can shape (content sniffing, phishing text under
/// the vehicle's address).
pub fn response(path: &str, request: &HeaderMap) -> Response {
    let Some(file) = find(path) else {
        return (
            StatusCode::NOT_FOUND,
            [(header::CONTENT_TYPE, "text/plain; charset=utf-8")],
            "no such page on this vehicle: open / for the operator interface",
        )
            .into_response();
    };
    let tag = etag(&file.metadata.sha256_hash());
    let validators = [
        (header::ETAG, tag.clone()),
        (header::CACHE_CONTROL, HeaderValue::from_static("no-cache")),
    ];
    if matches(request, &tag) {
        return (StatusCode::NOT_MODIFIED, validators).into_response();
    }
    let mime = file.metadata.mimetype().to_owned();
    let mime = if mime.starts_with("text/")
        || mime == "application/javascript"
        || mime == "text/javascript"
    {
        format!("{mime}; charset=utf-8")
    } else {
        mime
    };
    (
        [(header::CONTENT_TYPE, mime)],
        validators,
        file.data.into_owned(),
    )
        .into_response()
}

/// `W/"<first 128 bits of the SHA-256 in hex>"`: unique enough for a
/// handful of files, and short on every request and 304.
pub(crate) fn etag(sha256: &[u8; 32]) -> HeaderValue {
    use std::fmt::Write as _;
    let mut tag = String::with_capacity(38);
    tag.push_str("W/\"");
    for b in &sha256[..16] {
        let _ = write!(tag, "{b:02x}");
    }
    tag.push('"');
    // Only ASCII hex and quotes: always a valid header value.
    HeaderValue::from_str(&tag).unwrap_or(HeaderValue::from_static("W/\"\""))
}

/// Whether `If-None-Match` names `tag` (weak comparison, RFC 9110 13.1.2:
/// `W/` is ignored on both sides) or is `*`. A header that is not text, or
/// a list with nothing matching, is a miss: the file is sent.
pub(crate) fn matches(request: &HeaderMap, tag: &HeaderValue) -> bool {
    let Ok(tag) = tag.to_str() else {
        return false;
    };
    let opaque = |t: &str| t.trim().trim_start_matches("W/").to_owned();
    let ours = opaque(tag);
    request
        .get_all(header::IF_NONE_MATCH)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .any(|t| t.trim() == "*" || opaque(t) == ours)
}

/// The compression of the page's files: brotli or gzip, whichever the
/// request's `Accept-Encoding` prefers (brotli at equal weight), none when
/// it names neither. tower-http's defaults: brotli at quality 4 (nginx's
/// on-the-fly level; 11 would take the BeagleBone hundreds of milliseconds
/// for the page), nothing under 32 bytes, no images. A 304 has no body and
/// is sent as it is.
pub fn compression() -> CompressionLayer {
    CompressionLayer::new().gzip(true).br(true)
}

/// Paths of every embedded file (tests, diagnostics).
pub fn paths() -> Vec<String> {
    Web::iter()
        .map(|p| p.into_owned())
        .chain(Uplot::iter().map(|p| format!("vendor/{p}")))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with(values: &[&[u8]]) -> HeaderMap {
        let mut h = HeaderMap::new();
        for v in values {
            h.append(
                header::IF_NONE_MATCH,
                HeaderValue::from_bytes(v).expect("a header value"),
            );
        }
        h
    }

    #[test]
    fn if_none_match_compares_weakly_and_reads_lists() {
        let tag = etag(&[0xab; 32]);
        let t = tag.to_str().expect("ascii");
        assert_eq!(t, format!("W/\"{}\"", "ab".repeat(16)));
        let strong = t.trim_start_matches("W/");
        assert!(matches(&with(&[t.as_bytes()]), &tag));
        assert!(matches(&with(&[strong.as_bytes()]), &tag));
        assert!(matches(&with(&[format!("\"x\" ,  {t}").as_bytes()]), &tag));
        assert!(matches(&with(&[b"\"x\"", t.as_bytes()]), &tag));
        assert!(matches(&with(&[b"*"]), &tag));
    }

    #[test]
    fn anything_else_in_if_none_match_is_a_miss() {
        let tag = etag(&[0xab; 32]);
        for bad in [
            &b""[..],
            b",,,",
            b"W/",
            b"W/\"\"",
            b"\"ab\"",
            b"\xff\xfe",
            b"**",
        ] {
            assert!(!matches(&with(&[bad]), &tag), "{bad:?}");
        }
        assert!(!matches(&HeaderMap::new(), &tag));
    }

    #[test]
    fn an_unchanged_file_is_a_304_with_its_validators_and_no_body() {
        let first = response("index.html", &HeaderMap::new());
        assert_eq!(first.status(), StatusCode::OK);
        let tag = first.headers()[header::ETAG].clone();
        let again = response("index.html", &with(&[tag.as_bytes()]));
        assert_eq!(again.status(), StatusCode::NOT_MODIFIED);
        assert_eq!(again.headers()[header::ETAG], tag);
        assert_eq!(again.headers()[header::CACHE_CONTROL], "no-cache");
        assert!(again.headers().get(header::CONTENT_TYPE).is_none());
        let missing = response("no/such/file.js", &with(&[b"*"]));
        assert_eq!(missing.status(), StatusCode::NOT_FOUND);
    }
}
