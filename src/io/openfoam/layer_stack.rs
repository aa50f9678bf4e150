//! Boundary layers: N thin cells on every wall face, in the room the wall
//! layer makes between the staircase and the surface.
//!
//! `layer_points::place` gives each wall point its staircase position
//! (`inner`) and its surface point (`outer`). Here the way between them is
//! cut into a buffer cell next to the staircase and N layers next to the
//! surface: heights `h_1, h_1 R, h_1 R^2, ...` from the surface outwards,
//! along the unit vector from the surface point to the inner point (the
//! layer points stay on the segment, so a column's cells keep the shape
//! of the wall layer's cell). Where the stack would take more than
//! [`FILL`] of a point's gap, the point's stack is scaled down to that
//! (thinned, not dropped) and its faces count as not covered.
//!
//! Each wall point takes the setting of the lowest-numbered patch with
//! layers among its faces; its local cell (for relative sizes) is its
//! finest face. Both are merged over the ranks (least over the ranks that
//! have the point), and every other input (the two positions) is already
//! the same on every rank, so the layer points are the same bits on any
//! number of ranks. Every face gets as many cells as the most layers any
//! patch asks for (plus the buffer), so the columns meet across every
//! edge; a point with fewer layers splits its buffer evenly into the rest.

use serde::Serialize;

use super::layer::{PolyMesh, Wall};
use super::layer_points::{exchange, home};
use super::*;
use crate::geometry::vector::{add, add_scaled, dot, norm, scale, sub};

/// The most of a point's gap (staircase to surface) its layers may take.
pub const FILL: f64 = 0.6;

/// How a layer setting gives its thickness.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LayerThickness {
    /// The first layer's height (next to the wall).
    First(f64),
    /// The last layer's height (the N-th from the wall).
    Final(f64),
    /// All N layers together.
    Total(f64),
}

/// The layers of one patch.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct LayerSpec {
    /// Layers, 1 or more.
    pub layers: u32,
    /// Each layer's height over the one before it (> 0).
    pub expansion: f64,
    /// The thickness.
    pub thickness: LayerThickness,
    /// The thickness is a fraction of the local wall cell's side.
    pub relative: bool,
}

impl LayerSpec {
    /// The first layer's height for a wall cell of side `cell`.
    pub fn first_height(&self, cell: f64) -> f64 {
        let (n, r) = (self.layers as i32, self.expansion);
        let unit = if self.relative { cell } else { 1.0 };
        match self.thickness {
            LayerThickness::First(t) => t * unit,
            LayerThickness::Final(t) => t * unit / r.powi(n - 1),
            LayerThickness::Total(t) => {
                // The sum of R^k, k < N.
                let sum: f64 = (0..n).map(|k| r.powi(k)).sum();
                t * unit / sum
            }
        }
    }

    /// The N heights from the wall outwards for a wall cell of side `cell`.
    pub fn heights(&self, cell: f64) -> Vec<f64> {
        let h1 = self.first_height(cell);
        (0..self.layers as i32)
            .map(|k| h1 * self.expansion.powi(k))
            .collect()
    }
}

/// The layers asked for: a setting per wall patch (indices from
/// [`SURFACE_PATCH`]), `None` for a patch without layers.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LayerPlan {
    /// By wall patch.
    pub patches: Vec<Option<LayerSpec>>,
}

impl LayerPlan {
    /// The most layers of any patch.
    pub(super) fn most(&self) -> u32 {
        self.patches
            .iter()
            .flatten()
            .map(|s| s.layers)
            .max()
            .unwrap_or(0)
    }
}

/// What the layers of one wall patch came to, over all ranks.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct PatchLayerReport {
    /// The patch's name.
    pub patch: String,
    /// Layers asked for.
    pub layers: u32,
    /// The patch's wall faces.
    pub faces: u64,
    /// Faces with a point whose stack was thinned to fit its gap.
    pub thinned_faces: u64,
    /// The area fraction of the faces with all layers at full thickness.
    pub coverage: f64,
    /// The mean layers per face, area weighted (each face's least over its
    /// points; thinned layers count, as they are not dropped).
    pub mean_layers: f64,
    /// The first cell's height, area-weighted mean over the faces (each
    /// face's mean over its points).
    pub first_height_mean: f64,
    /// Its least over the faces.
    pub first_height_min: f64,
    /// Its largest over the faces.
    pub first_height_max: f64,
}

