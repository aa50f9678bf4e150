//! Brute-force checks of every template against the scheme's rules.

use super::*;
use crate::geometry::cells::{corner_scaled_jacobians, hexahedron_volume};
use crate::octree::octant::Octant;
use std::collections::{BTreeMap, BTreeSet};

/// The faces of a VTK hexahedron.
const HEX_FACES: [[usize; 4]; 6] = [
    [0, 3, 2, 1],
    [4, 5, 6, 7],
    [0, 1, 5, 4],
    [1, 2, 6, 5],
    [2, 3, 7, 6],
    [3, 0, 4, 7],
];

/// The edges of a VTK hexahedron.
const HEX_EDGES: [[usize; 2]; 12] = [
    [0, 1],
    [1, 2],
    [2, 3],
    [3, 0],
    [4, 5],
    [5, 6],
    [6, 7],
    [7, 4],
    [0, 4],
    [1, 5],
    [2, 6],
    [3, 7],
];

type Quad = [Point; 4];

fn key(q: Quad) -> Quad {
    let mut k = q;
    k.sort();
    k
}

fn coords(h: &Hex) -> [[f64; 3]; 8] {
    h.map(|p| p.map(f64::from))
}

/// Whether `p` lies on the segment from `a` to `b`, not at an end.
fn strictly_inside(p: Point, a: Point, b: Point) -> bool {
    let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let e = [p[0] - a[0], p[1] - a[1], p[2] - a[2]];
    let cross = [
        d[1] * e[2] - d[2] * e[1],
        d[2] * e[0] - d[0] * e[2],
        d[0] * e[1] - d[1] * e[0],
    ];
    let t = d[0] * e[0] + d[1] * e[1] + d[2] * e[2];
    let len2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    cross == [0; 3] && t > 0 && t < len2
}

/// What a mesh of the box `[lo, hi]` shows when it passes the checks.
struct Checked {
    min_sj: f64,
    /// The quadrilaterals on each side of the box, by (axis, side).
    sides: BTreeMap<(usize, usize), BTreeSet<Quad>>,
}

/// Checks the hexahedra `hexes` as a conforming mesh of the box `[lo, hi]`:
/// volumes add up to the box's, every inner face is in exactly two
/// hexahedra and every face on the box's sides in one, and no node lies
/// inside an edge of a hexahedron it is not a corner of.
fn check_box(hexes: &[Hex], lo: Point, hi: Point) -> Result<Checked, String> {
    let mut min_sj = f64::INFINITY;
    let mut volume = 0.0;
    for h in hexes {
        let sj = corner_scaled_jacobians(&coords(h));
        min_sj = sj.iter().copied().fold(min_sj, f64::min);
        volume += hexahedron_volume(&coords(h));
    }
    let box_volume: f64 = (0..3).map(|a| f64::from(hi[a] - lo[a])).product();
    if (volume - box_volume).abs() > 1e-9 * box_volume {
        return Err(format!("volume {volume} for a box of {box_volume}"));
    }
    let mut uses: BTreeMap<Quad, usize> = BTreeMap::new();
    for h in hexes {
        for f in HEX_FACES {
            *uses.entry(key(f.map(|i| h[i]))).or_default() += 1;
        }
    }
    let mut sides: BTreeMap<(usize, usize), BTreeSet<Quad>> = BTreeMap::new();
    for (q, &n) in &uses {
        let side = (0..3).find_map(|a| {
            [(lo[a], 0), (hi[a], 1)]
                .into_iter()
                .find(|&(x, _)| q.iter().all(|p| p[a] == x))
                .map(|(_, s)| (a, s))
        });
        match side {
            Some(s) if n == 1 => {
                sides.entry(s).or_default().insert(*q);
            }
            None if n == 2 => {}
            _ => return Err(format!("face {q:?} in {n} hexahedra")),
        }
    }
    let nodes: BTreeSet<Point> = hexes.iter().flatten().copied().collect();
    for h in hexes {
        for [i, j] in HEX_EDGES {
            if let Some(p) = nodes.iter().find(|&&p| strictly_inside(p, h[i], h[j])) {
                return Err(format!("node {p:?} inside the edge {:?} {:?}", h[i], h[j]));
            }
        }
    }
    Ok(Checked { min_sj, sides })
}

