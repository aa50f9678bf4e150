//! The polyMesh files: their headers, the points (in ASCII or binary), the
//! faces as a compact list, and the label lists.

use super::*;

pub(super) fn header(
    out: &mut impl Write,
    format: FoamFormat,
    class: &str,
    location: &str,
    object: &str,
    note: Option<&str>,
) -> std::io::Result<()> {
    writeln!(
        out,
        "/*--------------------------------*- C++ -*----------------------------------*\\"
    )?;
    writeln!(out, "  written by octmesh {}", env!("CARGO_PKG_VERSION"))?;
    writeln!(
        out,
        "\\*---------------------------------------------------------------------------*/"
    )?;
    writeln!(out, "FoamFile\n{{")?;
    writeln!(out, "    version     2.0;")?;
    writeln!(out, "    format      {};", format.name())?;
    writeln!(out, "    arch        \"LSB;label=32;scalar=64\";")?;
    writeln!(out, "    class       {class};")?;
    if let Some(n) = note {
        writeln!(out, "    note        \"{n}\";")?;
    }
    writeln!(out, "    location    \"{location}\";")?;
    writeln!(out, "    object      {object};")?;
    writeln!(out, "}}\n")
}

/// Writes the `n` labels of `v` as a labelList body.
pub(super) fn write_label_iter(
    out: &mut impl Write,
    format: FoamFormat,
    n: usize,
    v: impl Iterator<Item = u32>,
) -> std::io::Result<()> {
    write!(out, "{n}\n(")?;
    match format {
        FoamFormat::Binary => {
            // Through one small buffer, reused: no copy of the whole list
            // (tens of megabytes, all of it fresh pages to fault in).
            const CHUNK: usize = 1 << 16;
            let mut buf = Vec::with_capacity(CHUNK);
            for x in v {
                buf.push(x);
                if buf.len() == CHUNK {
                    write_raw(out, &buf)?;
                    buf.clear();
                }
            }
            write_raw(out, &buf)?;
            writeln!(out, ")")
        }
        FoamFormat::Ascii => {
            writeln!(out)?;
            for x in v {
                writeln!(out, "{x}")?;
            }
            writeln!(out, ")")
        }
    }
}

/// Numbers written to binary lists as their raw little-endian bytes:
/// 32-bit labels (below 2^31 they have the bits of OpenFOAM's signed ones)
/// and points of three 64-bit scalars. Both are plain numbers without
/// padding.
pub(super) trait Raw: Copy {
    /// Appends the little-endian bytes (for big-endian machines).
    fn put_le(&self, out: &mut Vec<u8>);
}

impl Raw for u32 {
    fn put_le(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
}

impl Raw for [f64; 3] {
    fn put_le(&self, out: &mut Vec<u8>) {
        self.iter()
            .for_each(|x| out.extend_from_slice(&x.to_le_bytes()));
    }
}

/// Writes `v` as raw little-endian bytes.
pub(super) fn write_raw<T: Raw>(out: &mut impl Write, v: &[T]) -> std::io::Result<()> {
    if cfg!(target_endian = "little") {
        // SAFETY: `T` is `u32` or `[f64; 3]` (no padding, every bit
        // pattern a value) and any alignment suits `u8`; the bytes are
        // those of `v`, which outlives the borrow.
        let bytes = unsafe {
            std::slice::from_raw_parts(v.as_ptr().cast::<u8>(), std::mem::size_of_val(v))
        };
        out.write_all(bytes)
    } else {
        let mut buf = Vec::with_capacity(std::mem::size_of_val(v));
        v.iter().for_each(|x| x.put_le(&mut buf));
        out.write_all(&buf)
    }
}

/// The local nodes' positions, written to [`PointsOut`] in label order in
/// short steps: on a mesh that is not snapped, the nodes' lattice points
/// are gathered from the elements' corners first.
pub(super) struct NodeFill<'m> {
    pub(super) nodes: &'m NodeLabels,
    /// By node; empty on a snapped mesh.
    pub(super) lattice: Vec<[u32; 3]>,
    /// Elements whose corners are in `lattice`.
    pub(super) gathered: usize,
    /// Labels written, and the entries of `nodes.moved` passed.
    pub(super) written: u32,
    pub(super) moved_at: usize,
}

impl<'m> NodeFill<'m> {
    /// Elements, or labels, per step.
    const STEP: usize = 1 << 15;

    pub(super) fn new(mesh: &'m Mesh, nodes: &'m NodeLabels) -> Self {
        let lattice = match mesh.moved() {
            Some(_) => Vec::new(),
            None => vec![[0; 3]; mesh.num_nodes()],
        };
        NodeFill {
            nodes,
            lattice,
            gathered: 0,
            written: 0,
            moved_at: 0,
        }
    }

