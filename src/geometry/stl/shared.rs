//! Reading one STL file on all the ranks of a communicator, each rank its
//! own share of the bytes.
//!
//! A binary file splits by records: of `n` triangles, rank `r` of `P` reads
//! triangles `r n / P` to `(r + 1) n / P`. An ASCII file splits by bytes:
//! rank `r` starts at the first line at or after byte `r size / P` that
//! opens a facet or a solid (`facet`, `solid` or `endsolid`), found by
//! scanning its own bytes, and ends where the next rank starts, so each
//! rank parses whole facets and solid boundaries. The ranks then exchange
//! what they read (the vertices as `f32`, and for ASCII the solid names
//! and facet counts in file order), and each one builds the whole surface,
//! the same triangles in the same order with the same parts as
//! [`read_stl_file`] gives.
//!
//! Files this strict split does not accept (a file shorter than its
//! declared triangles, a malformed facet, text after the last `endsolid`,
//! an I/O error on one rank) are read whole by every rank with
//! [`read_stl_file`] once the ranks agree that one of them failed, so that
//! the error, or the lenient reading of an unusual file, is exactly the
//! one-process one, the same on every rank.

use std::borrow::Cow;
use std::path::Path;

use super::{
    binary_size, declared_count, parts_of, read_stl_file, starts_with_solid, triangle_of, PREAMBLE,
    RECORD,
};
use crate::error::{Error, Result};
use crate::geometry::{Surface, Triangle};
use crate::parallel::comm::Comm;
use crate::parallel::file::{Mode, SharedFile};

/// Bytes a rank reads past its range at first, to finish its last facet
/// (an ASCII facet takes about 250).
const MARGIN: u64 = 4096;

/// Bytes of one triangle's vertices: nine `f32`.
const VERTICES: usize = 36;

/// Reads the STL file at `path` on every rank of `comm` (see the module
/// documentation). Collective. On one rank, and for files the split does
/// not accept, it is [`read_stl_file`]; the result, error included, is
/// the same on every rank.
pub fn read_stl_file_on(comm: &dyn Comm, path: &Path) -> Result<Surface> {
    if comm.size() == 1 || path.as_os_str().is_empty() {
        return read_stl_file(path);
    }
    match read_split(comm, path) {
        Some(surface) => surface
            .map_err(|e| Error::new(e.kind(), format!("STL file '{}': {}", path.display(), e))),
        None => read_stl_file(path),
    }
}

/// True on every rank if `ok` is true on every rank. Collective.
fn all_ok(comm: &dyn Comm, ok: bool) -> bool {
    let mut v = [u64::from(!ok)];
    comm.max_u64(&mut v);
    v[0] == 0
}

/// The split read: `None` on every rank when any rank's share failed (the
/// caller then reads the whole file), otherwise the surface, or the error
/// the whole surface gives (the same on every rank).
fn read_split(comm: &dyn Comm, path: &Path) -> Option<Result<Surface>> {
    // Only regular files: MPI-IO may not return on a directory.
    let regular = std::fs::metadata(path).is_ok_and(|m| m.is_file());
    if !all_ok(comm, regular) {
        return None;
    }
    let file = SharedFile::open(comm, path, Mode::Read).ok()?;
    let size = file.size();
    // Every rank must see the same size: one reduction of the size and its
    // complement gives the largest and the smallest.
    let s = *size.as_ref().unwrap_or(&0);
    let mut v = [u64::from(size.is_err()), s, !s];
    comm.max_u64(&mut v);
    if v[0] != 0 || v[1] != !v[2] {
        return None;
    }
    let size = v[1];
    let mut head = vec![0u8; size.min(PREAMBLE as u64) as usize];
    let ok = file.read_at_all(0, &mut head).is_ok();
    if !all_ok(comm, ok) {
        return None;
    }
    if head.len() == PREAMBLE {
        let n = declared_count(&head);
        if binary_size(n) == size {
            return read_binary(comm, &file, n as u64);
        }
    }
    if !starts_with_solid(&head) {
        return None;
    }
    read_ascii(comm, &file, size)
}

