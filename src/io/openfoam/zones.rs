//! The zone files of a mesh with zones ([`crate::mesh::zones`]):
//! `cellZones`, one cellZone per zone, and `faceZones`, one faceZone per
//! interface between two zones, named `<first>_<second>` (zone order),
//! whose flipMap orients every face from the first zone to the second.
//! Both are ASCII whatever the format of the other files (they hold a
//! label per cell at most). Every rank writes every zone and interface,
//! empty where it has none of it, as OpenFOAM wants the same zones in
//! every processor directory; a face between two ranks is in the faceZone
//! on both sides, each rank's flip seen from its own cell.

use super::*;
use crate::mesh::zones::{interfaces, Zones};

/// Zone pairs `(a, b)`, `a < b`, of each internal and halo face of `faces`
/// whose sides lie in different zones.
fn face_pairs<'a>(
    zones: &'a Zones,
    faces: &'a Faces,
) -> impl Iterator<Item = (usize, (u16, u16))> + 'a {
    let (own, halo) = (zones.of_elements(), zones.of_halo());
    faces.faces().iter().enumerate().filter_map(move |(k, f)| {
        let z = own[f.owner() as usize];
        let other = match f.other() {
            Other::Element(j) => own[j as usize],
            Other::Halo(h) => halo[h as usize],
            Other::Patch(_) => return None,
        };
        (z != other).then_some((k, (z, other)))
    })
}

/// The interfaces between the zones over all ranks (collective).
pub(super) fn zone_interfaces(comm: &dyn Comm, mesh: &Mesh, faces: &Faces) -> Vec<(u16, u16)> {
    match mesh.zones() {
        Some(z) => interfaces(
            comm,
            z.names().len(),
            face_pairs(z, faces).map(|(_, (a, b))| (a.min(b), a.max(b))),
        ),
        None => Vec::new(),
    }
}

/// Writes `cellZones` and `faceZones` in `dir` for the `interfaces` of
/// [`zone_interfaces`].
pub(super) fn write_zones(
    dir: &Path,
    loc: &str,
    faces: &Faces,
    zones: &Zones,
    interfaces: &[(u16, u16)],
) -> std::io::Result<()> {
    let fmt = FoamFormat::Ascii;
    let names = zones.names();
    let mut cells: Vec<Vec<u32>> = vec![Vec::new(); names.len()];
    for (i, &z) in zones.of_elements().iter().enumerate() {
        cells[z as usize].push(i as u32);
    }
    let mut w = create(&dir.join("cellZones")).map_err(std::io::Error::other)?;
    header(&mut w, fmt, "regIOobject", loc, "cellZones", None)?;
    writeln!(w, "{}\n(", names.len())?;
    for (name, list) in names.iter().zip(&cells) {
        writeln!(w, "{name}\n{{\n    type            cellZone;")?;
        write!(w, "cellLabels      List<label> ")?;
        write_label_iter(&mut w, fmt, list.len(), list.iter().copied())?;
        writeln!(w, ";\n}}")?;
    }
    writeln!(w, ")")?;
    w.flush()?;
    drop(cells);

    // Each interface's faces in face order, with their flips.
    let mut lists: Vec<(Vec<u32>, Vec<u32>)> = vec![(Vec::new(), Vec::new()); interfaces.len()];
    for (k, (z, other)) in face_pairs(zones, faces) {
        let pair = (z.min(other), z.max(other));
        if let Ok(i) = interfaces.binary_search(&pair) {
            lists[i].0.push(k as u32);
            // The face's normal points from its owner (zone `z`).
            lists[i].1.push(u32::from(z != pair.0));
        }
    }
    let mut w = create(&dir.join("faceZones")).map_err(std::io::Error::other)?;
    header(&mut w, fmt, "regIOobject", loc, "faceZones", None)?;
    writeln!(w, "{}\n(", interfaces.len())?;
    for (&(a, b), (labels, flips)) in interfaces.iter().zip(&lists) {
        let (a, b) = (&names[a as usize], &names[b as usize]);
        writeln!(w, "{a}_{b}\n{{\n    type            faceZone;")?;
        write!(w, "faceLabels      List<label> ")?;
        write_label_iter(&mut w, fmt, labels.len(), labels.iter().copied())?;
        writeln!(w, ";")?;
        write!(w, "flipMap         List<bool> ")?;
        write_label_iter(&mut w, fmt, flips.len(), flips.iter().copied())?;
        writeln!(w, ";\n}}")?;
    }
    writeln!(w, ")")?;
    w.flush()
}
