//! `GET /api/recordings` (the recordings on the vehicle, each file with its
//! recording, kind, size and time) and `GET /api/recordings/{name}` (one
//! file, streamed: a recording is far larger than a log).
//!
//! Like the logs, they are the vehicle's records: only for a client that
//! may pilot ([`super::guard::is_record`]). A download serves only a name
//! the listing itself produced (`camera::record::listed_path`): nothing
//! from the request is ever joined onto a path.

use std::sync::Arc;

use axum::body::Body;
use axum::extract::{Path, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Json, Response};
use futures_util::StreamExt as _;
use tokio::io::AsyncReadExt as _;

use super::Shared;
use crate::camera::record::{self, FileKind};

/// Bytes read from the file per chunk of the response.
const CHUNK_BYTES: usize = 64 * 1024;

pub(crate) async fn list(State(shared): State<Arc<Shared>>) -> Json<serde_json::Value> {
    let dir = record::recordings_dir(&shared.data_dir);
    let files = tokio::task::spawn_blocking(move || record::list(&dir))
        .await
        .unwrap_or_default();
    let files: Vec<_> = files
        .into_iter()
        .map(|f| {
            let url = format!("/api/recordings/{}", f.name);
            let mut v = serde_json::to_value(&f).unwrap_or_default();
            if let Some(o) = v.as_object_mut() {
                o.insert("url".into(), url.into());
            }
            v
        })
        .collect();
    Json(serde_json::json!({ "recordings": files }))
}

fn content_type(kind: FileKind) -> &'static str {
    match kind {
        FileKind::Video => "video/mp2t",
        FileKind::Subtitles => "text/vtt; charset=utf-8",
        FileKind::Telemetry => "text/csv; charset=utf-8",
    }
}

pub(crate) async fn file(State(shared): State<Arc<Shared>>, Path(name): Path<String>) -> Response {
    let dir = record::recordings_dir(&shared.data_dir);
    let listed = {
        let name = name.clone();
        tokio::task::spawn_blocking(move || record::listed_path(&dir, &name))
            .await
            .ok()
            .flatten()
    };
    let (Some(path), Some((_, kind))) = (listed, record::files::parse_name(&name)) else {
        return (
            StatusCode::NOT_FOUND,
            "no such recording file: see /api/recordings",
        )
            .into_response();
    };
    let f = match tokio::fs::File::open(&path).await {
        Ok(f) => f,
        Err(e) => {
            return (
                StatusCode::NOT_FOUND,
                format!("cannot read the recording: {e}"),
            )
                .into_response();
        }
    };
    // The size now: a recording still being written grows, and the
    // download gives what there was when it began.
    let len = f.metadata().await.map_or(0, |m| m.len());
    let chunks = futures_util::stream::unfold((f, len), |(mut f, left)| async move {
        if left == 0 {
            return None;
        }
        let mut buf = vec![0u8; CHUNK_BYTES.min(usize::try_from(left).unwrap_or(CHUNK_BYTES))];
        match f.read(&mut buf).await {
            Ok(0) => None,
            Ok(n) => {
                buf.truncate(n);
                Some((Ok::<_, std::io::Error>(buf), (f, left - n as u64)))
            }
            Err(e) => Some((Err(e), (f, 0))),
        }
    });
    (
        [
            (header::CONTENT_TYPE, content_type(kind).to_owned()),
            (header::CONTENT_LENGTH, len.to_string()),
            (
                header::CONTENT_DISPOSITION,
                format!("attachment; filename=\"{name}\""),
            ),
        ],
        Body::from_stream(chunks.map(|c| c.map(bytes::Bytes::from))),
    )
        .into_response()
}