/// The range `[r n / p, (r + 1) n / p)` of rank `r`.
pub(crate) fn share(n: u64, r: usize, p: usize) -> (u64, u64) {
    let at = |k: usize| (u128::from(n) * k as u128 / p as u128) as u64;
    (at(r), at(r + 1))
}

/// This rank's share of the `n` records of a binary STL file, or `None`
/// on every rank when a rank's read failed. Collective.
fn read_records(comm: &dyn Comm, file: &SharedFile, n: u64) -> Option<Vec<u8>> {
    let (lo, hi) = share(n, comm.rank(), comm.size());
    let mut records = vec![0u8; ((hi - lo) as usize) * RECORD];
    let ok = file
        .read_at_all(PREAMBLE as u64 + lo * RECORD as u64, &mut records)
        .is_ok();
    all_ok(comm, ok).then_some(records)
}

fn read_binary(comm: &dyn Comm, file: &SharedFile, n: u64) -> Option<Result<Surface>> {
    let records = read_records(comm, file, n)?;
    let mut mine = Vec::with_capacity(records.len() / RECORD * VERTICES);
    for rec in records.chunks_exact(RECORD) {
        // Bytes 0..12 hold the normal, which is ignored.
        mine.extend_from_slice(&rec[12..12 + VERTICES]);
    }
    drop(records);
    let (all, _) = comm.allgatherv_bytes(&mine);
    drop(mine);
    Some(Surface::new(triangles(&all)))
}

/// One rank's share of a binary STL file, for the distributed surface:
/// triangles `first..first + triangles.len()` of the file's `total`, not
/// validated (the ranks validate the whole together).
pub struct StlShare {
    pub triangles: Vec<Triangle>,
    pub first: u64,
    pub total: u64,
}

/// Reads this rank's share of the binary STL file at `path` (records
/// `r n / P` to `(r + 1) n / P`) and nothing else. `None` on every rank
/// when the file is not a binary STL whose size matches its count, or a
/// rank failed to read: the caller then reads the file whole. Collective.
pub fn read_stl_share(comm: &dyn Comm, path: &Path) -> Option<StlShare> {
    let regular = std::fs::metadata(path).is_ok_and(|m| m.is_file());
    if !all_ok(comm, regular) {
        return None;
    }
    let file = SharedFile::open(comm, path, Mode::Read).ok()?;
    let s = file.size().unwrap_or(0);
    let mut head = vec![0u8; s.min(PREAMBLE as u64) as usize];
    let read = file.read_at_all(0, &mut head).is_ok();
    let n = if head.len() == PREAMBLE {
        declared_count(&head)
    } else {
        0
    };
    let binary = read && head.len() == PREAMBLE && binary_size(n) == s;
    if !all_ok(comm, binary) {
        return None;
    }
    let n = n as u64;
    let records = read_records(comm, &file, n)?;
    let (lo, _) = share(n, comm.rank(), comm.size());
    let triangles = records
        .chunks_exact(RECORD)
        .map(|rec| triangle_of(&rec[12..12 + VERTICES]))
        .collect();
    Some(StlShare {
        triangles,
        first: lo,
        total: n,
    })
}

/// The triangles of consecutive `VERTICES`-byte records of `f32`s.
fn triangles(bytes: &[u8]) -> Vec<Triangle> {
    bytes.chunks_exact(VERTICES).map(triangle_of).collect()
}

/// Bytes `[start, start + bytes.len())` of the file.
struct Window {
    start: u64,
    bytes: Vec<u8>,
}

impl Window {
    fn end(&self) -> u64 {
        self.start + self.bytes.len() as u64
    }

    /// Extends the window to `to` (nothing if it reaches there already).
    /// Collective: every rank calls it, each with its own `to`.
    fn extend(&mut self, file: &SharedFile, to: u64) -> bool {
        let at = self.end();
        let more = to.saturating_sub(at) as usize;
        let old = self.bytes.len();
        self.bytes.resize(old + more, 0);
        file.read_at_all(at, &mut self.bytes[old..]).is_ok()
    }
}

