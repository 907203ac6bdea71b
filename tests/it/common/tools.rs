//! Tools outside Rust a test needs (a C compiler, Octave) and the C
//! libraries: shared by this crate's tests and zwidth-ffi's (there
//! included by `#[path]`).

use std::path::PathBuf;
use std::process::Command;

/// Whether `tool` runs here. Without it a test says so and passes, unless
/// `ZWIDTH_REQUIRE_TOOLS` is set (CI sets it and installs the tools: there
/// it fails, never skips).
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

/// target/<profile>, holding libzwidth_ffi.{a,so} built with the running
/// test's profile: `cargo test` builds zwidth-ffi only as an rlib for
/// tests, so the C libraries are built here (the same artefacts: nothing
/// else recompiles).
pub fn ffi_lib_dir() -> PathBuf {
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
}
