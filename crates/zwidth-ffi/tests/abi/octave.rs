//! MATLAB/Octave: mex/zw_estimate.c (MEX API only) built with Octave's
//! `mkoctfile --mex` against the static library, and mex/test_golden.m
//! run in Octave: all 90 golden cases bit for bit and its refusals. Needs
//! Octave and its headers (CI installs `octave liboctave-dev`): without
//! them it says so and passes, unless ZWIDTH_REQUIRE_TOOLS is set (CI sets
//! it: there it fails, never skips).

use super::support::{have, lib_dir};
use std::path::PathBuf;
use std::process::Command;

#[test]
fn the_mex_gateway_in_octave_equals_the_golden_vectors() {
    if !have("mkoctfile") || !have("octave") {
        return;
    }
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let lib = lib_dir();
    let tmp = std::env::temp_dir().join(format!("zwidth-mex-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    let run = |cmd: &mut Command| {
        let out = cmd
            .output()
            .unwrap_or_else(|e| panic!("{cmd:?}: {e} (CI installs octave and liboctave-dev)"));
        let text = format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(out.status.success(), "{cmd:?}: {}\n{text}", out.status);
        text
    };
    run(Command::new("mkoctfile")
        .arg("--mex")
        .arg(format!("-I{}", dir.join("include").display()))
        .arg(dir.join("mex/zw_estimate.c"))
        .arg(lib.join("libzwidth_ffi.a"))
        .args(["-lpthread", "-ldl", "-lm", "-o"])
        .arg(tmp.join("zw_estimate.mex")));
    let script = format!(
        "addpath('{}'); addpath('{}'); test_golden('{}')",
        tmp.display(),
        dir.join("mex").display(),
        dir.join("../zwidth-dsp/golden/vectors.txt").display()
    );
    let out = run(Command::new("octave").args([
        "--no-gui",
        "--no-window-system",
        "-q",
        "--eval",
        &script,
    ]));
    assert!(
        out.contains("octave: 90 cases equal, 7 refusals checked"),
        "{out}"
    );
    let _ = std::fs::remove_dir_all(&tmp);
}
