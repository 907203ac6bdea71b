//! The simulated device: the plant between force updates.

pub mod plant;

pub use plant::{Plant, PlantState};
