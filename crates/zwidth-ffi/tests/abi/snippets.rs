//! docs/rigs.md's snippets (where the call goes in CHAI3D, a Force
//! Dimension loop, ros2_control and a Simulink C Function block) are the
//! files in examples/rig_snippets, shown verbatim, and each compiles
//! against include/zwidth.h with warnings as errors (the SDKs' few
//! declarations they use stand in from examples/rig_snippets/stubs).

use super::support::have;
use std::path::PathBuf;
use std::process::Command;

const SNIPPETS: [&str; 4] = [
    "chai3d_device.cpp",
    "force_dimension_loop.c",
    "ros2_control_read.cpp",
    "simulink_c_function.c",
];

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

#[test]
fn the_docs_show_each_snippet_verbatim() {
    let root = root();
    let docs = std::fs::read_to_string(root.join("docs/rigs.md")).unwrap();
    for name in SNIPPETS {
        let text = std::fs::read_to_string(root.join("examples/rig_snippets").join(name)).unwrap();
        assert!(
            docs.contains(text.trim()),
            "docs/rigs.md does not show examples/rig_snippets/{name} as it is"
        );
    }
}

#[test]
fn each_snippet_compiles_against_the_header() {
    if !have("cc") || !have("c++") {
        return;
    }
    let root = root();
    let dir = root.join("examples/rig_snippets");
    for name in SNIPPETS {
        let (compiler, std) = match name.ends_with(".cpp") {
            true => ("c++", "-std=c++17"),
            false => ("cc", "-std=c11"),
        };
        let mut cmd = Command::new(compiler);
        cmd.args([
            std,
            "-Wall",
            "-Wextra",
            "-Werror",
            "-pedantic",
            "-fsyntax-only",
            "-I",
        ])
        .arg(root.join("crates/zwidth-ffi/include"))
        .arg("-I")
        .arg(dir.join("stubs"))
        .arg(dir.join(name));
        let out = cmd.output().expect("the compiler runs");
        assert!(
            out.status.success(),
            "{cmd:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
}