/// The layer report of a case: the wall patches with layers.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct LayerReport {
    /// By wall patch with layers, in patch order.
    pub patches: Vec<PatchLayerReport>,
    /// Seconds of the layer points and cells (maximum over ranks).
    pub seconds: f64,
}

/// What each wall point takes from all its faces, merged over the ranks
/// that have the point.
struct PointSettings {
    /// The patch whose setting it takes (`u64::MAX`: none).
    patch: Vec<u64>,
    /// Its finest face's side.
    side: Vec<f64>,
    /// The unit normal of its faces on the surface, into the mesh.
    normal: Vec<Option<[f64; 3]>>,
}

/// Fixed-point scale of the normals' sums: areas in units of the domain
/// side's square.
const FIXED: f64 = (1u64 << 60) as f64;

/// The wall points' settings: the least patch and side and the summed
/// area vectors (integers, so the sum does not depend on the order) over
/// the point's faces on all ranks (collective).
fn point_settings(
    comm: &dyn Comm,
    pm: &PolyMesh,
    wall: &Wall,
    (plan, outer, domain_side): (&LayerPlan, &[[f64; 3]], f64),
) -> PointSettings {
    let nw = wall.labels.len();
    // Patch, side bits, area sums x y z.
    let mut rows = vec![[u64::MAX, u64::MAX, 0, 0, 0]; nw];
    let mut q = SURFACE_PATCH as usize;
    for (k, &f) in wall.faces.iter().enumerate() {
        while !pm.patches[q].contains(&f) {
            q += 1;
        }
        let with = plan.patches[q - SURFACE_PATCH as usize].is_some();
        let poly = &wall.polys[k];
        let area = super::layer::polygon_area(poly.iter().map(|&i| outer[i as usize]));
        let fixed = area.map(|a| (a / (domain_side * domain_side) * FIXED).round() as i64);
        for &i in poly {
            let r = &mut rows[i as usize];
            if with {
                r[0] = r[0].min(q as u64);
            }
            // Positive numbers order as their bits do.
            r[1] = r[1].min(wall.sides[k].to_bits());
            for j in 0..3 {
                r[2 + j] = (r[2 + j] as i64).wrapping_add(fixed[j]) as u64;
            }
        }
    }
    merge(comm, &wall.keys, &mut rows, |e, c| {
        e[0] = e[0].min(c[0]);
        e[1] = e[1].min(c[1]);
        for j in 2..5 {
            e[j] = (e[j] as i64).wrapping_add(c[j] as i64) as u64;
        }
    });
    PointSettings {
        patch: rows.iter().map(|r| r[0]).collect(),
        side: rows.iter().map(|r| f64::from_bits(r[1])).collect(),
        // The faces point out of the mesh.
        normal: rows
            .iter()
            .map(|r| {
                let v = [r[2], r[3], r[4]].map(|x| -(x as i64 as f64));
                let l = norm(v);
                (l > 0.0).then(|| scale(v, 1.0 / l))
            })
            .collect(),
    }
}

