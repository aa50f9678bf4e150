//! The option reference, `docs/options.md`, generated from the one
//! declaration of the options ([`super::options::OPTIONS`]).

use super::options::*;

/// The reference of every option and case-file key, in Markdown
/// (`docs/options.md`).
pub fn markdown() -> String {
    let cell = |s: &str| s.replace('|', "\\|").replace('\n', " ");
    let mut t = String::from(
        "# Options and case-file keys\n\n\
         Generated from the one declaration of the options (`src/config/options.rs`) by \
         `markdown` in `src/config/reference.rs`; `tests/options_reference.rs` checks that this \
         file is up to date and matches `octmesh octree --help` and `octmesh mesh --help`. \
         Do not edit by hand: after changing an option, run \
         `OCTMESH_BLESS=1 cargo test --release --test options_reference`.\n\n\
         Every option fills the case-file keys named next to it (`table.key`, or the \
         `[[regions]]` tables); in a case file (`octmesh mesh case.toml`) the same keys \
         take TOML values, and options given with a case file override its keys. \
         `octmesh mesh ... --print-case` prints the case file of a command line.\n",
    );
    for (title, scope) in [
        ("`octmesh octree` and `octmesh mesh`", Scope::Octree),
        ("`octmesh mesh` only", Scope::Mesh),
    ] {
        t.push_str(&format!(
            "\n## {title}\n\n| Option | Case-file key | Default | Range | Description |\n\
             |---|---|---|---|---|\n"
        ));
        for o in OPTIONS.iter().filter(|o| o.scope == scope) {
            let flag = match o.value {
                Some(v) if o.kind != Kind::Input => format!("`{} {v}`", o.flag()),
                _ => format!("`{}`", o.flag()),
            };
            let keys: Vec<String> = o.keys.iter().map(|k| format!("`{k}`")).collect();
            let keys = match keys.is_empty() {
                true => "(command line only)".to_string(),
                false => keys.join(", "),
            };
            let default = o.default_text().unwrap_or_else(|| {
                match o.kind {
                    Kind::Input => "",
                    Kind::Switch => "off",
                    Kind::Many => "none",
                    _ if o.keys.is_empty() => "",
                    _ => "unset",
                }
                .to_string()
            });
            let range = o.range.map(|r| r.0.to_string()).unwrap_or_default();
            t.push_str(&format!(
                "| {flag} | {keys} | {} | {} | {} |\n",
                cell(&default),
                cell(&range),
                cell(o.help.trim())
            ));
        }
    }
    t.push_str(
        "\n## `octmesh check`\n\nDiagnoses a surface; it reads no case file.\n\n\
         | Option | Description |\n|---|---|\n",
    );
    let check = super::cli::command();
    let check = check.find_subcommand("check").into_iter();
    for a in check.flat_map(|c| c.get_arguments()) {
        let value = a.get_value_names().map(|v| v.join(" "));
        let flag = match (a.get_long(), value) {
            (Some(l), Some(v)) if a.get_action().takes_values() => format!("`--{l} {v}`"),
            (Some(l), _) => format!("`--{l}`"),
            (None, v) => format!("`{}`", v.unwrap_or_default()),
        };
        let help = a.get_help().map(|h| h.to_string()).unwrap_or_default();
        t.push_str(&format!("| {flag} | {} |\n", cell(&help)));
    }
    t
}
