//! Criterion micro-benchmarks of the octmesh kernels: Morton key encoding,
//! radix sort of octant keys, the triangle/box test, bounding-box tree
//! queries, local 2:1 balance and mesh construction (node extraction).
//!
//! Run with `cargo bench --bench kernels`. Every input is deterministic: the
//! random inputs come from a fixed-seed generator, the geometric ones from the
//! built-in sphere (20480 triangles) refined to level 8 on one rank.

use std::hint::black_box;
use std::rc::Rc;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, BatchSize, Criterion, SamplingMode, Throughput};

use octmesh::internals::classify::{classify_leaves, CutRule, Keep};
use octmesh::internals::geometry::bvh::Bvh;
use octmesh::internals::geometry::intersect::triangle_box_overlap;
use octmesh::internals::geometry::{shapes, Triangle};
use octmesh::internals::mesh::{Mesh, MeshOptions};
use octmesh::internals::octree::domain::{Domain, DEFAULT_FIT};
use octmesh::internals::octree::octant::{morton_decode, morton_encode, ROOT_LEN};
use octmesh::internals::octree::sort::radix_sort_bits;
use octmesh::internals::parallel::comm::{CommRef, SerialComm};
use octmesh::internals::refine::{build_from_surface, SurfaceIndex, NO_LIMIT};
use octmesh::{Connectivity, LinearOctree, Octant, MAX_LEVEL};

/// Refinement level of the sphere octree used by the geometric benchmarks.
const LEVEL: u8 = 8;
/// Number of random lattice points for the Morton benchmarks.
const MORTON_POINTS: usize = 1 << 20;
/// Number of random octant keys for the sort benchmarks.
const SORT_KEYS: usize = 1 << 22;
/// Every `QUERY_STRIDE`-th level-8 leaf is used for the box tests and tree
/// queries, to keep one iteration short.
const QUERY_STRIDE: usize = 8;

/// SplitMix64: a small deterministic generator, enough for benchmark inputs.
struct SplitMix(u64);

impl SplitMix {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// A lattice coordinate in `0..ROOT_LEN`.
    fn coord(&mut self) -> u32 {
        (self.next() % ROOT_LEN as u64) as u32
    }
}

fn comm() -> CommRef {
    Rc::new(SerialComm)
}

/// The built-in sphere in lattice units and its surface-refined octree.
struct Sphere {
    domain: Domain,
    index: SurfaceIndex,
    refined: Vec<Octant>,
}

fn sphere() -> Sphere {
    let surface = shapes::default_sphere();
    let b = surface.bbox();
    let domain = Domain::around(b.min, b.max, DEFAULT_FIT).expect("domain");
    let index = SurfaceIndex::new(&surface, &domain);
    let tree = build_from_surface(comm(), &index, LEVEL, NO_LIMIT).expect("refine");
    let refined = tree.leaves().to_vec();
    Sphere {
        domain,
        index,
        refined,
    }
}

/// Every `QUERY_STRIDE`-th leaf at the target level (those touch the surface).
fn surface_octants(s: &Sphere) -> Vec<Octant> {
    s.refined
        .iter()
        .copied()
        .filter(|o| o.level() == LEVEL)
        .step_by(QUERY_STRIDE)
        .collect()
}

fn bench_morton(c: &mut Criterion) {
    let mut rng = SplitMix(1);
    let points: Vec<[u32; 3]> = (0..MORTON_POINTS)
        .map(|_| [rng.coord(), rng.coord(), rng.coord()])
        .collect();
    let codes: Vec<u64> = points
        .iter()
        .map(|&[x, y, z]| morton_encode(x, y, z))
        .collect();

    let mut g = c.benchmark_group("morton");
    g.sample_size(20)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(3))
        .throughput(Throughput::Elements(MORTON_POINTS as u64));
    g.bench_function("encode", |b| {
        b.iter(|| {
            let mut acc = 0u64;
            for &[x, y, z] in black_box(&points) {
                acc ^= morton_encode(x, y, z);
            }
            acc
        })
    });
    g.bench_function("decode", |b| {
        b.iter(|| {
            let mut acc = 0u32;
            for &m in black_box(&codes) {
                let [x, y, z] = morton_decode(m);
                acc ^= x ^ y.rotate_left(7) ^ z.rotate_left(14);
            }
            acc
        })
    });
    g.finish();
}

fn bench_sort(c: &mut Criterion) {
    // Random valid octants: uniform level, random anchor aligned to the level.
    let mut rng = SplitMix(2);
    let keys: Vec<u64> = (0..SORT_KEYS)
        .map(|_| {
            let level = (rng.next() % (MAX_LEVEL as u64 + 1)) as u8;
            let mask = !((ROOT_LEN >> level) - 1);
            let [x, y, z] = [rng.coord() & mask, rng.coord() & mask, rng.coord() & mask];
            Octant::new(x, y, z, level).expect("octant").key()
        })
        .collect();
    // Keys use bits 0..62 (57-bit Morton code above a 5-bit level).
    let (lo, hi) = (0, 62);
    {
        let mut a = keys.clone();
        radix_sort_bits(&mut a, &mut Vec::new(), lo, hi);
        let mut b = keys.clone();
        b.sort_unstable();
        assert_eq!(a, b, "radix sort disagrees with sort_unstable");
    }

    let mut g = c.benchmark_group("sort_octant_keys");
    g.sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(4))
        .sampling_mode(SamplingMode::Flat)
        .throughput(Throughput::Elements(SORT_KEYS as u64));
    g.bench_function("radix_sort_bits", |b| {
        let mut tmp = Vec::with_capacity(SORT_KEYS);
        b.iter_batched_ref(
            || keys.clone(),
            |v| radix_sort_bits(v, &mut tmp, lo, hi),
            BatchSize::LargeInput,
        )
    });
    g.bench_function("sort_unstable", |b| {
        b.iter_batched_ref(
            || keys.clone(),
            |v| v.sort_unstable(),
            BatchSize::LargeInput,
        )
    });
    g.finish();
}

