//! `include/octmesh.h` must be what cbindgen generates from `src/ffi`, and
//! follow the rules of the C API (`src/ffi/mod.rs`): the index types for
//! every local or global index and count, no type of the crate's internals,
//! one form for every enumeration, `bool` for yes-or-no values, and every
//! item and parameter documented. Run with `OCTMESH_UPDATE_HEADER=1` to
//! rewrite the header.

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

// ---- The rules of the C API, checked on the committed header ----

/// The committed header.
fn committed() -> String {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("include/octmesh.h");
    std::fs::read_to_string(&path).expect("read include/octmesh.h")
}

/// The header's C code: without comments, preprocessor lines and the
/// blocks for C++ only (`#ifdef __cplusplus ... #endif`).
fn code(text: &str) -> String {
    let mut bare = String::new();
    let mut rest = text;
    while let Some(i) = rest.find("/*") {
        bare.push_str(&rest[..i]);
        let end = rest[i..].find("*/").map_or(rest.len(), |j| i + j + 2);
        rest = &rest[end..];
    }
    bare.push_str(rest);
    let mut out = String::new();
    let mut cpp_only = false;
    for line in bare.lines() {
        let t = line.trim();
        if t.starts_with("#ifdef __cplusplus") {
            cpp_only = true;
        } else if cpp_only {
            cpp_only = !t.starts_with("#endif");
        } else if !t.starts_with('#') {
            out.push_str(line.split("//").next().unwrap_or(""));
            out.push('\n');
        }
    }
    out
}

/// A declaration of the header.
#[derive(Debug, Default)]
struct Item {
    /// `typedef enum`, `typedef struct`, `opaque`, `callback`, `typedef`
    /// or `function`.
    kind: &'static str,
    name: String,
    /// The return type (functions, callbacks) or the aliased type.
    ty: String,
    /// Parameters (functions, callbacks) or fields (structs): type, name.
    members: Vec<(String, String)>,
    /// Enumerators: name, value.
    enumerators: Vec<(String, String)>,
}