fn read_ascii(comm: &dyn Comm, file: &SharedFile, size: u64) -> Option<Result<Surface>> {
    let r = comm.rank();
    let (lo, hi) = share(size, r, comm.size());
    // The byte before the range tells whether the range starts a line.
    let mut win = Window {
        start: lo.saturating_sub(1),
        bytes: Vec::new(),
    };
    let mut ok = win.extend(file, (hi + MARGIN).min(size));
    // Rank 0 starts at the top; the others at their first facet or solid
    // boundary, reading further until they find it or the file ends.
    let cut = loop {
        let cut = if r == 0 {
            Some(0)
        } else {
            find_cut(&win, lo, size)
        };
        let need = ok && cut.is_none();
        let mut v = [u64::from(!ok), u64::from(need)];
        comm.max_u64(&mut v);
        if v[0] != 0 {
            return None;
        }
        if v[1] == 0 {
            break cut.unwrap_or(size);
        }
        let to = if need {
            (win.end() + MARGIN.max(win.end() - win.start)).min(size)
        } else {
            0
        };
        ok = win.extend(file, to);
    };
    let cuts = comm.allgather_u64(cut);
    let next = cuts.get(r + 1).copied().unwrap_or(size);
    // The last facet may run past the window: one more read for all.
    ok = win.extend(file, next);
    let parsed = if ok {
        let from = (cut - win.start) as usize;
        let to = (next - win.start) as usize;
        parse_segment(&win.bytes[from..to], r == 0)
    } else {
        None
    };
    drop(win);
    if !all_ok(comm, parsed.is_some()) {
        return None;
    }
    let (all, lens) = comm.allgatherv_bytes(&parsed.map(|s| s.encode()).unwrap_or_default());
    assemble(&all, &lens)
}

/// The surface of the gathered segments (`lens` bytes from each rank),
/// `None` if they do not make a file read the same way whole.
fn assemble(all: &[u8], lens: &[usize]) -> Option<Result<Surface>> {
    let (coords, events) = decode_all(all, lens)?;
    let solids = solids_of(&events)?;
    Some(Surface::new(triangles(&coords)).and_then(|s| s.with_parts(parts_of(&solids))))
}

/// The tokens of one line, as `split_whitespace` of its text (invalid UTF-8
/// replaced, as the whole-file reading does).
fn line_text(line: &[u8]) -> Cow<'_, str> {
    String::from_utf8_lossy(line)
}

/// The lines of `bytes`, split at `\n` and `\r`, without the empty ones.
fn lines(bytes: &[u8]) -> impl Iterator<Item = &[u8]> {
    bytes
        .split(|&c| c == b'\n' || c == b'\r')
        .filter(|l| l.iter().any(|&c| !c.is_ascii_whitespace() && c != 0x0b))
}

/// Whether a line's first token opens a facet or a solid boundary.
fn is_cut_line(line: &[u8]) -> bool {
    let text = line_text(line);
    let key = text.split_whitespace().next().unwrap_or("");
    ["facet", "solid", "endsolid"]
        .iter()
        .any(|k| key.eq_ignore_ascii_case(k))
}

/// Where a rank whose range starts at `lo` starts: the first line starting
/// at or after `lo` whose first token is `facet`, `solid` or `endsolid`,
/// or `size` if there is none. `None` if the window ends first.
fn find_cut(win: &Window, lo: u64, size: u64) -> Option<u64> {
    let newline = |c: u8| c == b'\n' || c == b'\r';
    let b = &win.bytes;
    let mut pos = (lo - win.start) as usize;
    // Inside a line: go to the next one (none: the file's last line).
    if lo > 0 && !newline(b[pos - 1]) {
        match b[pos..].iter().position(|&c| newline(c)) {
            Some(k) => pos += k + 1,
            None if win.end() == size => return Some(size),
            None => return None,
        }
    }
    loop {
        if win.start + pos as u64 >= size {
            return Some(size);
        }
        let end = match b[pos..].iter().position(|&c| newline(c)) {
            Some(k) => pos + k,
            None if win.end() == size => b.len(),
            None => return None,
        };
        if is_cut_line(&b[pos..end]) {
            return Some(win.start + pos as u64);
        }
        pos = end + 1;
    }
}

