//! The C ABI from C: tests/c/golden.c compiled with
//! `cc -std=c11 -Wall -Wextra -Werror` at -O0 (against the static library)
//! and -O2 (against the shared one), run over zwidth-dsp's golden vectors
//! (all 90 cases bit for bit, and every bad input's status), and the
//! header compiled as C++ (`c++ -std=c++17 -Wall -Wextra -Werror`). Needs
//! `cc` and `c++`: without them it says so and passes, unless ZWIDTH_REQUIRE_TOOLS
//! is set (CI sets it and installs them: there it fails, never skips).

use super::support::{have, lib_dir};
use std::path::PathBuf;
use std::process::Command;

fn dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn run(cmd: &mut Command) -> String {
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("{cmd:?}: {e} (CI installs a C and a C++ compiler)"));
    assert!(
        out.status.success(),
        "{cmd:?}: {}\n{}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn the_c_program_equals_the_golden_vectors_at_o0_and_o2() {
    if !have("cc") {
        return;
    }
    let (lib, dir) = (lib_dir(), dir());
    let tmp = std::env::temp_dir().join(format!("zwidth-ffi-c-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    let vectors = dir.join("../zwidth-dsp/golden/vectors.txt");
    let common = |cmd: &mut Command| {
        cmd.args(["-std=c11", "-Wall", "-Wextra", "-Werror", "-pedantic", "-I"])
            .arg(dir.join("include"))
            .arg(dir.join("tests/c/golden.c"));
    };
    // -O0, the static library.
    let o0 = tmp.join("golden_o0");
    let mut cc = Command::new("cc");
    common(&mut cc);
    cc.arg("-O0")
        .arg(lib.join("libzwidth_ffi.a"))
        .args(["-lm", "-lpthread", "-ldl", "-o"])
        .arg(&o0);
    run(&mut cc);
    // -O2, the shared library.
    let o2 = tmp.join("golden_o2");
    let mut cc = Command::new("cc");
    common(&mut cc);
    cc.arg("-O2")
        .arg("-L")
        .arg(&lib)
        .arg(format!("-Wl,-rpath,{}", lib.display()))
        .args(["-lzwidth_ffi", "-lm", "-o"])
        .arg(&o2);
    run(&mut cc);
    for exe in [&o0, &o2] {
        let out = run(Command::new(exe).arg(&vectors));
        assert!(
            out.contains("c: 90 cases equal, 59 refusals checked"),
            "{exe:?}: {out}"
        );
    }
    let _ = std::fs::remove_dir_all(&tmp);
}

#[test]
fn the_header_compiles_as_cpp() {
    if !have("c++") {
        return;
    }
    let dir = dir();
    run(Command::new("c++")
        .args([
            "-std=c++17",
            "-Wall",
            "-Wextra",
            "-Werror",
            "-fsyntax-only",
            "-x",
            "c++",
        ])
        .arg(dir.join("include/zwidth.h")));
}