fn pattern_keys(marks: Marks, axis: usize, side: usize) -> Option<BTreeSet<Quad>> {
    face_pattern(marks, axis, side).map(|qs| qs.into_iter().map(key).collect())
}

#[test]
fn the_configurations_are_the_22_classes_of_256_mark_sets() {
    let classes = configurations();
    assert_eq!(classes.len(), 22);
    assert_eq!(classes.iter().map(|c| c.members).sum::<usize>(), 256);
    for m in 0..=255u8 {
        let rep = Marks(m).class();
        assert!(Symmetry::all().any(|s| Marks(m).transform(s) == rep));
        assert_eq!(rep.class(), rep);
    }
}

#[test]
fn every_template_passes_the_brute_force_check() {
    let mut worst = f64::INFINITY;
    let mut covered = 0;
    for m in 0..=255u8 {
        let marks = Marks(m);
        let Some(hexes) = macro_template(marks) else {
            continue;
        };
        covered += 1;
        let checked =
            check_box(&hexes, [0; 3], [MACRO; 3]).unwrap_or_else(|e| panic!("marks {m:08b}: {e}"));
        assert!(
            checked.min_sj >= 0.3,
            "marks {m:08b}: scaled Jacobian {}",
            checked.min_sj
        );
        worst = worst.min(checked.min_sj);
        for axis in 0..3 {
            for side in 0..2 {
                let want = pattern_keys(marks, axis, side)
                    .unwrap_or_else(|| panic!("marks {m:08b}: no pattern for face {axis} {side}"));
                let got = checked
                    .sides
                    .get(&(axis, side))
                    .cloned()
                    .unwrap_or_default();
                assert_eq!(got, want, "marks {m:08b}, face {axis} {side}");
            }
        }
    }
    eprintln!("{covered} of 256 mark sets have a template; worst scaled Jacobian {worst:.3}");
    // Every mark set whose marked edges share no corner (77), one whole
    // face (6), all eight (1), and the three classes whose L faces make
    // every octant a corner piece: the convex corner 00010111 (8), its
    // pair 01101011 (8) and 01111110 (4).
    let expected = 77 + 6 + 1 + 8 + 8 + 4;
    assert_eq!(covered, expected);
    assert!(worst >= 0.399, "worst scaled Jacobian {worst}");
}

#[test]
fn face_patterns_do_not_depend_on_the_frame() {
    // The pattern of a face seen through any symmetry of the cube is the
    // pattern of the image face under the image marks: a face's pattern is
    // a function of its own corner marks, not of where it sits.
    for m in 0..=255u8 {
        let marks = Marks(m);
        for s in Symmetry::all() {
            let image = marks.transform(s);
            for axis in 0..3 {
                for side in 0..2 {
                    let Some(quads) = pattern_keys(marks, axis, side) else {
                        continue;
                    };
                    let out_axis = (0..3).find(|&a| s.perm[a] == axis).unwrap();
                    let out_side = side ^ (s.flip as usize >> out_axis & 1);
                    let moved: BTreeSet<Quad> = quads
                        .into_iter()
                        .map(|q| key(q.map(|p| apply(s, p))))
                        .collect();
                    assert_eq!(
                        Some(moved),
                        pattern_keys(image, out_axis, out_side),
                        "marks {m:08b} face {axis} {side} under {s:?}"
                    );
                }
            }
        }
    }
}

fn apply(s: Symmetry, p: Point) -> Point {
    s.point(p)
}