/// What one rank's share of an ASCII file holds, in file order.
#[derive(Debug, Default, PartialEq)]
struct Segment {
    /// Nine `f32` (little-endian) per facet.
    coords: Vec<u8>,
    events: Vec<Event>,
}

#[derive(Clone, Debug, PartialEq)]
enum Event {
    /// A `solid` line (or the file's first line), with the solid's name.
    Solid(String),
    /// This many facets in a row.
    Facets(u64),
    /// An `endsolid` line.
    End,
}

/// Parses whole lines of ASCII STL, starting with the file's first line if
/// `first`. `None` for anything the whole-file reading would not read the
/// same way: a facet that is not exactly `facet [normal x y z]`, `outer
/// loop`, three `vertex x y z` of finite `f32`, `endloop`, `endfacet`; a
/// line outside a facet that is neither `solid` nor `endsolid`.
fn parse_segment(bytes: &[u8], first: bool) -> Option<Segment> {
    let bytes = if first {
        bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes)
    } else {
        bytes
    };
    let mut seg = Segment::default();
    let mut lines = lines(bytes).map(line_text);
    let name = |t: &str| t.split_whitespace().skip(1).collect::<Vec<_>>().join(" ");
    if first {
        // Whatever follows "solid" in the first line is the name.
        if let Some(l) = lines.next() {
            seg.events.push(Event::Solid(name(&l)));
        }
    }
    while let Some(l) = lines.next() {
        let mut t = l.split_whitespace();
        let key = t.next().unwrap_or("");
        if key.eq_ignore_ascii_case("facet") {
            let rest: Vec<&str> = t.collect();
            let plain =
                rest.is_empty() || (rest.len() == 4 && rest[0].eq_ignore_ascii_case("normal"));
            if !plain {
                return None;
            }
            facet(&mut lines, &mut seg.coords)?;
            match seg.events.last_mut() {
                Some(Event::Facets(n)) => *n += 1,
                _ => seg.events.push(Event::Facets(1)),
            }
        } else if key.eq_ignore_ascii_case("solid") {
            seg.events.push(Event::Solid(name(&l)));
        } else if key.eq_ignore_ascii_case("endsolid") {
            seg.events.push(Event::End);
        } else {
            return None;
        }
    }
    Some(seg)
}

/// Whether `line` is exactly `words` (any case).
fn is_line(line: Option<Cow<'_, str>>, words: &[&str]) -> Option<()> {
    let line = line?;
    let mut t = line.split_whitespace();
    for w in words {
        if !t.next()?.eq_ignore_ascii_case(w) {
            return None;
        }
    }
    t.next().is_none().then_some(())
}

/// The lines of one facet after its `facet` line; appends its vertices.
fn facet<'a>(lines: &mut impl Iterator<Item = Cow<'a, str>>, out: &mut Vec<u8>) -> Option<()> {
    is_line(lines.next(), &["outer", "loop"])?;
    for _ in 0..3 {
        let l = lines.next()?;
        let mut t = l.split_whitespace();
        if !t.next()?.eq_ignore_ascii_case("vertex") {
            return None;
        }
        for _ in 0..3 {
            let x: f32 = t.next()?.parse().ok()?;
            if !x.is_finite() {
                return None;
            }
            out.extend_from_slice(&x.to_le_bytes());
        }
        if t.next().is_some() {
            return None;
        }
    }
    is_line(lines.next(), &["endloop"])?;
    is_line(lines.next(), &["endfacet"])
}

