//! What the tests that compile C share: the tools and the built libraries
//! (the workspace's tests/it/common/tools.rs, built once per run here).

use std::path::PathBuf;
use std::sync::OnceLock;

#[path = "../../../../tests/it/common/tools.rs"]
mod tools;

pub use tools::have;

/// target/<profile>, holding libzwidth_ffi.{a,so} (built once).
pub fn lib_dir() -> PathBuf {
    static BUILT: OnceLock<PathBuf> = OnceLock::new();
    BUILT.get_or_init(tools::ffi_lib_dir).clone()
}
