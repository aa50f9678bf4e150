//! STL input and output.
//!
//! # Format detection
//!
//! Many binary STL files have an 80-byte header that starts with `solid`, so
//! the header text alone cannot decide the format. The size can: a binary
//! file is exactly `84 + 50 n` bytes where `n` is the little-endian `u32` at
//! offset 80. The rules, in order:
//!
//! 1. empty input: error;
//! 2. at least 84 bytes and the size matches `n`: binary;
//! 3. starts (after whitespace) with `solid`, any case: ASCII;
//! 4. at least 84 bytes: a binary file of the wrong size, error;
//! 5. otherwise: too short for binary, error.
//!
//! If rule 3 applies but the ASCII parse fails and the bytes contain control
//! characters that never occur in text, the file is reported as a
//! wrong-size binary file instead, which is the likelier cause.
//!
//! Binary files are decoded here; ASCII files go through `stl_io` after a
//! light normalisation (keywords lower-cased, normals replaced since they
//! are ignored, consecutive solids merged into one surface whose
//! [`Parts`] remember each triangle's solid). Coordinates are `f32` in the
//! file and widened to `f64`.
//!
//! On several ranks, [`read_stl_file_on`] gives each rank its share of the
//! file to read ([`shared`]).

use std::io::Cursor;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;

use super::{Parts, Surface, Triangle};
use crate::error::{Error, Result};

pub mod shared;
pub use shared::{read_stl_file_on, read_stl_share, StlShare};

const HEADER: usize = 80;
const PREAMBLE: usize = 84;
const RECORD: usize = 50;

/// Reads an ASCII or binary STL file into a validated [`Surface`].
///
/// Errors (see [`crate::error::ErrorKind`]): an empty path is
/// `InvalidArgument`; a missing, unreadable or directory path is `Io`;
/// malformed content is `Format`; an unusable surface (no triangles, NaN or
/// infinite coordinates) is `Geometry`. Content errors are prefixed with the
/// path.
pub fn read_stl_file(path: &Path) -> Result<Surface> {
    if path.as_os_str().is_empty() {
        return Err(Error::invalid("empty STL path"));
    }
    if path.is_dir() {
        return Err(Error::io(format!(
            "'{}' is a directory, not an STL file",
            path.display()
        )));
    }
    let bytes = std::fs::read(path)
        .map_err(|e| Error::io(format!("cannot read STL file '{}': {}", path.display(), e)))?;
    read_stl_bytes(&bytes)
        .map_err(|e| Error::new(e.kind(), format!("STL file '{}': {}", path.display(), e)))
}

/// Decodes ASCII or binary STL content (see the module documentation for
/// how the format is chosen) into a validated [`Surface`].
pub fn read_stl_bytes(bytes: &[u8]) -> Result<Surface> {
    let len = bytes.len();
    if len == 0 {
        return Err(Error::format("empty file"));
    }
    let declared = (len >= PREAMBLE).then(|| declared_count(bytes));
    if let Some(n) = declared {
        if binary_size(n) == len as u64 {
            return read_binary(bytes, n as usize);
        }
    }
    if starts_with_solid(bytes) {
        return match read_ascii(bytes) {
            Err(e) if declared.is_some() && looks_binary(bytes) => {
                let n = declared.unwrap_or(0);
                Err(Error::format(format!(
                    "{} (the header starts with \"solid\" but the content is not ASCII STL: {})",
                    size_mismatch(n, len),
                    e
                )))
            }
            other => other,
        };
    }
    match declared {
        Some(n) => Err(Error::format(size_mismatch(n, len))),
        None => Err(Error::format(format!(
            "file too short to be a binary STL ({len} bytes)"
        ))),
    }
}

/// Writes `surface` as binary STL. Coordinates are rounded to `f32`; normals
/// are recomputed from the vertices.
pub fn write_stl_binary(path: &Path, surface: &Surface) -> Result<()> {
    let bytes = encode_binary(surface.triangles(), b"binary STL written by octmesh");
    std::fs::write(path, bytes)
        .map_err(|e| Error::io(format!("cannot write STL file '{}': {}", path.display(), e)))
}