#[test]
fn symmetry_maps_corners_as_points() {
    for s in Symmetry::all() {
        for c in 0..8 {
            let p: Point = std::array::from_fn(|a| MACRO * (c >> a & 1) as i32);
            let q = apply(s, p);
            let image: usize = (0..3).map(|a| ((q[a] / MACRO) as usize) << a).sum();
            assert_eq!(image, s.corner(c));
        }
    }
}

#[test]
fn a_face_with_all_four_corners_marked_is_fine_cells_and_none_is_leaves() {
    let all = pattern_keys(Marks(0xff), 2, 0).unwrap();
    assert_eq!(all.len(), 16);
    assert!(all
        .iter()
        .all(|q| q[3][0] - q[0][0] == FINE && q[3][1] - q[0][1] == FINE));
    let none = pattern_keys(Marks(0), 2, 0).unwrap();
    assert_eq!(none.len(), 4);
}

#[test]
fn the_classes_without_a_template_are_listed() {
    let open: Vec<String> = configurations()
        .into_iter()
        .filter(|c| !c.covered)
        .map(|c| format!("{:08b}", c.representative.0))
        .collect();
    eprintln!("classes without a template: {}", open.join(" "));
    let covered = configurations().iter().filter(|c| c.covered).count();
    assert_eq!(covered + open.len(), 22);
    assert!(covered >= 10, "{covered} classes covered");
}

/// Leaves of a random complete octree (each octant split with probability
/// `p` down to `max_level`), corner balanced.
fn random_leaves(seed: u64, max_level: u8, p: f64) -> Vec<Octant> {
    use crate::octree::octant::Connectivity;
    use crate::octree::LinearOctree;
    let mut rng = crate::testutil::Rng(seed);
    let mut out = Vec::new();
    let mut stack = vec![Octant::ROOT];
    while let Some(o) = stack.pop() {
        if o.level() < 2 || (o.level() < max_level && rng.unit() < p) {
            stack.extend(o.children().into_iter().rev());
        } else {
            out.push(o);
        }
    }
    let mut t = LinearOctree::from_local_leaves(serial(), out).unwrap();
    t.balance(Connectivity::Corner).unwrap();
    t.leaves().to_vec()
}

fn serial() -> crate::parallel::comm::CommRef {
    std::rc::Rc::new(crate::parallel::comm::SerialComm)
}

/// How a leaf set fares under the scheme: the extra refinement of the
/// conditions and the macro cells per class, covered or not.
struct Census {
    leaves: usize,
    macros: usize,
    covered: usize,
    /// Hexahedra of the covered macro cells' templates.
    hexes: usize,
    /// Macro cells per open class representative.
    open: BTreeMap<u8, usize>,
}

fn census(leaves: &[Octant]) -> Census {
    let macros = conditions::macro_tree(serial(), leaves).unwrap();
    let marks = conditions::marks(&macros);
    // The conditions, checked on their own: every macro corner is touched
    // by cells at most one level finer, and the children of the macro cells
    // cover what the leaves covered.
    let mut finest: BTreeMap<[u32; 3], u8> = BTreeMap::new();
    for &o in &macros {
        for c in 0..8 {
            let p: [u32; 3] =
                std::array::from_fn(|d| o.coords()[d] + (c >> d & 1) as u32 * o.side());
            let e = finest.entry(p).or_insert(0);
            *e = (*e).max(o.level());
        }
    }
    for &o in &macros {
        for c in 0..8 {
            let p: [u32; 3] =
                std::array::from_fn(|d| o.coords()[d] + (c >> d & 1) as u32 * o.side());
            assert!(
                finest[&p] <= o.level() + 1,
                "macro tree not corner balanced"
            );
        }
    }
    let volume = |os: &[Octant]| os.iter().map(|o| (o.side() as f64).powi(3)).sum::<f64>();
    assert_eq!(volume(&macros), volume(leaves));
    let mut open = BTreeMap::new();
    let mut covered = 0;
    let mut hexes = 0;
    for m in &marks {
        if let Some(t) = macro_template(*m) {
            covered += 1;
            hexes += t.len();
        } else {
            *open.entry(m.class().0).or_default() += 1;
        }
    }
    Census {
        leaves: leaves.len(),
        macros: macros.len(),
        covered,
        hexes,
        open,
    }
}