/// Combines each wall point's row over the ranks that have the point
/// (`combine` must not depend on the order; collective): every rank ends
/// with the combined rows of its points.
fn merge<const W: usize>(
    comm: &dyn Comm,
    keys: &[u64],
    rows: &mut [[u64; W]],
    combine: impl Fn(&mut [u64; W], &[u64; W]),
) {
    let p = comm.size();
    // Alone, each point's row is its only one (the keys are distinct).
    if p == 1 {
        return;
    }
    let mut out = vec![Vec::new(); p];
    for (k, r) in keys.iter().zip(rows.iter()) {
        out[home(*k, p)].push(*k);
        out[home(*k, p)].extend(r);
    }
    let mut merged: std::collections::BTreeMap<u64, [u64; W]> = Default::default();
    let mut senders: Vec<Vec<u64>> = vec![Vec::new(); p];
    for (r, recs) in exchange(comm, out).iter().enumerate() {
        for c in recs.chunks_exact(W + 1) {
            let row: [u64; W] = c[1..].try_into().expect("W words");
            match merged.get_mut(&c[0]) {
                Some(e) => combine(e, &row),
                None => {
                    merged.insert(c[0], row);
                }
            }
            senders[r].push(c[0]);
        }
    }
    let reply: Vec<Vec<u64>> = senders
        .iter()
        .map(|ks| {
            ks.iter()
                .flat_map(|k| std::iter::once(*k).chain(merged[k]))
                .collect()
        })
        .collect();
    let back: std::collections::HashMap<u64, [u64; W]> = exchange(comm, reply)
        .iter()
        .flat_map(|r| {
            r.chunks_exact(W + 1)
                .map(|c| (c[0], c[1..].try_into().expect("W words")))
        })
        .collect();
    for (k, r) in keys.iter().zip(rows.iter_mut()) {
        if let Some(e) = back.get(k) {
            *r = *e;
        }
    }
}

/// One wall point's column: the distances from the surface point of its
/// `most` layer points, nearest the surface first, and whether the stack
/// was thinned.
fn column(spec: Option<&LayerSpec>, side: f64, gap: f64, most: u32) -> (Vec<f64>, bool) {
    let heights = spec.map_or_else(Vec::new, |s| s.heights(side));
    let total: f64 = heights.iter().sum();
    let thinned = total > FILL * gap;
    let f = if thinned { FILL * gap / total } else { 1.0 };
    let mut t = Vec::with_capacity(most as usize);
    let mut at = 0.0;
    for h in &heights {
        at += h * f;
        t.push(at);
    }
    // The buffer split evenly into the cells this point has no layers for.
    let n = heights.len() as u32;
    let rest = (most - n + 1) as f64;
    for j in 1..=most - n {
        t.push(at + (gap - at) * j as f64 / rest);
    }
    (t, thinned)
}

/// The way a wall point's layers grow from its surface point and the room
/// along it: the surface's normal (into the mesh) where it points well
/// into the gap towards the inner point (`toward`, `gap` away), else
/// the mean of the two, the room being the gap's length along that way.
fn direction(normal: Option<[f64; 3]>, toward: [f64; 3], gap: f64) -> ([f64; 3], f64) {
    let Some(n) = normal else {
        return (toward, gap);
    };
    let dir = if dot(n, toward) >= LEAN {
        n
    } else {
        let m = add(n, toward);
        let l = norm(m);
        if l > 1e-9 {
            scale(m, 1.0 / l)
        } else {
            toward
        }
    };
    (dir, gap * dot(dir, toward).max(0.0))
}

/// The least cosine between the surface's normal and the way to the
/// inner point for the layers to grow along the normal.
const LEAN: f64 = 0.5;

/// The point layers of the wall from the staircase (`inner`) to the
/// surface (`outer`): `most + 2` of them, by wall point number, and per
/// wall point its first layer's height and whether it was thinned
/// (collective).
struct Columns {
    /// The point layers, staircase first.
    layers: Vec<Vec<[f64; 3]>>,
    /// Each wall point's first layer height (0: no layers).
    first: Vec<f64>,
    /// Whether its stack was thinned or spread.
    thinned: Vec<bool>,
}

