//! Every integration test of this crate, one binary (issue 33): one link
//! per test build instead of one per file. Each module is the file of one
//! surface; `common` holds what they share.

mod agents;
mod architecture;
mod cli;
mod common;
mod distributed;
mod limits;
mod reliability;
mod service;
mod store;
mod tls;
mod tune;
mod ui;
