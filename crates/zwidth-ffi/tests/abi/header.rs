//! include/zwidth.h is what cbindgen 0.29.4 (pinned in Cargo.toml) writes
//! from src/lib.rs with cbindgen.toml: a change of the ABI that forgot the
//! header fails here. `ZWIDTH_BLESS=1` rewrites it.

#[test]
fn the_committed_header_is_cbindgens() {
    let dir = env!("CARGO_MANIFEST_DIR");
    let config = cbindgen::Config::from_file(format!("{dir}/cbindgen.toml")).unwrap();
    let mut out = Vec::new();
    cbindgen::Builder::new()
        .with_crate(dir)
        .with_config(config)
        .generate()
        .expect("cbindgen")
        .write(&mut out);
    let fresh = String::from_utf8(out).unwrap();
    let path = format!("{dir}/include/zwidth.h");
    if std::env::var_os("ZWIDTH_BLESS").is_some() {
        std::fs::write(&path, &fresh).unwrap();
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        committed == fresh,
        "{path} differs from what cbindgen writes: run `ZWIDTH_BLESS=1 cargo test -p zwidth-ffi --test abi header` and commit it"
    );
}