fn point_layers(
    comm: &dyn Comm,
    pm: &PolyMesh,
    wall: &Wall,
    (plan, domain_side): (&LayerPlan, f64),
    (inner, outer): (Vec<[f64; 3]>, Vec<[f64; 3]>),
) -> Columns {
    let PointSettings {
        patch,
        side,
        normal,
    } = point_settings(comm, pm, wall, (plan, &outer, domain_side));
    let most = plan.most();
    let nw = inner.len();
    let mut layers = vec![Vec::with_capacity(nw); most as usize];
    let (mut first, mut thinned) = (vec![0.0; nw], vec![false; nw]);
    for i in 0..nw {
        let d = sub(inner[i], outer[i]);
        let gap = norm(d);
        let toward = if gap > 0.0 {
            scale(d, 1.0 / gap)
        } else {
            [0.0; 3]
        };
        let (dir, gap) = direction(normal[i], toward, gap);
        let spec = (patch[i] != u64::MAX)
            .then(|| plan.patches[patch[i] as usize - SURFACE_PATCH as usize].as_ref())
            .flatten();
        let (t, thin) = column(spec, side[i], gap, most);
        first[i] = if spec.is_some() { t[0] } else { 0.0 };
        thinned[i] = thin;
        // Outwards from the staircase: the farthest from the surface first.
        for (j, &tj) in t.iter().rev().enumerate() {
            layers[j].push(add_scaled(outer[i], dir, tj));
        }
    }
    let mut full = Vec::with_capacity(most as usize + 2);
    full.push(inner);
    full.extend(layers);
    full.push(outer);
    // The wall cell cut evenly along the way to the inner point.
    let m = full.len() - 1;
    let even: Vec<Vec<[f64; 3]>> = (0..=m)
        .map(|j| {
            let w = 1.0 - j as f64 / m as f64;
            (0..nw)
                .map(|i| add_scaled(full[m][i], sub(full[0][i], full[m][i]), w))
                .collect()
        })
        .collect();
    let spread = spread_bad_columns(comm, wall, &full, &even);
    let all: Vec<Vec<[f64; 3]>> = (0..=m)
        .map(|j| {
            (0..nw)
                .map(|i| match spread[i] {
                    0 => full[j][i],
                    a => {
                        let a = a as f64 / SPREAD as f64;
                        add_scaled(full[j][i], sub(even[j][i], full[j][i]), a)
                    }
                })
                .collect()
        })
        .collect();
    for i in 0..nw {
        if spread[i] > 0 {
            thinned[i] = true;
            first[i] = norm(sub(all[m - 1][i], all[m][i]));
        }
    }
    Columns {
        layers: all,
        first,
        thinned,
    }
}

/// Steps from a column's layers to its even cut.
const SPREAD: u64 = 4;
/// The least quality (a cell's [`super::layer_cell::cell_quality`] over
/// that of a box as thick) a layer cell needs.
const GOOD: f64 = 0.05;

