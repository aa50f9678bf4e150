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
use crate::geometry::vector::{add_scaled, norm, scale, sub};

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
    fn most(&self) -> u32 {
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

/// Per wall point: the patch whose setting it takes (`u64::MAX`: none)
/// and its finest face's side, each the least over the ranks that have
/// the point (collective).
fn point_settings(
    comm: &dyn Comm,
    pm: &PolyMesh,
    wall: &Wall,
    plan: &LayerPlan,
) -> (Vec<u64>, Vec<f64>) {
    let nw = wall.labels.len();
    let mut patch = vec![u64::MAX; nw];
    let mut side = vec![f64::INFINITY; nw];
    let mut q = SURFACE_PATCH as usize;
    for (k, &f) in wall.faces.iter().enumerate() {
        while !pm.patches[q].contains(&f) {
            q += 1;
        }
        let with = plan.patches[q - SURFACE_PATCH as usize].is_some();
        for &i in &wall.polys[k] {
            let i = i as usize;
            if with {
                patch[i] = patch[i].min(q as u64);
            }
            side[i] = side[i].min(wall.sides[k]);
        }
    }
    let p = comm.size();
    let mut out = vec![Vec::new(); p];
    for i in 0..nw {
        out[home(wall.keys[i], p)].extend([wall.keys[i], patch[i], side[i].to_bits()]);
    }
    // Positive numbers order as their bits do.
    let mut least: std::collections::BTreeMap<u64, [u64; 2]> = Default::default();
    let mut senders: Vec<Vec<u64>> = vec![Vec::new(); p];
    for (r, recs) in exchange(comm, out).iter().enumerate() {
        for c in recs.chunks_exact(3) {
            let e = least.entry(c[0]).or_insert([u64::MAX; 2]);
            e[0] = e[0].min(c[1]);
            e[1] = e[1].min(c[2]);
            senders[r].push(c[0]);
        }
    }
    let reply: Vec<Vec<u64>> = senders
        .iter()
        .map(|keys| {
            keys.iter()
                .flat_map(|k| {
                    let e = least[k];
                    [*k, e[0], e[1]]
                })
                .collect()
        })
        .collect();
    let back: std::collections::HashMap<u64, [u64; 2]> = exchange(comm, reply)
        .iter()
        .flat_map(|r| r.chunks_exact(3).map(|c| (c[0], [c[1], c[2]])))
        .collect();
    for i in 0..nw {
        if let Some(e) = back.get(&wall.keys[i]) {
            patch[i] = e[0];
            side[i] = f64::from_bits(e[1]);
        }
    }
    (patch, side)
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

/// The point layers of the wall from the staircase (`inner`) to the
/// surface (`outer`): `most + 2` of them, by wall point number, and per
/// wall point its first layer's height and whether it was thinned
/// (collective).
type Layers = (Vec<Vec<[f64; 3]>>, Vec<f64>, Vec<bool>);

fn point_layers(
    comm: &dyn Comm,
    pm: &PolyMesh,
    wall: &Wall,
    plan: &LayerPlan,
    (inner, outer): (Vec<[f64; 3]>, Vec<[f64; 3]>),
) -> Layers {
    let (patch, side) = point_settings(comm, pm, wall, plan);
    let most = plan.most();
    let nw = inner.len();
    let mut layers = vec![Vec::with_capacity(nw); most as usize];
    let (mut first, mut thinned) = (vec![0.0; nw], vec![false; nw]);
    for i in 0..nw {
        let d = sub(inner[i], outer[i]);
        let gap = norm(d);
        let dir = if gap > 0.0 {
            scale(d, 1.0 / gap)
        } else {
            [0.0; 3]
        };
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
    let mut all = Vec::with_capacity(most as usize + 2);
    all.push(inner);
    all.extend(layers);
    all.push(outer);
    (all, first, thinned)
}

/// Adds the buffer cells and the layers of `plan` on the wall of `pm`
/// whose points `place` put at `inner` and `outer` (collective); returns
/// the per-patch report (complete on every rank).
pub(super) fn add_layers(
    comm: &dyn Comm,
    pm: &mut PolyMesh,
    wall: &Wall,
    plan: &LayerPlan,
    names: &PatchNames,
    points: (Vec<[f64; 3]>, Vec<[f64; 3]>),
) -> LayerReport {
    let (layers, first, thinned) = point_layers(comm, pm, wall, plan, points);
    let report = report(comm, pm, wall, plan, names, (&layers, &first, &thinned));
    super::layer::stack(pm, wall, &layers);
    report
}

/// Per wall patch with layers: faces, thinned faces, area, covered area,
/// sum of layers by area, sum of first heights by area.
const SUMS: usize = 6;

fn report(
    comm: &dyn Comm,
    pm: &PolyMesh,
    wall: &Wall,
    plan: &LayerPlan,
    names: &PatchNames,
    (layers, first, thinned): (&[Vec<[f64; 3]>], &[f64], &[bool]),
) -> LayerReport {
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
