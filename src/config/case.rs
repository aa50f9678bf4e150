//! TOML case files: a [`Config`] written down, with errors that give the
//! file, the line and the key.

use std::path::Path;

use super::{Config, ConfigError};
use crate::error::{Error, Result};

/// A case file read from disk: its configuration and its text (kept to
/// point at the line of a key in later messages).
#[derive(Clone, Debug)]
pub struct CaseFile {
    /// The file's name as given.
    pub name: String,
    /// Its text.
    pub text: String,
    /// What it configures.
    pub config: Config,
}

impl CaseFile {
    /// Reads and parses `path`. Unknown tables or keys, wrong types and
    /// malformed TOML are [`crate::ErrorKind::InvalidArgument`] errors
    /// naming the file, the line and the key.
    pub fn read(path: &Path) -> Result<CaseFile> {
        let name = path.display().to_string();
        let text = std::fs::read_to_string(path)
            .map_err(|e| Error::io(format!("cannot read the case file '{name}': {e}")))?;
        let config = parse(&text, &name)?;
        Ok(CaseFile { name, text, config })
    }

    /// How a message names `key` of this file: `case.toml line 7:
    /// domain.fit`, or without the line when the key is not written in it.
    pub fn label(&self, key: &str) -> String {
        match line_of_key(&self.text, key) {
            Some(line) => format!("{} line {line}: {key}", self.name),
            None => format!("{}: {key}", self.name),
        }
    }

    /// A validation error in this file's words.
    pub fn error(&self, e: &ConfigError) -> Error {
        Error::invalid(e.render(|k| self.label(k)))
    }
}

/// Parses the text of a case file called `file` (for messages).
pub fn parse(text: &str, file: &str) -> Result<Config> {
    toml::from_str(text).map_err(|e| {
        let message = e.message().trim_end();
        let at = e.span().map(|s| s.start).unwrap_or(0);
        let line = text[..at.min(text.len())].matches('\n').count() + 1;
        match (e.span(), key_at(text, line)) {
            (Some(_), Some(key)) => Error::invalid(format!("{file} line {line}: {key}: {message}")),
            (Some(_), None) => Error::invalid(format!("{file} line {line}: {message}")),
            (None, _) => Error::invalid(format!("{file}: {message}")),
        }
    })
}

/// The `[table]` header in force at 1-based `line` and the key written on
/// it, as `table.key` (or the header itself when the line is one).
fn key_at(text: &str, line: usize) -> Option<String> {
    let lines: Vec<&str> = text.lines().collect();
    let here = lines.get(line.checked_sub(1)?)?.trim();
    if let Some(h) = header(here) {
        return Some(h.to_string());
    }
    let key = here.split('=').next()?.trim().trim_matches('"');
    if key.is_empty() || here.starts_with('#') || !here.contains('=') {
        return None;
    }
    let table = lines[..line - 1]
        .iter()
        .rev()
        .find_map(|l| header(l.trim()));
    Some(match table {
        Some(t) => format!("{t}.{key}"),
        None => key.to_string(),
    })
}

/// The table name of a `[table]` line.
fn header(line: &str) -> Option<&str> {
    let inner = line.strip_prefix('[')?.split(']').next()?;
    Some(inner.trim())
}

/// The 1-based line where `table.key` is written, if it is.
fn line_of_key(text: &str, key: &str) -> Option<usize> {
    (1..=text.lines().count()).find(|&l| key_at(text, l).as_deref() == Some(key))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_name_file_line_and_key() {
        let text = "[surface]\nfile = \"sphere\"\n\n[octree]\nlevl = 4\n";
        let e = parse(text, "c.toml").unwrap_err();
        assert!(
            e.message()
                .starts_with("c.toml line 5: octree.levl: unknown field `levl`"),
            "{}",
            e.message()
        );
        let text = "[octree]\nlevel = \"nine\"\n";
        let e = parse(text, "c.toml").unwrap_err();
        assert!(
            e.message()
                .starts_with("c.toml line 2: octree.level: invalid type"),
            "{}",
            e.message()
        );
        let e = parse("[octree\nlevel = 3\n", "c.toml").unwrap_err();
        assert!(e.message().starts_with("c.toml line 1"), "{}", e.message());
        let text = "[mesh]\nkeep = \"solid\"\n";
        let e = parse(text, "c.toml").unwrap_err();
        assert!(
            e.message().contains("mesh.keep: unknown keep mode 'solid'"),
            "{}",
            e.message()
        );
    }

    #[test]
    fn labels_point_at_the_line() {
        let text = "[surface]\nfile = \"sphere\"\n[domain]\n# fit = 1\nfit = 2.0\n";
        let case = CaseFile {
            name: "c.toml".into(),
            text: text.into(),
            config: parse(text, "c.toml").unwrap(),
        };
        assert_eq!(case.label("domain.fit"), "c.toml line 5: domain.fit");
        assert_eq!(case.label("octree.level"), "c.toml: octree.level");
    }
}