/// Where a layer cell would be nearly flat or inverted, its points move
/// step by step from their layers towards the even cut of the wall cell
/// (`even`), whose slabs `layer_points` made valid: per wall
/// point the steps taken, the same on every rank (collective).
fn spread_bad_columns(
    comm: &dyn Comm,
    wall: &Wall,
    full: &[Vec<[f64; 3]>],
    even: &[Vec<[f64; 3]>],
) -> Vec<u64> {
    let nw = wall.labels.len();
    let mut level = vec![[0u64]; nw];
    let at = |level: &[[u64; 1]], j: usize, i: usize| match level[i][0] {
        0 => full[j][i],
        a => add_scaled(
            full[j][i],
            sub(even[j][i], full[j][i]),
            a as f64 / SPREAD as f64,
        ),
    };
    let mut layers: Vec<Vec<[f64; 3]>> = full.to_vec();
    let is_bad = |layers: &[Vec<[f64; 3]>], k: usize| {
        let poly = &wall.polys[k];
        (0..layers.len() - 1).any(|j| {
            let (a, b) = (&layers[j], &layers[j + 1]);
            let thick = poly
                .iter()
                .map(|&i| norm(sub(b[i as usize], a[i as usize])))
                .sum::<f64>()
                / poly.len() as f64
                / wall.sides[k];
            super::layer_cell::cell_quality(wall, k, a, b) < GOOD * 0.5 * thick
        })
    };
    // A cell is measured again only when one of its points has moved.
    let mut moved = vec![false; nw];
    let spare = crate::parallel::cores::spare_core(comm);
    let mut bad: Vec<bool> =
        crate::parallel::cores::map_chunks(spare, wall.polys.len(), 4096, |r| {
            r.map(|k| is_bad(&layers, k)).collect::<Vec<_>>()
        })
        .concat();
    // A step of some points of a face can spoil a face beside it, which
    // then steps too: rounds go on until no face that can still step is bad.
    for round in 0..SPREAD * SPREAD {
        if round > 0 {
            for (k, poly) in wall.polys.iter().enumerate() {
                if poly.iter().any(|&i| moved[i as usize]) {
                    bad[k] = is_bad(&layers, k);
                }
            }
        }
        let mut bump = vec![[0u64]; nw];
        let mut any = [0u64];
        for (k, poly) in wall.polys.iter().enumerate() {
            if bad[k] && poly.iter().any(|&i| level[i as usize][0] < SPREAD) {
                any[0] += 1;
                for &i in poly {
                    bump[i as usize][0] = 1;
                }
            }
        }
        comm.sum_u64(&mut any);
        if any[0] == 0 {
            break;
        }
        merge(comm, &wall.keys, &mut bump, |e, c| e[0] = e[0].max(c[0]));
        moved.iter_mut().for_each(|m| *m = false);
        for i in 0..nw {
            let l = (level[i][0] + bump[i][0]).min(SPREAD);
            if l != level[i][0] {
                level[i][0] = l;
                moved[i] = true;
                for (j, layer) in layers.iter_mut().enumerate() {
                    layer[i] = at(&level, j, i);
                }
            }
        }
    }
    level.iter().map(|l| l[0]).collect()
}

/// Adds the buffer cells and the layers of `plan` on the wall of `pm`
/// whose points `place` put at `inner` and `outer` (collective); returns
/// the per-patch report (complete on every rank).
pub(super) fn add_layers(
    comm: &dyn Comm,
    pm: &mut PolyMesh,
    wall: &Wall,
    (plan, names, domain_side): (&LayerPlan, &PatchNames, f64),
    points: (Vec<[f64; 3]>, Vec<[f64; 3]>),
) -> LayerReport {
    let columns = point_layers(comm, pm, wall, (plan, domain_side), points);
    let report = report(comm, pm, wall, (plan, names), &columns);
    super::layer::stack(pm, wall, &columns.layers);
    report
}

/// Per wall patch with layers: faces, thinned faces, area, covered area,
/// sum of layers by area, sum of first heights by area.
const SUMS: usize = 6;