fn print_census(name: &str, c: &Census) {
    let open: Vec<String> = c.open.iter().map(|(k, n)| format!("{k:08b}:{n}")).collect();
    eprintln!(
        "{name}: {} leaves -> {} macro cells ({} leaves, x{:.2}); {} covered \
         ({} hexahedra, {:.2} per leaf), {} open [{}]",
        c.leaves,
        c.macros,
        8 * c.macros,
        8.0 * c.macros as f64 / c.leaves as f64,
        c.covered,
        c.hexes,
        c.hexes as f64 / (8 * c.covered) as f64,
        c.macros - c.covered,
        open.join(" ")
    );
}

#[test]
fn the_conditions_hold_on_random_octrees_and_the_census_names_the_open_classes() {
    for seed in 0..6 {
        let leaves = random_leaves(seed, 6, 0.3);
        let c = census(&leaves);
        print_census(&format!("random {seed}"), &c);
        assert!(8 * c.macros >= c.leaves);
        // A random octree has concave transitions: the open class of two
        // marked faces must show up, or the census is not looking.
        assert!(c.open.contains_key(&0b0011_1111), "seed {seed}");
        assert!(!c.open.contains_key(&0b0000_1111), "seed {seed}");
    }
}

#[test]
fn census_of_the_sphere() {
    use crate::octree::domain::{Domain, DEFAULT_FIT};
    use crate::octree::octant::Connectivity;
    use crate::refine::{build_from_surface, SurfaceIndex, NO_LIMIT};
    let s = crate::geometry::load_surface("sphere").unwrap();
    let b = s.bbox();
    let domain = Domain::around(b.min, b.max, DEFAULT_FIT).unwrap();
    let index = SurfaceIndex::new(&s, &domain);
    for level in [4u8, 5] {
        let mut t = build_from_surface(serial(), &index, level, NO_LIMIT).unwrap();
        t.balance(Connectivity::Corner).unwrap();
        let c = census(t.leaves());
        print_census(&format!("sphere level {level}"), &c);
        assert!(c.covered > 0 && c.covered < c.macros);
    }
}

/// A box of macro cells: lowest and past-the-highest indices.
type Region = ([u32; 3], [u32; 3]);

/// The leaves of macro cells of `level` filling the root, with the boxes
/// `refined` (in macro cells of that level, half-open) one macro level
/// finer, and the boxes `deeper` two levels finer.
fn boxed_leaves(level: u8, refined: &[Region], deeper: &[Region]) -> Vec<Octant> {
    let inside = |o: Octant, boxes: &[Region], l: u8| {
        let side = 1u32 << (crate::octree::octant::MAX_LEVEL + 1 - l);
        let c = o.coords();
        boxes
            .iter()
            .any(|(lo, hi)| (0..3).all(|d| c[d] >= lo[d] * side && c[d] < hi[d] * side))
    };
    let mut out = Vec::new();
    let mut stack = vec![Octant::ROOT];
    while let Some(o) = stack.pop() {
        // Macro cells: `level` outside, +1 in `refined`, +2 in `deeper`;
        // leaves one level below their macro cell.
        let macro_level = if inside(o, deeper, level) {
            level + 2
        } else if inside(o, refined, level) {
            level + 1
        } else {
            level
        };
        if o.level() <= macro_level {
            stack.extend(o.children().into_iter().rev());
        } else {
            out.push(o);
        }
    }
    out
}

