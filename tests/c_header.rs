//! `include/octmesh.h` must be what cbindgen generates from `src/ffi`.
//! Run with `OCTMESH_UPDATE_HEADER=1` to rewrite it.

use std::path::PathBuf;

fn generate() -> String {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let mut config =
        cbindgen::Config::from_file(root.join("cbindgen.toml")).expect("read cbindgen.toml");
    let major = env!("CARGO_PKG_VERSION_MAJOR");
    let minor = env!("CARGO_PKG_VERSION_MINOR");
    let patch = env!("CARGO_PKG_VERSION_PATCH");
    let version = env!("CARGO_PKG_VERSION");
    config.after_includes = Some(format!(
        "\n/** Version of the octmesh library this header belongs to. */\n\
         #define OCTMESH_VERSION_MAJOR {major}\n\
         #define OCTMESH_VERSION_MINOR {minor}\n\
         #define OCTMESH_VERSION_PATCH {patch}\n\
         #define OCTMESH_VERSION_STRING \"{version}\"\n"
    ));
    let mut out = Vec::new();
    cbindgen::Builder::new()
        .with_config(config)
        .with_crate(&root)
        .generate()
        .expect("cbindgen failed")
        .write(&mut out);
    String::from_utf8(out).expect("header is UTF-8")
}

#[test]
fn header_is_up_to_date() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("include/octmesh.h");
    let fresh = generate();
    if std::env::var_os("OCTMESH_UPDATE_HEADER").is_some_and(|v| v == "1") {
        std::fs::write(&path, &fresh).expect("write include/octmesh.h");
        return;
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        committed == fresh,
        "include/octmesh.h is out of date with src/ffi: regenerate it with \
         `OCTMESH_UPDATE_HEADER=1 cargo test --test c_header`"
    );
}

#[test]
fn every_item_is_documented() {
    // Each function, type, field and constant in the header is preceded by
    // a comment. Items start at column 0; fields and enumerators at column
    // 2 (deeper indentation continues a declaration).
    let text = generate();
    let lines: Vec<&str> = text.lines().collect();
    for (i, l) in lines.iter().enumerate() {
        let top = !l.is_empty()
            && !l.starts_with([' ', '#', '/', '*', '}'])
            && !l.starts_with("extern")
            && !l.starts_with("typedef struct octmesh_t octmesh_t");
        let member =
            l.starts_with("  ") && !l.starts_with("   ") && !l.trim().starts_with(['/', '*']);
        if !(top || member) {
            continue;
        }
        let prev = lines[..i]
            .iter()
            .rev()
            .find(|p| !p.trim().is_empty())
            .copied()
            .unwrap_or("");
        assert!(
            prev.trim_end().ends_with("*/"),
            "undocumented item in the header: {l}"
        );
    }
}