/// `const int32_t *offsets` as (`const int32_t *`, `offsets`); array
/// fields lose their bounds.
fn split_decl(decl: &str) -> (String, String) {
    let decl = decl.split('[').next().unwrap_or("").trim();
    let cut = decl
        .rfind(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
        .map_or(0, |i| i + 1);
    let ty = decl[..cut].split_whitespace().collect::<Vec<_>>().join(" ");
    (
        ty.replace(" *", "*")
            .replace('*', " *")
            .replace("  ", " ")
            .trim()
            .to_string(),
        decl[cut..].to_string(),
    )
}

/// The top-level declarations of the header's code.
fn items(text: &str) -> Vec<Item> {
    let code = code(text);
    // Statements end with `;` outside braces.
    let mut statements = Vec::new();
    let (mut depth, mut start) = (0, 0);
    for (i, c) in code.char_indices() {
        match c {
            '{' => depth += 1,
            '}' => depth -= 1,
            ';' if depth == 0 => {
                statements.push(
                    code[start..i]
                        .split_whitespace()
                        .collect::<Vec<_>>()
                        .join(" "),
                );
                start = i + 1;
            }
            _ => {}
        }
    }
    assert!(
        code[start..].trim().is_empty(),
        "unterminated declaration: {}",
        &code[start..]
    );
    let params = |s: &str| -> Vec<(String, String)> {
        let inner = &s[s.rfind('(').unwrap() + 1..s.rfind(')').unwrap()];
        inner
            .split(',')
            .map(str::trim)
            .filter(|p| !p.is_empty() && *p != "void")
            .map(split_decl)
            .collect()
    };
    statements
        .iter()
        .map(|s| {
            let (head, body, tail) = match (s.find('{'), s.rfind('}')) {
                (Some(a), Some(b)) => (&s[..a], &s[a + 1..b], s[b + 1..].trim()),
                _ => (s.as_str(), "", ""),
            };
            let mut item = Item::default();
            if head.starts_with("typedef enum") {
                item.kind = "typedef enum";
                item.ty = head.trim().to_string();
                item.name = tail.to_string();
                item.enumerators = body
                    .split(',')
                    .map(str::trim)
                    .filter(|e| !e.is_empty())
                    .map(|e| {
                        let (n, v) = e.split_once('=').unwrap_or((e, ""));
                        (n.trim().to_string(), v.trim().to_string())
                    })
                    .collect();
            } else if head.starts_with("typedef struct") && !body.is_empty() {
                item.kind = "typedef struct";
                item.ty = head.trim().to_string();
                item.name = tail.to_string();
                item.members = body
                    .split(';')
                    .map(str::trim)
                    .filter(|f| !f.is_empty())
                    .map(split_decl)
                    .collect();
            } else if let Some(rest) = s.strip_prefix("typedef struct ") {
                item.kind = "opaque";
                let (tag, name) = rest.split_once(' ').unwrap_or((rest, ""));
                item.ty = format!("struct {tag}");
                item.name = name.to_string();
            } else if let Some(rest) = s.strip_prefix("typedef ") {
                if let Some(open) = rest.find("(*") {
                    item.kind = "callback";
                    item.ty = rest[..open].trim().to_string();
                    let close = open + rest[open..].find(')').unwrap();
                    item.name = rest[open + 2..close].to_string();
                    item.members = params(rest);
                } else {
                    item.kind = "typedef";
                    (item.ty, item.name) = split_decl(rest);
                }
            } else {
                item.kind = "function";
                let open = s
                    .find('(')
                    .unwrap_or_else(|| panic!("not a declaration: {s}"));
                (item.ty, item.name) = split_decl(&s[..open]);
                item.members = params(s);
            }
            item
        })
        .collect()
}

/// C's own types, and MPI's communicator: the only types of the header not
/// prefixed `octmesh_`.
const STANDARD_TYPES: [&str; 15] = [
    "void", "char", "double", "bool", "int8_t", "uint8_t", "int16_t", "uint16_t", "int32_t",
    "uint32_t", "int64_t", "uint64_t", "size_t", "MPI_Comm", "float",
];

/// C's integer types: an index or a count must not be one of them.
const RAW_INTEGERS: [&str; 10] = [
    "int8_t", "uint8_t", "int16_t", "uint16_t", "int32_t", "uint32_t", "int64_t", "uint64_t",
    "size_t", "int",
];

/// Words of a parameter or field name that say it counts or indexes
/// something (of one rank, or over all ranks).
const INDEX_WORDS: [&str; 31] = [
    "n",
    "num",
    "count",
    "counts",
    "index",
    "indices",
    "idx",
    "capacity",
    "offset",
    "offsets",
    "first",
    "element",
    "elements",
    "node",
    "nodes",
    "leaf",
    "leaves",
    "face",
    "faces",
    "patch",
    "patches",
    "halo",
    "send",
    "recv",
    "owner",
    "neighbour",
    "deps",
    "global",
    "local",
    "octants",
    "roots",
];

/// Words that say what a plain integer is when it is not an index: an MPI
/// rank (MPI's `int`), an octree level, a lattice coordinate, a size in
/// bytes, a number of relaxation layers or iterations, a verbosity.
const NON_INDEX_WORDS: [&str; 12] = [
    "rank",
    "ranks",
    "level",
    "levels",
    "x",
    "y",
    "z",
    "bytes",
    "budget",
    "layers",
    "iterations",
    "verbosity",
];

/// The base type of a declaration type: `const int32_t **` -> `int32_t`.
fn base(ty: &str) -> &str {
    ty.split([' ', '*'])
        .rfind(|w| !w.is_empty() && *w != "const" && *w != "struct")
        .unwrap_or("")
}

/// The words of a name: `num_outgoing` -> `num`, `outgoing`; a count
/// written `nfields` or `ntri` gives `n` too.
fn words(name: &str) -> Vec<&str> {
    let mut w: Vec<&str> = name.split('_').collect();
    let first = w[0];
    let not_counts = [
        "name",
        "names",
        "normal",
        "non",
        "node",
        "nodes",
        "neighbour",
    ];
    if first.len() > 1 && first.starts_with('n') && !not_counts.contains(&first) {
        w.push("n");
    }
    w
}

/// Every member (parameter or field) of the header with its owner's name.
fn members(items: &[Item]) -> Vec<(&str, &str, &str)> {
    items
        .iter()
        .flat_map(|i| {
            i.members
                .iter()
                .map(move |(t, n)| (i.name.as_str(), t.as_str(), n.as_str()))
        })
        .collect()
}

#[test]
fn indices_and_counts_have_the_index_types() {
    let text = committed();
    let items = items(&text);
    let typedef = |name: &str| {
        items
            .iter()
            .find(|i| i.kind == "typedef" && i.name == name)
            .map(|i| i.ty.clone())
    };
    assert_eq!(typedef("octmesh_locidx_t").as_deref(), Some("int32_t"));
    assert_eq!(typedef("octmesh_gloidx_t").as_deref(), Some("int64_t"));
    let mut plain = 0;
    for (owner, ty, name) in members(&items) {
        if !RAW_INTEGERS.contains(&base(ty)) {
            continue;
        }
        let w = words(name);
        let non_index = w.iter().any(|w| NON_INDEX_WORDS.contains(w));
        let index = w.iter().find(|w| INDEX_WORDS.contains(w));
        assert!(
            non_index || index.is_none(),
            "{owner}: '{ty} {name}' is an index or a count ('{}'): declare it \
             octmesh_locidx_t (one rank's) or octmesh_gloidx_t (over all ranks)",
            index.unwrap_or(&""),
        );
        // 8-bit arrays hold levels and classes, named `out` by the getters.
        assert!(
            non_index || base(ty) == "int8_t",
            "{owner}: '{ty} {name}' is a plain integer whose name does not say \
             what it is: an index or a count is octmesh_locidx_t or \
             octmesh_gloidx_t; otherwise name it for what it is (a rank, a \
             level, ...; NON_INDEX_WORDS in tests/c_header.rs)"
        );
        plain += 1;
    }
    // The API's plain integers: ranks, levels, lattice corners, sizes.
    assert!(plain >= 10, "only {plain} plain integers found");
    let indexed = members(&items)
        .iter()
        .filter(|(_, t, _)| matches!(base(t), "octmesh_locidx_t" | "octmesh_gloidx_t"))
        .count();
    assert!(indexed >= 60, "only {indexed} uses of the index types");
}

#[test]
fn no_type_but_octmesh_standard_and_mpi_ones() {
    let text = committed();
    let items = items(&text);
    assert!(
        items.len() >= 80,
        "only {} declarations parsed",
        items.len()
    );
    let allowed = |t: &str| STANDARD_TYPES.contains(&t) || t.starts_with("octmesh_");
    for i in &items {
        // Declared names: octmesh_ types and callbacks, octmesh_ functions.
        let suffix_ok = match i.kind {
            "callback" => i.name.ends_with("_fn"),
            "function" => true,
            _ => i.name.ends_with("_t"),
        };
        assert!(
            i.name.starts_with("octmesh_") && suffix_ok,
            "{} '{}' is not named octmesh_..._t (types) or octmesh_..._fn (callbacks)",
            i.kind,
            i.name
        );
        let used = std::iter::once(i.ty.as_str()).chain(i.members.iter().map(|(t, _)| t.as_str()));
        for ty in used {
            for word in ty.split([' ', '*']).filter(|w| !w.is_empty()) {
                let keyword = matches!(word, "const" | "struct" | "enum" | "typedef");
                assert!(
                    keyword || allowed(word),
                    "{} '{}' uses the type '{word}': the C API shows only its own \
                     octmesh_ types, C's and MPI_Comm (give the C API a #[repr(C)] \
                     type of its own, or plain parameters)",
                    i.kind,
                    i.name
                );
            }
        }
    }
    // Whatever the parser above would miss: a capitalised identifier
    // anywhere in the code is a constant OCTMESH_... or MPI_Comm.
    for word in code(&text).split(|c: char| !(c.is_ascii_alphanumeric() || c == '_')) {
        if word.chars().any(|c| c.is_ascii_uppercase()) {
            assert!(
                word.starts_with("OCTMESH_") || word == "MPI_Comm",
                "the header names '{word}', which is not part of the C API"
            );
        }
    }
}

#[test]
fn every_enumeration_has_one_form() {
    let text = committed();
    let items = items(&text);
    let enums: Vec<&Item> = items.iter().filter(|i| i.kind == "typedef enum").collect();
    assert!(enums.len() >= 7, "only {} enumerations found", enums.len());
    for e in &enums {
        // p4est's form: typedef enum { OCTMESH_X_A = 0, ... } octmesh_x_t;
        assert_eq!(
            e.ty, "typedef enum",
            "{}: not an anonymous typedef enum",
            e.name
        );
        let stem = e
            .name
            .strip_prefix("octmesh_")
            .and_then(|n| n.strip_suffix("_t"))
            .unwrap_or_else(|| panic!("enumeration {} is not named octmesh_..._t", e.name));
        let prefix = format!("OCTMESH_{}_", stem.to_ascii_uppercase());
        assert!(!e.enumerators.is_empty(), "{} is empty", e.name);
        for (name, value) in &e.enumerators {
            assert!(
                name.starts_with(&prefix) && name.len() > prefix.len(),
                "{}: constant {name} is not named {prefix}...",
                e.name
            );
            assert!(
                value.parse::<i64>().is_ok(),
                "{}: {name} has no explicit value",
                e.name
            );
        }
    }
    // No other form: no tagged or bare `enum`, and no integer typedef
    // standing for an enumeration (only the two index types are integer
    // typedefs).
    let statements = code(&text);
    assert_eq!(
        statements.matches("enum").count(),
        statements.matches("typedef enum {").count(),
        "an enumeration is declared in another form than `typedef enum {{ ... }} octmesh_x_t;`"
    );
    for i in items.iter().filter(|i| i.kind == "typedef") {
        assert!(
            matches!(i.name.as_str(), "octmesh_locidx_t" | "octmesh_gloidx_t"),
            "typedef {} {}: an enumeration's values are its enum type",
            i.ty,
            i.name
        );
    }
    // A parameter documented as `one of `octmesh_x_t`` has that type.
    for item in text.split("\n\n") {
        let Some(decl) = items_of(item).into_iter().next() else {
            continue;
        };
        for line in item.lines().filter(|l| l.contains("\\param")) {
            let Some(p) = line.split_whitespace().nth(2) else {
                continue;
            };
            let doc = param_doc(item, p);
            let Some(e) = enums
                .iter()
                .find(|e| doc.contains(&format!("one of `{}`", e.name)))
            else {
                continue;
            };
            let ty = decl
                .members
                .iter()
                .find(|(_, n)| n == p)
                .map(|(t, _)| base(t));
            assert_eq!(
                ty,
                Some(e.name.as_str()),
                "{}: parameter {p} is one of {} but not declared so",
                decl.name,
                e.name
            );
        }
    }
}

/// The declarations of one item of the header (its doc comment and code).
fn items_of(item: &str) -> Vec<Item> {
    let c = code(item);
    if c.trim().is_empty() || !c.trim_end().ends_with(';') {
        return Vec::new();
    }
    items(item)
}

/// The text of the `\param` entry of `p` in an item's comment (its
/// continuation lines included).
fn param_doc(item: &str, p: &str) -> String {
    let mut doc = String::new();
    let mut inside = false;
    for line in item.lines() {
        let l = line.trim().trim_start_matches('*').trim();
        if l.starts_with("\\param") {
            inside = l.split_whitespace().nth(1) == Some(p);
        } else if l.is_empty() || l.starts_with('/') {
            inside = false;
        }
        if inside {
            doc.push_str(l);
            doc.push(' ');
        }
    }
    doc
}

#[test]
fn yes_or_no_values_are_bool() {
    let text = committed();
    let items = items(&text);
    let flag_names = [
        "keep",
        "overwrite",
        "recursive",
        "enable",
        "enabled",
        "flag",
    ];
    let flag_prefixes = ["is_", "has_", "use_", "allow_", "do_"];
    let mut bools = 0;
    for (owner, ty, name) in members(&items) {
        if base(ty) == "bool" {
            bools += 1;
            continue;
        }
        let named_as_flag = RAW_INTEGERS.contains(&base(ty))
            && (flag_names.contains(&name) || flag_prefixes.iter().any(|p| name.starts_with(p)));
        assert!(
            !named_as_flag,
            "{owner}: '{ty} {name}' is a yes-or-no value: declare it bool"
        );
    }
    assert!(bools >= 4, "only {bools} bool parameters");
    // By the documentation: a value read as zero or non-zero is a bool,
    // parameters and callbacks' answers alike.
    for item in text.split("\n\n") {
        let Some(decl) = items_of(item).into_iter().next() else {
            continue;
        };
        for (ty, p) in &decl.members {
            let doc = param_doc(item, p);
            assert!(
                !doc.contains("non-zero") || base(ty) == "bool",
                "{}: parameter {p} is read as zero or non-zero: declare it bool",
                decl.name
            );
        }
        let says_yes_or_no = item.contains("returns non-zero")
            || item.contains("returns true")
            || item.contains("return non-zero");
        if decl.kind == "callback" && says_yes_or_no {
            assert_eq!(
                decl.ty, "bool",
                "callback {} answers yes or no: it returns bool",
                decl.name
            );
            assert!(
                !item.contains("non-zero"),
                "callback {}: document its answer as true or false",
                decl.name
            );
        }
    }
    assert!(
        text.contains("#include <stdbool.h>"),
        "the header uses bool without <stdbool.h>"
    );
}