impl Segment {
    /// `[facets u64][coords][events]`, each event a tag byte then a `u64`
    /// count or a `u64` length and the name's bytes.
    fn encode(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(8 + self.coords.len() + 16 * self.events.len());
        out.extend_from_slice(&((self.coords.len() / VERTICES) as u64).to_le_bytes());
        out.extend_from_slice(&self.coords);
        for e in &self.events {
            match e {
                Event::Solid(name) => {
                    out.push(0);
                    out.extend_from_slice(&(name.len() as u64).to_le_bytes());
                    out.extend_from_slice(name.as_bytes());
                }
                Event::Facets(n) => {
                    out.push(1);
                    out.extend_from_slice(&n.to_le_bytes());
                }
                Event::End => out.push(2),
            }
        }
        out
    }
}

/// Splits the gathered segments (`lens` bytes from each rank, in rank
/// order) back into the coordinates and the events, in file order.
fn decode_all(bytes: &[u8], lens: &[usize]) -> Option<(Vec<u8>, Vec<Event>)> {
    let mut coords = Vec::new();
    let mut events = Vec::new();
    let mut rest = bytes;
    for &len in lens {
        let (mut seg, after) = (rest.get(..len)?, &rest[len..]);
        rest = after;
        let mut take = |n: usize| -> Option<&[u8]> {
            let (a, b) = (seg.get(..n)?, &seg[n..]);
            seg = b;
            Some(a)
        };
        let word = |b: &[u8]| u64::from_le_bytes(b.try_into().expect("8 bytes"));
        let n = word(take(8)?) as usize;
        coords.extend_from_slice(take(n.checked_mul(VERTICES)?)?);
        while let Some(tag) = take(1) {
            match tag[0] {
                0 => {
                    let len = word(take(8)?) as usize;
                    events.push(Event::Solid(String::from_utf8(take(len)?.to_vec()).ok()?));
                }
                1 => events.push(Event::Facets(word(take(8)?))),
                2 => events.push(Event::End),
                _ => return None,
            }
        }
    }
    Some((coords, events))
}

/// The solids `(name, facets)` in file order, as the whole-file reading
/// finds them: the first line names the first solid; an `endsolid`
/// directly followed by a `solid` line starts the next one; the file ends
/// with the last `endsolid`. `None` for any other order.
fn solids_of(events: &[Event]) -> Option<Vec<(String, usize)>> {
    let mut solids: Vec<(String, usize)> = Vec::new();
    let mut open = false;
    for e in events {
        match (e, open) {
            (Event::Solid(name), false) => {
                solids.push((name.clone(), 0));
                open = true;
            }
            (Event::Facets(n), true) => solids.last_mut()?.1 += *n as usize,
            (Event::End, true) => open = false,
            _ => return None,
        }
    }
    (!open && !solids.is_empty()).then_some(solids)
}

#[cfg(test)]
mod tests {
    use super::super::read_stl_bytes;
    use super::*;
    use crate::geometry::shapes::sphere;

    /// The split read of `bytes` by `p` ranks, done in one process.
    fn split(bytes: &[u8], p: usize) -> Option<Result<Surface>> {
        let size = bytes.len() as u64;
        let win = Window {
            start: 0,
            bytes: bytes.to_vec(),
        };
        let cuts: Vec<u64> = (0..p)
            .map(|r| {
                if r == 0 {
                    0
                } else {
                    find_cut(&win, share(size, r, p).0, size).expect("the whole file")
                }
            })
            .collect();
        let mut all = Vec::new();
        let mut lens = Vec::new();
        let mut failed = false;
        for r in 0..p {
            let next = cuts.get(r + 1).copied().unwrap_or(size);
            let seg = parse_segment(&bytes[cuts[r] as usize..next as usize], r == 0);
            failed |= seg.is_none();
            let b = seg.map(|s| s.encode()).unwrap_or_default();
            lens.push(b.len());
            all.extend_from_slice(&b);
        }
        if failed {
            return None;
        }
        assemble(&all, &lens)
    }