/// Checks the assembled hexahedra of a whole octree: the volume is the
/// root's, every face is in two hexahedra or on the root's boundary, no
/// node lies inside a hexahedron's edge, every corner's scaled Jacobian is
/// at least 0.3. Returns the number of hexahedra.
fn check_global(hexes: &[[assemble::GlobalPoint; 8]]) -> usize {
    let root = (1u64 << (crate::octree::octant::MAX_LEVEL + 1)) * MACRO as u64;
    check_kept(hexes, (root as f64).powi(3), |q| {
        (0..3).any(|a| q.iter().all(|p| p[a] == 0) || q.iter().all(|p| p[a] == root))
    })
}

/// [`check_global`] for a mesh of part of the root: the volume is
/// `expected`, every face is in two hexahedra or in one and `boundary`.
fn check_kept(
    hexes: &[[assemble::GlobalPoint; 8]],
    expected: f64,
    boundary: impl Fn(&[assemble::GlobalPoint; 4]) -> bool,
) -> usize {
    let mut volume = 0.0;
    for h in hexes {
        let p = h.map(|q| q.map(|x| x as f64));
        volume += hexahedron_volume(&p);
        let sj = corner_scaled_jacobians(&p);
        assert!(sj.iter().all(|&x| x >= 0.3), "{h:?}: {sj:?}");
    }
    assert!(
        (volume - expected).abs() <= 1e-12 * expected,
        "volume {volume} against {expected}"
    );
    let mut uses: BTreeMap<[assemble::GlobalPoint; 4], usize> = BTreeMap::new();
    for h in hexes {
        for f in HEX_FACES {
            let mut k = f.map(|i| h[i]);
            k.sort();
            *uses.entry(k).or_default() += 1;
        }
    }
    for (q, n) in &uses {
        assert!(*n == 2 || (*n == 1 && boundary(q)), "face {q:?} in {n}");
    }
    // A node inside an edge sits at a lattice point between its ends: walk
    // each edge in its smallest lattice steps.
    // Every node is a multiple of the smallest step any coordinate makes.
    let nodes: BTreeSet<assemble::GlobalPoint> = hexes.iter().flatten().copied().collect();
    let unit = nodes
        .iter()
        .flatten()
        .fold(0i64, |g, &x| gcd(g, x as i64))
        .max(1);
    for h in hexes {
        for [i, j] in HEX_EDGES {
            let (a, b) = (h[i].map(|x| x as i64 / unit), h[j].map(|x| x as i64 / unit));
            let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            let g = d.iter().fold(0i64, |g, &x| gcd(g, x.abs()));
            for t in 1..g {
                let p: assemble::GlobalPoint =
                    std::array::from_fn(|k| ((a[k] + d[k] / g * t) * unit) as u64);
                assert!(
                    !nodes.contains(&p),
                    "node {p:?} inside the edge {:?} {:?}",
                    h[i],
                    h[j]
                );
            }
        }
    }
    hexes.len()
}

fn gcd(a: i64, b: i64) -> i64 {
    if b == 0 {
        a
    } else {
        gcd(b, a % b)
    }
}

#[test]
fn octrees_of_covered_configurations_assemble_into_conforming_meshes() {
    // Boxes of finer macro cells inside coarser ones: every coarse macro
    // cell sees a face, an edge or a corner of a box (the covered classes);
    // the nested box puts a third level inside the second.
    let cases: [(&str, Vec<Region>, Vec<Region>); 4] = [
        ("one box", vec![([1, 1, 1], [3, 2, 3])], vec![]),
        ("box at the boundary", vec![([0, 0, 0], [2, 2, 1])], vec![]),
        (
            "two boxes",
            vec![([0, 0, 0], [1, 1, 1]), ([2, 2, 2], [4, 4, 4])],
            vec![],
        ),
        (
            "nested",
            vec![([0, 0, 0], [3, 3, 3])],
            vec![([1, 1, 1], [2, 2, 2])],
        ),
    ];
    for (name, refined, deeper) in cases {
        let leaves = boxed_leaves(2, &refined, &deeper);
        let macros = conditions::macro_tree(serial(), &leaves).unwrap();
        assert_eq!(
            8 * macros.len(),
            leaves.len(),
            "{name}: the conditions held"
        );
        let marks = conditions::marks(&macros);
        let hexes = assemble::assemble(&macros, &marks)
            .unwrap_or_else(|o| panic!("{name}: no template for {o:?}"));
        let n = check_global(&hexes);
        eprintln!(
            "{name}: {} leaves, {n} hexahedra ({:.2} per leaf)",
            leaves.len(),
            n as f64 / leaves.len() as f64
        );
        assert!(n <= 4 * leaves.len());
    }
}

