//! A leak's path for inspection: legacy VTK lines (ParaView, meshio) or a
//! CSV table, from the octants of [`crate::leak::LeakPath`].

use std::io::Write;
use std::path::Path;

use crate::error::{Error, Result};
use crate::leak::LeakPath;
use crate::octree::domain::Domain;
use crate::octree::octant::Octant;

impl LeakPath {
    /// Writes the path for ParaView: for `.vtk`, a legacy VTK unstructured
    /// grid holding the polyline through the centres as one line cell per
    /// step, with point data `size`, `level` and `step`; for any other
    /// extension a CSV table `step,x,y,z,size,level`. User units. Not
    /// collective.
    pub fn write(&self, path: &Path, domain: &Domain) -> Result<()> {
        write_leak_path(
            path,
            &self.centres(domain),
            &self.sizes(domain),
            &self.octants,
        )
    }
}

/// Writes a path of octants: `c` their centres and `s` their sizes (user
/// units). With the extension `.vtk` a legacy VTK polyline with point data
/// size, level and step; otherwise a CSV table `step,x,y,z,size,level`.
/// Not collective.
pub fn write_leak_path(path: &Path, c: &[[f64; 3]], s: &[f64], octants: &[Octant]) -> Result<()> {
    let vtk = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("vtk"));
    let n = octants.len();
    let mut out = String::new();
    use std::fmt::Write as _;
    if vtk {
        let _ = writeln!(out, "# vtk DataFile Version 3.0");
        let _ = writeln!(
            out,
            "octmesh leak path: {n} octants from the domain boundary to the inside point"
        );
        let _ = writeln!(out, "ASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS {n} double");
        for p in c {
            let _ = writeln!(out, "{:e} {:e} {:e}", p[0], p[1], p[2]);
        }
        // One line cell per step (a lone vertex for a path of one
        // octant): what both ParaView and meshio read.
        let cells = n.saturating_sub(1).max(1);
        if n == 1 {
            let _ = write!(out, "CELLS 1 2\n1 0\nCELL_TYPES 1\n1");
        } else {
            let _ = writeln!(out, "CELLS {cells} {}", 3 * cells);
            for i in 1..n {
                let _ = writeln!(out, "2 {} {i}", i - 1);
            }
            let _ = write!(out, "CELL_TYPES {cells}");
            for _ in 1..n {
                let _ = write!(out, "\n3");
            }
        }
        let _ = writeln!(out, "\nPOINT_DATA {n}");
        let _ = writeln!(out, "SCALARS size double 1\nLOOKUP_TABLE default");
        for v in s {
            let _ = writeln!(out, "{v:e}");
        }
        let _ = writeln!(out, "SCALARS level int 1\nLOOKUP_TABLE default");
        for o in octants {
            let _ = writeln!(out, "{}", o.level());
        }
        let _ = writeln!(out, "SCALARS step int 1\nLOOKUP_TABLE default");
        for i in 0..n {
            let _ = writeln!(out, "{i}");
        }
    } else {
        let _ = writeln!(out, "step,x,y,z,size,level");
        for i in 0..n {
            let _ = writeln!(
                out,
                "{i},{:e},{:e},{:e},{:e},{}",
                c[i][0],
                c[i][1],
                c[i][2],
                s[i],
                octants[i].level()
            );
        }
    }
    std::fs::File::create(path)
        .and_then(|mut f| f.write_all(out.as_bytes()))
        .map_err(|e| Error::io(format!("cannot write '{}': {e}", path.display())))
}