    fn solid(name: &str, tris: &[Triangle], style: usize) -> String {
        let mut s = format!("solid {name}\n");
        for t in tris {
            s.push_str(match style {
                0 => "  facet normal 0 0 1\n    outer loop\n",
                1 => "FACET NORMAL 1e0 0 0\r\n OUTER LOOP\r\n",
                _ => "facet\n\n\touter   loop\n",
            });
            for p in &t.v {
                s.push_str(&format!("      vertex {:e} {} {}\n", p[0], p[1], p[2]));
            }
            s.push_str(if style == 1 {
                "ENDLOOP\r\nENDFACET\r\n"
            } else {
                "    endloop\n  endfacet\n"
            });
        }
        s.push_str(&format!("endsolid {name}\n"));
        s
    }

    /// A file of several solids: two of the same name, one empty, a name
    /// with spaces, CR LF and upper-case keywords in one.
    fn multi() -> String {
        let t = sphere([0.0; 3], 1.0, 2).triangles().to_vec();
        let mut s = String::from("\u{feff}  \n");
        s.push_str(&solid("lid part", &t[..40], 0));
        s.push_str(&solid("wall", &t[40..100], 1));
        s.push_str(&solid("empty", &[], 0));
        s.push_str(&solid("lid part", &t[100..], 2));
        s
    }

    #[test]
    fn every_split_of_ascii_reads_as_the_whole_file() {
        let text = multi();
        let whole = read_stl_bytes(text.as_bytes()).unwrap();
        assert_eq!(whole.parts().names.len(), 3);
        for p in 1..=9 {
            let s = split(text.as_bytes(), p)
                .unwrap_or_else(|| panic!("{p} ranks: not split"))
                .unwrap();
            assert_eq!(s.triangles(), whole.triangles(), "{p} ranks");
            assert_eq!(s.parts(), whole.parts(), "{p} ranks");
        }
        // More ranks than lines: most of them have nothing; and no line
        // break at the end.
        let one = solid("x", &sphere([0.0; 3], 1.0, 0).triangles()[..2], 0);
        let one = one.trim_end();
        let whole = read_stl_bytes(one.as_bytes()).unwrap();
        for p in [30, 200, 2 * one.len()] {
            let s = split(one.as_bytes(), p).unwrap().unwrap();
            assert_eq!(s.triangles(), whole.triangles(), "{p} ranks");
        }
    }

    #[test]
    fn a_split_never_reads_what_the_whole_file_reading_rejects() {
        let text = multi();
        let facet = text.find("facet normal").unwrap();
        let bad = [
            text[..text.len() - 200].to_string(),
            text.replacen("outer loop", "outer lop", 1),
            text.replacen("endloop", "endloop x", 3),
            text.replacen("vertex 0", "vertex 0 0", 1),
            text.replacen("      vertex", "      vertex nan 0 0\n      vertex", 1),
            format!("{}endfacet\n{}", &text[..facet], &text[facet..]),
            text.replace("endsolid", "end"),
        ];
        for (k, b) in bad.iter().enumerate() {
            assert!(read_stl_bytes(b.as_bytes()).is_err(), "case {k}");
            for p in 1..=9 {
                assert!(split(b.as_bytes(), p).is_none(), "case {k} on {p} ranks");
            }
        }
        // Text after the last solid: read whole, where it is ignored.
        let trailing = format!("{text}junk\n");
        assert!(read_stl_bytes(trailing.as_bytes()).is_ok());
        assert!(split(trailing.as_bytes(), 3).is_none());
    }

    #[test]
    fn binary_records_decode_as_the_whole_file() {
        let s = sphere([0.5, 0.0, -1.0], 2.0, 1);
        let bytes = super::super::encode_binary(s.triangles(), b"x");
        let coords: Vec<u8> = bytes[PREAMBLE..]
            .chunks_exact(RECORD)
            .flat_map(|r| r[12..12 + VERTICES].to_vec())
            .collect();
        let whole = read_stl_bytes(&bytes).unwrap();
        assert_eq!(triangles(&coords), whole.triangles());
    }

    #[test]
    fn shares_cover_the_range() {
        for p in 1..=7 {
            let mut at = 0;
            for r in 0..p {
                let (lo, hi) = share(100, r, p);
                assert_eq!(lo, at);
                at = hi;
            }
            assert_eq!(at, 100);
        }
    }
}
