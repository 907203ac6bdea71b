//! What the tests that compile C share: the built libraries and the tools.

use std::path::PathBuf;
use std::process::Command;
use std::sync::OnceLock;

/// target/<profile>, holding libzwidth_ffi.{a,so}. `cargo test` builds the
/// crate only as an rlib for its tests, so the C libraries are built here
/// with the test's own profile (the same artefacts: nothing recompiles).
pub fn lib_dir() -> PathBuf {
    static BUILT: OnceLock<PathBuf> = OnceLock::new();
    BUILT
        .get_or_init(|| {
            let exe = std::env::current_exe().unwrap();
            let dir = exe.parent().unwrap().parent().unwrap().to_path_buf();
            let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
            let mut cmd = Command::new(cargo);
            cmd.args(["build", "-p", "zwidth-ffi", "--lib"]);
            if dir.file_name().is_some_and(|n| n == "release") {
                cmd.arg("--release");
            }
            // The profile's directory sits in the target directory.
            cmd.env("CARGO_TARGET_DIR", dir.parent().unwrap());
            let out = cmd.output().expect("cargo runs");
            assert!(
                out.status.success(),
                "{cmd:?}: {}",
                String::from_utf8_lossy(&out.stderr)
            );
            dir
        })
        .clone()
}

/// Whether `tool` runs here. Without it the test says so and passes,
/// unless `ZWIDTH_REQUIRE_TOOLS` is set (CI sets it: there it fails).
pub fn have(tool: &str) -> bool {
    let ok = Command::new(tool)
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        assert!(
            std::env::var_os("ZWIDTH_REQUIRE_TOOLS").is_none(),
            "{tool} is needed (ZWIDTH_REQUIRE_TOOLS is set)"
        );
        eprintln!("skipped: {tool} is not installed (CI installs it)");
    }
    ok
}
