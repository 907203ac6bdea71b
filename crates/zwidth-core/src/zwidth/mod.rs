//! Z-width engines: the scene, the time-domain wall hit, the frequency-domain
//! impedance probe, the analytic model, and the (K, B) searches.

pub mod analytic;
mod bisect;
pub mod bla;
pub mod classify;
mod columns;
pub mod compare;
mod compare_table;
pub mod control;
pub mod controller;
pub mod cost;
pub mod evaluator;
pub mod farm;
pub mod hit;
pub mod observer;
pub mod point;
pub mod poly;
pub mod prior;
pub mod probe;
pub mod psi;
mod psi_search;
pub mod scene;
pub mod search;
pub mod settings;
pub mod stats;
pub mod sweep;
pub mod tradeoff;
pub mod trial;
pub mod trust;

pub use scene::{Scene, SceneSpec};