fn encode_binary(tris: &[Triangle], header: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(PREAMBLE + RECORD * tris.len());
    let mut h = [b' '; HEADER];
    let used = header.len().min(HEADER);
    h[..used].copy_from_slice(&header[..used]);
    out.extend_from_slice(&h);
    out.extend_from_slice(&(tris.len() as u32).to_le_bytes());
    for t in tris {
        let n = t.normal();
        let len = super::vector::norm(n);
        let unit = if len > 0.0 && len.is_finite() {
            n.map(|c| c / len)
        } else {
            [0.0; 3]
        };
        for c in unit.iter().chain(t.v.iter().flatten()) {
            out.extend_from_slice(&(*c as f32).to_le_bytes());
        }
        out.extend_from_slice(&[0, 0]);
    }
    out
}

fn declared_count(bytes: &[u8]) -> u32 {
    u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]])
}

fn binary_size(n: u32) -> u64 {
    PREAMBLE as u64 + RECORD as u64 * u64::from(n)
}

fn size_mismatch(n: u32, len: usize) -> String {
    let expected = binary_size(n);
    let cause = if (len as u64) < expected {
        "truncated or corrupt"
    } else {
        "trailing data or corrupt"
    };
    format!("binary STL declares {n} triangles ({expected} bytes) but the file has {len} bytes ({cause})")
}

/// The triangle of nine little-endian `f32`s (36 bytes: three vertices).
fn triangle_of(rec: &[u8]) -> Triangle {
    let f = |at: usize| {
        f64::from(f32::from_le_bytes([
            rec[at],
            rec[at + 1],
            rec[at + 2],
            rec[at + 3],
        ]))
    };
    Triangle {
        v: [0, 1, 2].map(|i| [0, 1, 2].map(|k| f(12 * i + 4 * k))),
    }
}

fn read_binary(bytes: &[u8], n: usize) -> Result<Surface> {
    let mut tris = Vec::with_capacity(n);
    for rec in bytes[PREAMBLE..].chunks_exact(RECORD) {
        // Bytes 0..12 hold the normal, which is ignored.
        tris.push(triangle_of(&rec[12..48]));
    }
    debug_assert_eq!(tris.len(), n);
    Surface::new(tris)
}

fn skip_bom_and_space(bytes: &[u8]) -> &[u8] {
    let b = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    let start = b
        .iter()
        .position(|c| !c.is_ascii_whitespace())
        .unwrap_or(b.len());
    &b[start..]
}

fn starts_with_solid(bytes: &[u8]) -> bool {
    let b = skip_bom_and_space(bytes);
    b.len() >= 5 && b[..5].eq_ignore_ascii_case(b"solid")
}

/// True if the bytes contain control characters that text files do not.
fn looks_binary(bytes: &[u8]) -> bool {
    bytes
        .iter()
        .any(|&c| c < 0x20 && !matches!(c, b'\t' | b'\n' | b'\r' | 0x0b | 0x0c))
}

fn read_ascii(bytes: &[u8]) -> Result<Surface> {
    let text = String::from_utf8_lossy(bytes);
    let (normalized, solids) = normalize_ascii(&text)?;
    // stl_io is not expected to panic, but a malformed file must never take
    // the whole program down.
    let parsed = catch_unwind(AssertUnwindSafe(|| {
        let mut cursor = Cursor::new(normalized.as_bytes());
        let reader = stl_io::create_stl_reader(&mut cursor)?;
        reader.collect::<std::io::Result<Vec<stl_io::Triangle>>>()
    }));
    let facets = match parsed {
        Ok(Ok(facets)) => facets,
        Ok(Err(e)) => return Err(Error::format(format!("malformed ASCII STL: {e}"))),
        Err(_) => {
            return Err(Error::format(
                "malformed ASCII STL: the STL parser failed on this input",
            ))
        }
    };
    let tris = facets
        .iter()
        .map(|f| Triangle {
            v: f.vertices.map(|p| p.0.map(f64::from)),
        })
        .collect();
    Surface::new(tris)?.with_parts(parts_of(&solids))
}