    /// One step into `out`; whether there are more.
    pub(super) fn step(&mut self, out: &mut PointsOut) -> Result<bool> {
        let (mesh, snapped) = (out.mesh, out.mesh.moved());
        let ne = mesh.elements().len();
        if snapped.is_none() && self.gathered < ne {
            let r = self.gathered..ne.min(self.gathered + Self::STEP);
            self.gathered = r.end;
            let lattice = &mut self.lattice;
            mesh.for_each_corner_in(r, |n, x| lattice[n as usize] = x);
            return Ok(true);
        }
        let direct = self.nodes.direct;
        let end = direct.min(self.written + Self::STEP as u32);
        let domain = out.mesh.domain();
        for l in self.written..end {
            let n = self.nodes.node(l, &mut self.moved_at) as usize;
            out.put(match snapped {
                Some(m) => m[n],
                None => domain.from_lattice(self.lattice[n].map(f64::from)),
            })?;
        }
        self.written = end;
        if end == direct {
            self.lattice = Vec::new();
        }
        Ok(end < direct)
    }
}

/// The `points` file in label order ([`NodeLabels`]): the local nodes, then
/// the halo points the faces used (user units: the moved positions on a
/// snapped mesh, the lattice's otherwise). In binary the positions stream
/// to the file and the count goes last over room left for it, as in
/// `faces`: no array of every position is made. ASCII cases (small ones)
/// keep the positions and write them at the end.
pub(super) struct PointsOut<'m> {
    pub(super) mesh: &'m Mesh,
    pub(super) fmt: FoamFormat,
    pub(super) path: PathBuf,
    /// Binary: the file's writer, from the first position on.
    pub(super) w: Option<DirectWriter>,
    /// Where the first position goes (binary).
    pub(super) data_at: u64,
    /// Binary: the positions not yet handed to `w`; ASCII: all of them.
    pub(super) block: Vec<[f64; 3]>,
    /// On a snapped mesh, the halo points with their labels: their
    /// positions are the means of moved corners, found in one pass at the
    /// end (NaN until then).
    pub(super) off_node: Vec<([u32; 3], u32)>,
    pub(super) count: u32,
}

impl<'m> PointsOut<'m> {
    pub(super) fn new(path: &Path, fmt: FoamFormat, loc: &str, mesh: &'m Mesh) -> Result<Self> {
        let head = points_head(fmt, loc, 0).map_err(|e| io_err(path, e))?;
        let w = match fmt {
            FoamFormat::Binary => {
                let mut w = create(path)?;
                w.restart_at(head.len() as u64)
                    .map_err(|e| io_err(path, e))?;
                Some(w)
            }
            FoamFormat::Ascii => None,
        };
        Ok(PointsOut {
            mesh,
            fmt,
            path: path.to_path_buf(),
            w,
            data_at: head.len() as u64,
            block: Vec::with_capacity(1 << 14),
            off_node: Vec::new(),
            count: 0,
        })
    }

    /// The halo points at lattice points `xs`, in label order, after the
    /// nodes.
    pub(super) fn halo(&mut self, xs: &[[u32; 3]]) -> Result<()> {
        xs.iter().try_for_each(|&x| {
            let p = match self.mesh.moved() {
                Some(_) => {
                    self.off_node.push((x, self.count));
                    [f64::NAN; 3]
                }
                None => self.mesh.domain().from_lattice(x.map(f64::from)),
            };
            self.put(p)
        })
    }

    /// The next position.
    pub(super) fn put(&mut self, p: [f64; 3]) -> Result<()> {
        self.count += 1;
        self.block.push(p);
        if let Some(w) = &mut self.w {
            if self.block.len() == self.block.capacity() {
                write_raw(w, &self.block).map_err(|e| io_err(&self.path, e))?;
                self.block.clear();
            }
        }
        Ok(())
    }

    /// Writes what is left, the off-node positions, the end and the
    /// header.
    pub(super) fn finish(mut self, loc: &str) -> Result<u32> {
        let path = self.path.clone();
        let io = |e: std::io::Error| io_err(&path, e);
        let q: Vec<[u32; 3]> = self.off_node.iter().map(|o| o.0).collect();
        let off = if q.is_empty() {
            Vec::new()
        } else {
            self.mesh.off_node_positions(&q)?
        };
        let head = points_head(self.fmt, loc, self.count).map_err(io)?;
        match self.w.take() {
            Some(mut w) => {
                write_raw(&mut w, &self.block).map_err(io)?;
                w.write_all(b")\n").map_err(io)?;
                for (&(_, l), p) in self.off_node.iter().zip(&off) {
                    w.restart_at(self.data_at + 24 * l as u64).map_err(io)?;
                    write_raw(&mut w, std::slice::from_ref(p)).map_err(io)?;
                }
                w.restart_at(0).map_err(io)?;
                w.write_all(&head).map_err(io)?;
                w.flush().map_err(io)?;
            }
            None => {
                for (&(_, l), p) in self.off_node.iter().zip(&off) {
                    self.block[l as usize] = *p;
                }
                let mut w = create(&path)?;
                w.write_all(&head).map_err(io)?;
                for x in &self.block {
                    writeln!(w, "({:.17e} {:.17e} {:.17e})", x[0], x[1], x[2]).map_err(io)?;
                }
                w.write_all(b")\n").map_err(io)?;
                w.flush().map_err(io)?;
            }
        }
        Ok(self.count)
    }
}