fn report(
    comm: &dyn Comm,
    pm: &PolyMesh,
    wall: &Wall,
    (plan, names): (&LayerPlan, &PatchNames),
    columns: &Columns,
) -> LayerReport {
    let (layers, first, thinned) = (&columns.layers, &columns.first, &columns.thinned);
    let np = plan.patches.len();
    let mut sums = vec![0.0f64; np * SUMS];
    let (mut lo, mut hi) = (vec![f64::INFINITY; np], vec![f64::NEG_INFINITY; np]);
    let surface = layers.last().map_or(&[][..], |l| &l[..]);
    let mut q = SURFACE_PATCH as usize;
    for (k, &f) in wall.faces.iter().enumerate() {
        while !pm.patches[q].contains(&f) {
            q += 1;
        }
        let w = q - SURFACE_PATCH as usize;
        let Some(spec) = plan.patches[w].as_ref() else {
            continue;
        };
        let poly = &wall.polys[k];
        let area = norm(super::layer::polygon_area(
            poly.iter().map(|&i| surface[i as usize]),
        ));
        let full = poly
            .iter()
            .all(|&i| !thinned[i as usize] && first[i as usize] > 0.0);
        let h = poly.iter().map(|&i| first[i as usize]).sum::<f64>() / poly.len() as f64;
        let n = if poly.iter().all(|&i| first[i as usize] > 0.0) {
            spec.layers
        } else {
            0
        };
        let s = &mut sums[w * SUMS..(w + 1) * SUMS];
        s[0] += 1.0;
        s[1] += f64::from(u8::from(!full));
        s[2] += area;
        s[3] += if full { area } else { 0.0 };
        s[4] += area * f64::from(n);
        s[5] += area * h;
        lo[w] = lo[w].min(h);
        hi[w] = hi[w].max(h);
    }
    // The sums added in rank order, the same on every rank.
    let mine: Vec<u8> = sums.iter().flat_map(|x| x.to_le_bytes()).collect();
    let (all, counts) = comm.allgatherv_bytes(&mine);
    let mut total = vec![0.0f64; np * SUMS];
    let mut at = 0;
    for c in counts {
        for (j, b) in all[at..at + c].chunks_exact(8).enumerate() {
            total[j] += f64::from_le_bytes(b.try_into().expect("8 bytes"));
        }
        at += c;
    }
    let mut ext: Vec<f64> = lo.iter().map(|x| -x).chain(hi.iter().copied()).collect();
    comm.max_f64(&mut ext);
    let mut patches = Vec::new();
    for (w, spec) in plan.patches.iter().enumerate() {
        let Some(spec) = spec else { continue };
        let s = &total[w * SUMS..(w + 1) * SUMS];
        let area = s[2].max(f64::MIN_POSITIVE);
        patches.push(PatchLayerReport {
            patch: names.name(w + SURFACE_PATCH as usize).to_string(),
            layers: spec.layers,
            faces: s[0] as u64,
            thinned_faces: s[1] as u64,
            coverage: s[3] / area,
            mean_layers: s[4] / area,
            first_height_mean: s[5] / area,
            first_height_min: if s[0] > 0.0 { -ext[w] } else { 0.0 },
            first_height_max: if s[0] > 0.0 { ext[np + w] } else { 0.0 },
        });
    }
    LayerReport {
        patches,
        seconds: 0.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(thickness: LayerThickness, relative: bool) -> LayerSpec {
        LayerSpec {
            layers: 3,
            expansion: 1.2,
            thickness,
            relative,
        }
    }

    #[test]
    fn the_three_thicknesses_give_the_same_stack() {
        let h = spec(LayerThickness::First(0.01), false).heights(1.0);
        assert!((h[1] / h[0] - 1.2).abs() < 1e-12 && (h[2] / h[1] - 1.2).abs() < 1e-12);
        let last = spec(LayerThickness::Final(h[2]), false).heights(1.0);
        let total = spec(LayerThickness::Total(h.iter().sum()), false).heights(1.0);
        for k in 0..3 {
            assert!((last[k] - h[k]).abs() < 1e-15 && (total[k] - h[k]).abs() < 1e-15);
        }
        let rel = spec(LayerThickness::First(0.01), true).heights(0.5);
        assert!((rel[0] - 0.005).abs() < 1e-15);
    }

    #[test]
    fn a_column_fills_its_gap_and_thins_where_it_must() {
        let s = spec(LayerThickness::First(0.1), false);
        let (t, thin) = column(Some(&s), 1.0, 1.0, 3);
        assert!(!thin && t.len() == 3 && (t[0] - 0.1).abs() < 1e-15);
        let (t, thin) = column(Some(&s), 1.0, 0.5, 3);
        let total = 0.1 + 0.12 + 0.144;
        assert!(
            thin && (t[2] - FILL * 0.5).abs() < 1e-12
                && (t[0] - 0.1 * FILL * 0.5 / total).abs() < 1e-12
        );
        // Fewer layers than the most: the buffer split in two.
        let (t, _) = column(Some(&s), 1.0, 1.0, 4);
        assert!((t[3] - (0.364 + (1.0 - 0.364) / 2.0)).abs() < 1e-12);
        let (t, thin) = column(None, 1.0, 1.0, 2);
        assert!(!thin && (t[0] - 1.0 / 3.0).abs() < 1e-15 && (t[1] - 2.0 / 3.0).abs() < 1e-15);
    }
}