/// Rewrites ASCII STL into the strict form `stl_io` accepts: a first line
/// `solid <name>`, lower-case keywords, finite normals, and one solid.
/// Non-finite vertex coordinates are reported here, as `stl_io` would reject
/// them with a message that does not say which triangle is affected.
fn normalize_ascii(text: &str) -> Result<(String, Vec<(String, usize)>)> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut lines = text
        .split(['\n', '\r'])
        .map(|l| l.split_whitespace().collect::<Vec<&str>>())
        .filter(|t| !t.is_empty())
        .peekable();
    let mut out = String::with_capacity(text.len() + 64);
    // The caller checked that the first token starts with "solid".
    let name_of = |t: &[&str]| t[1..].join(" ");
    let mut solids: Vec<(String, usize)> = Vec::new();
    solids.push((lines.next().map(|t| name_of(&t)).unwrap_or_default(), 0));
    out.push_str("solid octmesh\n");
    let mut facet: Option<usize> = None;
    while let Some(tokens) = lines.next() {
        let key = tokens[0].to_ascii_lowercase();
        match key.as_str() {
            "facet" => {
                facet = Some(facet.map_or(0, |f| f + 1));
                if let Some(last) = solids.last_mut() {
                    last.1 += 1;
                }
                let plain = tokens.len() == 1
                    || (tokens.len() == 5 && tokens[1].eq_ignore_ascii_case("normal"));
                if plain {
                    out.push_str("facet normal 0 0 0\n");
                } else {
                    push_line(&mut out, &tokens, 2);
                }
            }
            "outer" | "endloop" | "endfacet" => push_line(&mut out, &tokens, tokens.len()),
            "vertex" => {
                if let Some(f) = facet {
                    let bad = tokens[1..]
                        .iter()
                        .any(|t| t.parse::<f32>().is_ok_and(|x| !x.is_finite()));
                    if bad {
                        return Err(Error::geometry(format!(
                            "triangle {f} has a non-finite coordinate (NaN or infinity)"
                        )));
                    }
                }
                push_line(&mut out, &tokens, 1);
            }
            "endsolid" => {
                let another = lines
                    .peek()
                    .is_some_and(|t| t[0].eq_ignore_ascii_case("solid"));
                if another {
                    let next = lines.next().map(|t| name_of(&t)).unwrap_or_default();
                    solids.push((next, 0));
                } else {
                    out.push_str("endsolid\n");
                }
            }
            _ => push_line(&mut out, &tokens, 0),
        }
    }
    Ok((out, solids))
}

/// The parts of an ASCII file's solids (`(name, facets)` in file order):
/// solids with the same name are one part; no part when the only solid is
/// unnamed.
fn parts_of(solids: &[(String, usize)]) -> Parts {
    let mut names: Vec<String> = Vec::new();
    let mut of: Vec<u16> = Vec::new();
    for (name, n) in solids {
        let p = match names.iter().position(|m| m == name) {
            Some(p) => p,
            None => {
                names.push(name.clone());
                names.len() - 1
            }
        };
        of.extend(std::iter::repeat_n(p.min(u16::MAX as usize) as u16, *n));
    }
    if names.len() == 1 && names[0].is_empty() {
        names.clear();
    }
    if names.len() < 2 {
        of.clear();
    }
    Parts { names, of }
}