/// The `points` file up to its first position: in binary the count padded
/// to [`COUNT_WIDTH`] (so it can be written last), in ASCII as is.
pub(super) fn points_head(fmt: FoamFormat, loc: &str, count: u32) -> std::io::Result<Vec<u8>> {
    let mut head = Vec::new();
    header(&mut head, fmt, "vectorField", loc, "points", None)?;
    match fmt {
        FoamFormat::Binary => write!(head, "{count:<COUNT_WIDTH$}\n(")?,
        FoamFormat::Ascii => write!(head, "{count}\n(\n")?,
    }
    Ok(head)
}

/// Width of a count written after its list in binary (the labels of
/// `faces`, the positions of `points`): the list is streamed before its
/// length is known, and the count written over room left for it
/// (OpenFOAM skips the trailing blanks).
pub(super) const COUNT_WIDTH: usize = 20;

/// Writes the `faces` file of this rank, the face polygons streamed from
/// [`face_polygons`] (which runs the steps of `side` on the way); returns
/// the halo points they used, in label order.
pub(super) fn write_faces(
    path: &Path,
    (fmt, loc): (FoamFormat, &str),
    mesh: (&Mesh, &Faces),
    nodes: &NodeLabels,
    spare_core: bool,
    side: impl FnMut() -> Result<bool>,
) -> Result<Vec<[u32; 3]>> {
    let io = |e: std::io::Error| io_err(path, e);
    let nf = mesh.1.faces().len();
    match fmt {
        FoamFormat::Binary => {
            // A faceCompactList: the offsets, then the labels. Both go to
            // the file as they come, each through its own writer at its
            // own place; the header, the end of the offsets and the label
            // count are written last.
            let mut head = Vec::new();
            header(&mut head, fmt, "faceCompactList", loc, "faces", None).map_err(io)?;
            write!(head, "{}\n(", nf + 1).map_err(io)?;
            // Between the two lists: the end of the offsets, then the
            // label count (written last, over the same room).
            let between = |count: u32| format!(")\n\n{count:<COUNT_WIDTH$}\n(");
            let offsets_end = head.len() + 4 * (nf + 1);
            let data_at = offsets_end + between(0).len();
            let mut w = DirectWriter::create(path).map_err(io)?;
            w.restart_at(data_at as u64).map_err(io)?;
            let mut wo = DirectWriter::open(path).map_err(io)?;
            wo.restart_at(head.len() as u64).map_err(io)?;
            let mut offsets = Vec::with_capacity(POLYGON_CHUNK + 1);
            offsets.push(0u32);
            let mut total = 0u32;
            let halo = face_polygons(mesh, nodes, spare_core, side, |c| {
                offsets.extend(c.lens.iter().map(|&n| {
                    total += n as u32;
                    total
                }));
                write_raw(&mut wo, &offsets).map_err(io)?;
                offsets.clear();
                write_raw(&mut w, &c.ids).map_err(io)
            })?;
            write_raw(&mut wo, &offsets).map_err(io)?;
            w.write_all(b")\n").map_err(io)?;
            w.flush().map_err(io)?;
            drop(w);
            wo.write_all(between(total).as_bytes()).map_err(io)?;
            wo.restart_at(0).map_err(io)?;
            wo.write_all(&head).map_err(io)?;
            wo.flush().map_err(io)?;
            Ok(halo)
        }
        FoamFormat::Ascii => {
            let mut w = create(path)?;
            header(&mut w, fmt, "faceList", loc, "faces", None).map_err(io)?;
            writeln!(w, "{nf}\n(").map_err(io)?;
            let halo = face_polygons(mesh, nodes, spare_core, side, |c| {
                let mut at = 0;
                c.lens
                    .iter()
                    .try_for_each(|&n| -> std::io::Result<()> {
                        let l = &c.ids[at..at + n as usize];
                        at += n as usize;
                        write!(w, "{}(", l.len())?;
                        for (k, x) in l.iter().enumerate() {
                            if k > 0 {
                                write!(w, " ")?;
                            }
                            write!(w, "{x}")?;
                        }
                        writeln!(w, ")")
                    })
                    .map_err(io)
            })?;
            writeln!(w, ")").map_err(io)?;
            w.flush().map_err(io)?;
            Ok(halo)
        }
    }
}
