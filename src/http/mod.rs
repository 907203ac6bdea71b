//! The HTTP API (axum), one module per resource, the state they share (`state`), the router
//! (`routes`) and the start-up (`startup`). Errors are RFC 9457
//! `application/problem+json` naming the field (`problem`); who may write
//! and from where is `guard`. Bodies are parsed with the engines' own spec
//! types and validated with the engines' own validation.

pub mod accept;
pub mod agent;
pub mod compare;
pub mod experiments;
pub mod guard;
pub mod limits;
pub mod openapi;
pub mod prior;
pub mod problem;
pub mod queue;
pub mod rigs;
pub mod routes;
pub mod startup;
pub mod state;
pub mod ui;

pub use limits::{BODY_LIMIT, URI_LIMIT};
pub use openapi::openapi_json;
pub use problem::{Problem, ProblemBody};
pub use routes::router;
pub use startup::{put_secret, secret_file, serve, ServeConfig};
pub use state::{refresh_served, AppState, WORKER_LIVE_MS};
