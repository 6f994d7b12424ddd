//! What Cockpit asks of a BlueOS vehicle besides mavlink2rest ([`super::m2r`]),
//! answered by the vehicle itself on the HMI's port, so that Cockpit given
//! only the vehicle's address finds everything: the settings bag
//! ([`bag`]: its vehicle id and each user's settings), the beacon's
//! addresses with their kinds of link and the vehicle's name, and the
//! helper's list of web services ([`beacon`]). The camera manager's
//! `/streams` (port 6020) is the camera's (`camera::webrtc`).
//!
//! Who may use them is decided in front ([`super::guard`]): the Host rule
//! everywhere, the Origin rule on every write; reads are open to every
//! client those admit (what the vehicle shows anyone watching), writes to
//! the bag follow [`bag::store`]'s rules. The answers carry CORS headers
//! for the origins the Origin rule admits (`hmi::cors`).

pub mod bag;
pub mod beacon;

use std::sync::Arc;

use axum::Router;
use axum::extract::{Request, State};
use axum::response::{IntoResponse, Json, Response};
use axum::routing::{get, post};

use super::Shared;
use super::server::ConnInfo;

fn is_blueos_path(path: &str) -> bool {
    path.starts_with(bag::GET_PREFIX)
        || path.starts_with(bag::SET_PREFIX)
        || path.starts_with("/beacon/v1.0/")
        || path.starts_with("/helper/v1.0/")
}

pub(crate) fn routes(shared: Arc<Shared>) -> Router {
    let r = Router::new()
        .route(&format!("{}{{*path}}", bag::GET_PREFIX), get(bag::get))
        .route(&format!("{}{{*path}}", bag::SET_PREFIX), post(bag::set))
        .route("/beacon/v1.0/services", get(services))
        .route("/beacon/v1.0/vehicle_name", get(vehicle_name))
        .route("/helper/v1.0/web_services", get(web_services));
    super::cors::layer(r, Arc::clone(&shared), is_blueos_path, None).with_state(shared)
}

/// The vehicle's name: its host name (the name the HMI answers to).
fn name() -> String {
    super::auth::machine_hostname()
        .filter(|h| !h.is_empty())
        .unwrap_or_else(|| "neptunus".to_owned())
}

fn local_of(req: &Request) -> Option<std::net::SocketAddr> {
    req.extensions().get::<ConnInfo>().and_then(|c| c.local)
}

/// `GET /beacon/v1.0/services`: the vehicle's addresses, each with its
/// kind of link, and the one this request reached.
async fn services(req: Request) -> Json<Vec<beacon::Service>> {
    let reached = local_of(&req).map(|a| a.ip());
    let host = name();
    Json(
        tokio::task::spawn_blocking(move || beacon::services(reached, &host))
            .await
            .unwrap_or_default(),
    )
}

/// `GET /beacon/v1.0/vehicle_name`: plain text (Cockpit shows it as "Manage
/// users on: NAME").
async fn vehicle_name() -> String {
    name()
}

/// `GET /helper/v1.0/web_services`: the web services the vehicle runs —
/// the HMI's page, on the port this request came to. Cockpit looks in each
/// for widgets of its own (`extras.cockpit`); the page offers none (it
/// cannot be framed).
async fn web_services(State(_shared): State<Arc<Shared>>, req: Request) -> Response {
    let port = local_of(&req).map(|a| a.port());
    Json(serde_json::json!([{
        "name": "Neptunus",
        "port": port,
        "metadata": {
            "name": "Neptunus",
            "description": "The vehicle's own page: video, telemetry, driving, logs",
            "icon": "mdi-submarine",
            "company": "Neptunus",
            "version": env!("CARGO_PKG_VERSION"),
            "webpage": "",
            "route": "/",
            "new_page": true,
            "works_in_relative_paths": false,
            "sanitized_name": "neptunus",
        },
    }]))
    .into_response()
}
