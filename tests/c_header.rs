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
        .with_src(root.join("src/ffi/mod.rs"))
        .generate()
        .expect("cbindgen failed")
        .write(&mut out);
    order_sections(&String::from_utf8(out).expect("header is UTF-8"))
}

/// The subsystems of the C API in pipeline order, with the prefix of their
/// functions (the handle's functions are the rest).
const SECTIONS: [(&str, &str); 4] = [
    ("", "The handle: options, creation, errors, the domain cube"),
    ("octmesh_surface_", "Surfaces"),
    (
        "octmesh_octree_",
        "The octree: refinement, balance, partition, leaves",
    ),
    ("octmesh_mesh_", "The mesh: building it, its arrays, output"),
];

/// Puts the function declarations in pipeline order, each subsystem under a
/// banner (cbindgen emits them file by file in name order).
fn order_sections(text: &str) -> String {
    let open = "extern \"C\" {\n#endif // __cplusplus\n\n";
    let close = "#ifdef __cplusplus\n}  // extern \"C\"";
    let (Some(a), Some(b)) = (text.find(open), text.find(close)) else {
        return text.to_string();
    };
    let body = &text[a + open.len()..b];
    // Items are a doc comment and a declaration, separated by blank lines.
    let items: Vec<&str> = body
        .split("\n\n")
        .filter(|i| !i.trim().is_empty())
        .collect();
    let section = |item: &str| {
        let decl = item
            .lines()
            .find(|l| l.contains("octmesh_") && l.contains('(') && !l.starts_with(' '))
            .unwrap_or("");
        let name = decl
            .split('(')
            .next()
            .unwrap_or("")
            .rsplit([' ', '*'])
            .next()
            .unwrap_or("");
        (1..SECTIONS.len())
            .rev()
            .find(|&k| name.starts_with(SECTIONS[k].0))
            .unwrap_or(0)
    };
    let mut out = text[..a + open.len()].to_string();
    for (k, (_, title)) in SECTIONS.iter().enumerate() {
        out.push_str(&format!("/* ---- {title} ---- */\n\n"));
        for item in items.iter().filter(|i| section(i) == k) {
            out.push_str(item.trim_end_matches('\n'));
            out.push_str("\n\n");
        }
    }
    out.push_str(&text[b..]);
    out
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

#[test]
fn every_parameter_is_documented_in_or_out() {
    // p4est's rule: each parameter of each function has a \\param[in],
    // [out] or [in,out] line in the comment above it.
    let text = generate();
    let mut checked = 0;
    for item in text.split("\n\n") {
        let Some(start) = item
            .find("\noctmesh_")
            .or_else(|| item.find("\nconst char *octmesh_"))
            .or_else(|| item.find("\nvoid octmesh_"))
        else {
            continue;
        };
        let decl: String = item[start..]
            .split_whitespace()
            .collect::<Vec<_>>()
            .join(" ");
        let (Some(open), Some(close)) = (decl.find('('), decl.rfind(')')) else {
            continue;
        };
        let params: Vec<&str> = decl[open + 1..close]
            .split(',')
            .map(|p| p.trim().rsplit([' ', '*']).next().unwrap_or(""))
            .filter(|p| !p.is_empty() && *p != "void")
            .collect();
        let doc = &item[..start];
        for p in params {
            let documented = ["[in]", "[out]", "[in,out]"].iter().any(|dir| {
                doc.lines().any(|l| {
                    l.contains(&format!("\\param{dir}")) && l.split_whitespace().nth(2) == Some(p)
                })
            });
            assert!(
                documented,
                "parameter '{p}' of {decl} has no \\param[in]/[out] line"
            );
        }
        checked += 1;
    }
    assert!(
        checked >= 30,
        "only {checked} functions found in the header"
    );
}

#[test]
fn fortran_parameters_equal_the_header() {
    // Every OCTMESH_* constant of the Fortran module has the value the C
    // header gives it.
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let header = generate();
    let fortran =
        std::fs::read_to_string(root.join("fortran/octmesh.f90")).expect("read the Fortran module");
    let c_value = |name: &str| -> Option<i64> {
        header.lines().find_map(|l| {
            let l = l.trim().trim_end_matches(',');
            let (n, v) = l.split_once(" = ")?;
            (n.trim() == name).then(|| v.trim().parse().ok()).flatten()
        })
    };
    let mut seen = 0;
    // Join continuation lines, then read `NAME = value` pairs of parameter
    // statements.
    let joined = fortran.replace("&\n", " ");
    for line in joined.lines().filter(|l| l.contains("parameter")) {
        let decls = line.split("::").nth(1).unwrap_or("");
        for d in decls.split(',') {
            let Some((n, v)) = d.split_once('=') else {
                continue;
            };
            let (n, v) = (n.trim(), v.trim().trim_start_matches('&').trim());
            if !n.starts_with("OCTMESH_") || n == "OCTMESH_ROOT_LEN" {
                continue;
            }
            let value: i64 = v
                .parse()
                .unwrap_or_else(|_| panic!("{n} = {v} is not an integer"));
            assert_eq!(
                c_value(n),
                Some(value),
                "Fortran {n} = {value} differs from the header"
            );
            seen += 1;
        }
    }
    assert!(seen >= 25, "only {seen} Fortran parameters checked");
}
