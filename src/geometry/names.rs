//! Patch names: the six sides of the domain, the surface patch's default
//! name from its file, and the rules every patch name follows (a subset of
//! OpenFOAM's `word`). The names themselves are given per mesh by
//! [`crate::mesh::patches::PatchNames`].

use crate::error::{Error, Result};

/// Names of the six domain-side patches, in patch-id order.
pub const SIDE_PATCHES: [&str; 6] = ["xmin", "xmax", "ymin", "ymax", "zmin", "zmax"];

/// Checks that `name` is a valid patch name: a letter or `_` first, then
/// letters, digits and `_ . - + :`, at most 255 characters (a subset of
/// OpenFOAM's `word` that is also safe as a file and field name).
pub fn check_word(name: &str) -> Result<()> {
    let mut chars = name.chars();
    let first_ok = chars
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_');
    let rest_ok = chars.all(|c| c.is_ascii_alphanumeric() || "_.-+:".contains(c));
    if first_ok && rest_ok && name.len() <= 255 {
        Ok(())
    } else {
        Err(Error::invalid(format!(
            "'{name}' is not a valid patch name: use a letter or '_' first, then letters, digits \
             or _ . - + : (no spaces, quotes, slashes, semicolons or braces)"
        )))
    }
}

/// The surface patch's default name: the file stem of `surface` with every
/// character a patch name cannot hold replaced by `_` (`sphere` for the
/// built-in sphere, `bunny` for `data/bunny.stl`).
pub fn surface_patch_name(surface: &str) -> String {
    let stem = std::path::Path::new(surface)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    word_of(&stem)
}

/// `text` made a valid patch name: characters a name cannot hold become
/// `_`, a `_` goes before a leading digit, and a side's name gets
/// `_surface`.
pub(crate) fn word_of(text: &str) -> String {
    let mut name: String = text
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "_.-+:".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect();
    if !name.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_') {
        name.insert(0, '_');
    }
    if SIDE_PATCHES.contains(&name.as_str()) {
        name.push_str("_surface");
    }
    name.truncate(255);
    name
}
