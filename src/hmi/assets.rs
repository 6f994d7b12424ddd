//! The page's files, embedded in the binary (debug builds too), with their
//! MIME types. Nothing is fetched from elsewhere at run time.
//!
//! `web/` holds our own files; the plotting library comes from
//! `web/node_modules/uplot/dist/` (installed by `build.rs` with `npm ci`),
//! of which only the two files the page loads are embedded, under `vendor/`.

use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use rust_embed::RustEmbed;

#[derive(RustEmbed)]
#[folder = "web/"]
#[exclude = "node_modules/*"]
#[exclude = "package.json"]
#[exclude = "package-lock.json"]
#[exclude = "README.md"]
struct Web;

#[derive(RustEmbed)]
#[folder = "web/node_modules/uplot/dist/"]
#[include = "uPlot.esm.js"]
#[include = "uPlot.min.css"]
struct Uplot;

fn find(path: &str) -> Option<rust_embed::EmbeddedFile> {
    match path.strip_prefix("vendor/") {
        Some(rest) => Uplot::get(rest),
        None => Web::get(path),
    }
}

/// The embedded file at `path` (no leading slash), or 404. The 404 never
/// repeats the path: a body echoing the request is a reflection an attacker
/// can shape (content sniffing, phishing text under the vehicle's address).
pub fn response(path: &str) -> Response {
    let Some(file) = find(path) else {
        return (
            StatusCode::NOT_FOUND,
            [(header::CONTENT_TYPE, "text/plain; charset=utf-8")],
            "no such page on this vehicle: open / for the operator interface",
        )
            .into_response();
    };
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
        [
            (header::CONTENT_TYPE, mime),
            (header::CACHE_CONTROL, "no-cache".to_owned()),
        ],
        file.data.into_owned(),
    )
        .into_response()
}

/// Paths of every embedded file (tests, diagnostics).
pub fn paths() -> Vec<String> {
    Web::iter()
        .map(|p| p.into_owned())
        .chain(Uplot::iter().map(|p| format!("vendor/{p}")))
        .collect()
}