/// Appends the tokens as one line, lower-casing the first `keywords` tokens.
fn push_line(out: &mut String, tokens: &[&str], keywords: usize) {
    for (i, t) in tokens.iter().enumerate() {
        if i > 0 {
            out.push(' ');
        }
        if i < keywords {
            out.push_str(&t.to_ascii_lowercase());
        } else {
            out.push_str(t);
        }
    }
    out.push('\n');
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::ErrorKind;
    use crate::geometry::shapes::sphere;
    use std::path::PathBuf;
    use std::sync::atomic::{AtomicUsize, Ordering};

    fn temp_path(name: &str) -> PathBuf {
        static COUNTER: AtomicUsize = AtomicUsize::new(0);
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        std::env::temp_dir().join(format!(
            "octmesh-geometry-{}-{}-{}",
            std::process::id(),
            n,
            name
        ))
    }

    fn tetra() -> Vec<Triangle> {
        let a = [0.0, 0.0, 0.0];
        let b = [1.5, 0.0, 0.0];
        let c = [0.0, 2.0, 0.0];
        let d = [0.0, 0.0, 0.25];
        vec![
            Triangle::new(a, c, b),
            Triangle::new(a, b, d),
            Triangle::new(a, d, c),
            Triangle::new(b, c, d),
        ]
    }

    fn ascii(tris: &[Triangle], upper: bool) -> String {
        let mut s = String::from("solid test part\n");
        for t in tris {
            s.push_str("  facet normal 0 0 1\n    outer loop\n");
            for p in &t.v {
                s.push_str(&format!("      vertex {:e} {} {}\n", p[0], p[1], p[2]));
            }
            s.push_str("    endloop\n  endfacet\n");
        }
        s.push_str("endsolid test part\n");
        if upper {
            s.to_uppercase()
        } else {
            s
        }
    }

    fn expect_err(bytes: &[u8], kind: ErrorKind) -> String {
        let e = read_stl_bytes(bytes).unwrap_err();
        assert_eq!(e.kind(), kind, "{e}");
        e.message().to_string()
    }

    #[test]
    fn binary_round_trip() {
        let s = sphere([0.1, -0.2, 0.3], 1.7, 2);
        let path = temp_path("round-trip.stl");
        write_stl_binary(&path, &s).unwrap();
        let r = read_stl_file(&path).unwrap();
        std::fs::remove_file(&path).unwrap();
        assert_eq!(r.len(), s.len());
        for (a, b) in s.triangles().iter().zip(r.triangles()) {
            assert_eq!(a.v.map(|p| p.map(|c| c as f32 as f64)), b.v);
        }
        // A surface read from a file survives a second round trip exactly.
        let path = temp_path("round-trip-2.stl");
        write_stl_binary(&path, &r).unwrap();
        let r2 = read_stl_file(&path).unwrap();
        std::fs::remove_file(&path).unwrap();
        assert_eq!(r.triangles(), r2.triangles());
    }

    #[test]
    fn binary_with_solid_header_is_binary() {
        let tris = tetra();
        let bytes = encode_binary(&tris, b"solid part exported by a CAD program");
        assert!(bytes.starts_with(b"solid "));
        let s = read_stl_bytes(&bytes).unwrap();
        assert_eq!(s.triangles(), &tris[..]);
        // Same with a leading-whitespace, upper-case header.
        let bytes = encode_binary(&tris, b"  SOLID x");
        assert_eq!(read_stl_bytes(&bytes).unwrap().len(), 4);
    }

    #[test]
    fn ascii_lower_and_upper_case() {
        let tris = tetra();
        for upper in [false, true] {
            let text = ascii(&tris, upper);
            let s = read_stl_bytes(text.as_bytes()).unwrap();
            assert_eq!(s.triangles(), &tris[..], "upper = {upper}");
        }
        // CRLF, indentation before "solid", no solid name, mixed case.
        let text = ascii(&tris, false)
            .replacen("solid test part\n", "\n  Solid\r\n", 1)
            .replace("outer loop", "Outer Loop")
            .replace('\n', "\r\n");
        assert_eq!(read_stl_bytes(text.as_bytes()).unwrap().len(), 4);
    }

    #[test]
    fn ascii_quirks() {
        let tris = tetra();
        // Two solids in one file are merged.
        let two = format!("{}{}", ascii(&tris[..2], false), ascii(&tris[2..], true));
        assert_eq!(
            read_stl_bytes(two.as_bytes()).unwrap().triangles(),
            &tris[..]
        );
        // ... and remembered as parts: "test part" and "TEST PART".
        let parts = read_stl_bytes(two.as_bytes()).unwrap().parts().clone();
        assert_eq!(parts.names, ["test part", "TEST PART"]);
        assert_eq!(parts.of, [0, 0, 1, 1]);
        // Solids with the same name are one part; a single named solid is
        // a part without per-triangle ids.
        let same = format!("{}{}", ascii(&tris[..1], false), ascii(&tris[1..], false));
        let parts = read_stl_bytes(same.as_bytes()).unwrap().parts().clone();
        assert_eq!((parts.names.len(), parts.of.len()), (1, 0));
        let unnamed = ascii(&tris, false).replace("solid test part", "solid");
        assert!(read_stl_bytes(unnamed.as_bytes())
            .unwrap()
            .parts()
            .names
            .is_empty());
        // Normals are ignored, even when they are NaN.
        let nan_normal = ascii(&tris, false).replace("normal 0 0 1", "normal nan nan nan");
        assert_eq!(read_stl_bytes(nan_normal.as_bytes()).unwrap().len(), 4);
        // No facets at all.
        let msg = expect_err(b"solid empty\nendsolid empty\n", ErrorKind::Geometry);
        assert_eq!(msg, "surface has no triangles");
    }

    #[test]
    fn ascii_malformed() {
        let text = ascii(&tetra(), false);
        let missing = text.replacen("    endloop\n", "", 1);
        let msg = expect_err(missing.as_bytes(), ErrorKind::Format);
        assert!(msg.starts_with("malformed ASCII STL: "), "{msg}");
        assert!(msg.contains("endloop"), "{msg}");

        let cut = &text[..text.len() / 2];
        let msg = expect_err(cut.as_bytes(), ErrorKind::Format);
        assert!(msg.starts_with("malformed ASCII STL: "), "{msg}");

        let no_end = text.replace("endsolid test part\n", "");
        expect_err(no_end.as_bytes(), ErrorKind::Format);

        let bad_number = text.replacen("vertex 0e0", "vertex 0,5", 1);
        let msg = expect_err(bad_number.as_bytes(), ErrorKind::Format);
        assert!(msg.starts_with("malformed ASCII STL: "), "{msg}");
    }

    #[test]
    fn nan_coordinates() {
        let mut tris = tetra();
        tris[2].v[1][0] = f64::NAN;
        let msg = expect_err(&encode_binary(&tris, b""), ErrorKind::Geometry);
        assert_eq!(
            msg,
            "triangle 2 has a non-finite coordinate (NaN or infinity)"
        );
        tris[2].v[1][0] = f64::INFINITY;
        let msg = expect_err(&encode_binary(&tris, b""), ErrorKind::Geometry);
        assert!(msg.contains("triangle 2 "), "{msg}");

        let mut text = ascii(&tetra(), false);
        let last = text.rfind("vertex 0e0 0 0.25").unwrap();
        text.replace_range(last..last + 10, "vertex NaN");
        let msg = expect_err(text.as_bytes(), ErrorKind::Geometry);
        assert_eq!(
            msg,
            "triangle 3 has a non-finite coordinate (NaN or infinity)"
        );
        let huge = ascii(&tetra(), false).replacen("vertex 0e0", "vertex 1e39", 1);
        let msg = expect_err(huge.as_bytes(), ErrorKind::Geometry);
        assert!(msg.contains("triangle 0 "), "{msg}");
    }

    #[test]
    fn binary_size_errors() {
        let tris = tetra();
        let good = encode_binary(&tris, b"");
        assert_eq!(good.len(), 84 + 4 * 50);

        let msg = expect_err(&good[..good.len() - 20], ErrorKind::Format);
        assert_eq!(
            msg,
            "binary STL declares 4 triangles (284 bytes) but the file has 264 bytes \
             (truncated or corrupt)"
        );

        let mut more = good.clone();
        more[80..84].copy_from_slice(&1000u32.to_le_bytes());
        let msg = expect_err(&more, ErrorKind::Format);
        assert_eq!(
            msg,
            "binary STL declares 1000 triangles (50084 bytes) but the file has 284 bytes \
             (truncated or corrupt)"
        );

        let mut longer = good.clone();
        longer.extend_from_slice(&[0; 7]);
        let msg = expect_err(&longer, ErrorKind::Format);
        assert!(msg.contains("trailing data"), "{msg}");

        // A "solid" header does not hide a truncated binary file.
        let solid = encode_binary(&tris, b"solid from CAD");
        let msg = expect_err(&solid[..solid.len() - 50 - 13], ErrorKind::Format);
        assert!(
            msg.starts_with(
                "binary STL declares 4 triangles (284 bytes) but the file has 221 bytes"
            ),
            "{msg}"
        );

        let mut max = good.clone();
        max[80..84].copy_from_slice(&u32::MAX.to_le_bytes());
        expect_err(&max, ErrorKind::Format);
    }

    #[test]
    fn empty_and_short_files() {
        assert_eq!(expect_err(b"", ErrorKind::Format), "empty file");
        assert_eq!(
            expect_err(b"\x01\x02\x03", ErrorKind::Format),
            "file too short to be a binary STL (3 bytes)"
        );
        let msg = expect_err(b"solid", ErrorKind::Format);
        assert!(msg.starts_with("malformed ASCII STL: "), "{msg}");

        let path = temp_path("empty.stl");
        std::fs::write(&path, b"").unwrap();
        let e = read_stl_file(&path).unwrap_err();
        std::fs::remove_file(&path).unwrap();
        assert_eq!(e.kind(), ErrorKind::Format);
        assert!(e.message().ends_with(": empty file"), "{e}");
        assert!(e.message().contains("empty.stl"), "{e}");
    }

    #[test]
    fn path_errors() {
        let e = read_stl_file(Path::new("")).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::InvalidArgument);
        assert_eq!(e.message(), "empty STL path");

        let dir = temp_path("dir");
        std::fs::create_dir(&dir).unwrap();
        let e = read_stl_file(&dir).unwrap_err();
        std::fs::remove_dir(&dir).unwrap();
        assert_eq!(e.kind(), ErrorKind::Io);
        assert_eq!(
            e.message(),
            format!("'{}' is a directory, not an STL file", dir.display())
        );

        let missing = temp_path("missing.stl");
        let e = read_stl_file(&missing).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Io);
        assert!(
            e.message()
                .starts_with(&format!("cannot read STL file '{}': ", missing.display())),
            "{e}"
        );
        assert!(e.message().contains("os error 2"), "{e}");

        let e = crate::geometry::load_surface(missing.to_str().unwrap()).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Io);
    }

    #[test]
    fn mutated_input_never_panics() {
        let mut rng = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            rng
        };
        let sources = [
            ascii(&tetra(), false).into_bytes(),
            encode_binary(&tetra(), b"solid binary"),
        ];
        for src in &sources {
            for _ in 0..2000 {
                let mut b = src.clone();
                match next() % 3 {
                    0 => b.truncate((next() % (b.len() as u64 + 1)) as usize),
                    1 => {
                        let i = (next() % b.len() as u64) as usize;
                        b[i] = next() as u8;
                    }
                    _ => {
                        let i = (next() % b.len() as u64) as usize;
                        b.insert(i, b" \n0e.-x"[(next() % 7) as usize]);
                    }
                }
                let _ = read_stl_bytes(&b);
            }
        }
    }
}