fn bench_geometry(c: &mut Criterion, s: &Sphere) {
    let tris: &[Triangle] = s.index.triangles();
    let bvh = Bvh::new(tris);
    let octants = surface_octants(s);
    let boxes: Vec<([f64; 3], [f64; 3])> = octants.iter().map(|o| o.bounds_f64()).collect();

    // (triangle, box) pairs whose bounding boxes overlap: exactly the pairs
    // the refinement hands to the exact test.
    let mut pairs: Vec<(u32, usize)> = Vec::new();
    let mut cand = Vec::new();
    for (bi, &(lo, hi)) in boxes.iter().enumerate() {
        cand.clear();
        bvh.query_candidates(lo, hi, &mut cand);
        pairs.extend(cand.iter().map(|&t| (t, bi)));
    }
    let hits = pairs
        .iter()
        .filter(|&&(t, bi)| triangle_box_overlap(&tris[t as usize], boxes[bi].0, boxes[bi].1))
        .count();
    eprintln!(
        "geometry inputs: {} triangles, {} level-{LEVEL} boxes (every {QUERY_STRIDE}th), \
         {} bbox-overlapping pairs, {} of them overlap ({:.1}%)",
        tris.len(),
        boxes.len(),
        pairs.len(),
        hits,
        100.0 * hits as f64 / pairs.len() as f64
    );

    let mut g = c.benchmark_group("triangle_box_overlap");
    g.sample_size(20)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(3))
        .throughput(Throughput::Elements(pairs.len() as u64));
    g.bench_function("sphere_level8_pairs", |b| {
        b.iter(|| {
            let mut n = 0usize;
            for &(t, bi) in black_box(&pairs) {
                let (lo, hi) = boxes[bi];
                n += triangle_box_overlap(&tris[t as usize], lo, hi) as usize;
            }
            n
        })
    });
    g.finish();

    let mut g = c.benchmark_group("bvh");
    g.sample_size(20)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(5))
        .throughput(Throughput::Elements(boxes.len() as u64));
    g.bench_function("query_box_level8", |b| {
        let mut out = Vec::new();
        b.iter(|| {
            let mut n = 0usize;
            for &(lo, hi) in black_box(&boxes) {
                out.clear();
                bvh.query_box(tris, lo, hi, &mut out);
                n += out.len();
            }
            n
        })
    });
    g.finish();
}

fn bench_balance(c: &mut Criterion, s: &Sphere) {
    let mut g = c.benchmark_group("balance");
    g.sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(4))
        .sampling_mode(SamplingMode::Flat)
        .throughput(Throughput::Elements(s.refined.len() as u64));
    g.bench_function("corner_sphere_level8", |b| {
        b.iter_batched(
            || LinearOctree::from_local_leaves(comm(), s.refined.clone()).expect("octree"),
            |mut t| {
                t.balance(Connectivity::Corner).expect("balance");
                t
            },
            BatchSize::LargeInput,
        )
    });
    g.finish();
}

fn bench_mesh(c: &mut Criterion, s: &Sphere) {
    let mut tree = LinearOctree::from_local_leaves(comm(), s.refined.clone()).expect("octree");
    tree.balance(Connectivity::Corner).expect("balance");
    let classes = classify_leaves(tree.leaves(), &s.index);
    let opts = MeshOptions {
        keep: Keep::All,
        cut_rule: CutRule::Center,
        clean_walls: false,
    };
    let mesh = Mesh::build(&tree, &s.domain, Some(&classes), &opts).expect("mesh");
    eprintln!(
        "mesh inputs: {} refined leaves, {} balanced leaves, {} elements, {} nodes, {} hanging",
        s.refined.len(),
        tree.local_len(),
        mesh.elements().len(),
        mesh.num_nodes(),
        mesh.num_hanging()
    );
    drop(mesh);

    let mut g = c.benchmark_group("mesh");
    g.sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(5))
        .sampling_mode(SamplingMode::Flat)
        .throughput(Throughput::Elements(tree.local_len() as u64));
    g.bench_function("build_all_sphere_level8", |b| {
        b.iter(|| Mesh::build(&tree, &s.domain, Some(&classes), &opts).expect("mesh"))
    });
    g.finish();
}

fn bench_surface_kernels(c: &mut Criterion) {
    let s = sphere();
    bench_geometry(c, &s);
    bench_balance(c, &s);
    bench_mesh(c, &s);
}

criterion_group!(kernels, bench_morton, bench_sort, bench_surface_kernels);
criterion_main!(kernels);