/// The closure on random corner-balanced octrees (whose staircases have
/// every class, covered or not): every leaf kept, the mesh is conforming
/// over the whole root and has only templates of covered classes; with
/// random tags (0 dropped), the kept volume is the kept leaves', every
/// face is in two hexahedra or on the kept region's boundary (a face of
/// a kept leaf whose other side is dropped or outside the root), and each
/// hexahedron has its leaf's tag.
#[test]
fn the_closure_meshes_random_octrees() {
    let unit = MACRO as u64;
    let root = (1u64 << (crate::octree::octant::MAX_LEVEL + 1)) * unit;
    for seed in 0..6 {
        let leaves = random_leaves(100 + seed, 5, 0.35);
        let all = build::build(serial(), &leaves, &vec![1; leaves.len()]).unwrap();
        let hexes: Vec<_> = all
            .hexes
            .iter()
            .map(|h| h.map(|n| all.points[n as usize]))
            .collect();
        let n = check_global(&hexes);
        eprintln!(
            "random {seed}: {} leaves, {n} hexahedra ({:.2} per leaf), {} macro cells split in {} rounds",
            leaves.len(),
            n as f64 / leaves.len() as f64,
            all.refined,
            all.rounds
        );
        assert!(all.rounds > 0, "the octree needs the closure to test it");
        // Tags by leaf, some dropped.
        let mut rng = crate::testutil::Rng(seed);
        let tags: Vec<u32> = leaves.iter().map(|_| (rng.unit() * 3.0) as u32).collect();
        let kept = build::build(serial(), &leaves, &tags).unwrap();
        let tag_at = |p: [f64; 3]| -> u32 {
            let c = p.map(|x| (x / unit as f64) as u32);
            let cell = crate::octree::octant::morton_encode(c[0], c[1], c[2]);
            tags[leaves.partition_point(|o| o.cell_end() <= cell)]
        };
        let volume: f64 = leaves
            .iter()
            .zip(&tags)
            .filter(|(_, &t)| t != 0)
            .map(|(o, _)| (o.side() as f64 * unit as f64).powi(3))
            .sum();
        let hexes: Vec<_> = kept
            .hexes
            .iter()
            .map(|h| h.map(|n| kept.points[n as usize]))
            .collect();
        for (h, &t) in hexes.iter().zip(&kept.tags) {
            let c = [0, 1, 2].map(|d| h.iter().map(|p| p[d] as f64).sum::<f64>() / 8.0);
            assert_eq!(tag_at(c), t, "hexahedron {h:?}");
        }
        check_kept(&hexes, volume, |q| {
            // The point just outside the face's centre is dropped or
            // outside the root.
            let axis = (0..3).find(|&a| q.iter().all(|p| p[a] == q[0][a])).unwrap();
            let c = [0, 1, 2].map(|d| q.iter().map(|p| p[d] as f64).sum::<f64>() / 4.0);
            [-0.5, 0.5].iter().any(|&e| {
                let mut p = c;
                p[axis] += e;
                p[axis] < 0.0 || p[axis] > root as f64 || tag_at(p) == 0
            })
        });
    }
}
