//! Helpers for the unit tests of several modules.

/// A small deterministic generator (splitmix64) for randomised tests, so a
/// failure can be replayed from its seed.
pub(crate) struct Rng(pub u64);

impl Rng {
    /// The next 64 random bits.
    pub fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform integer in [lo, hi].
    pub fn range(&mut self, lo: i64, hi: i64) -> i64 {
        lo + (self.next() % (hi - lo + 1) as u64) as i64
    }

    /// A point uniform in the cube [lo, hi)^3.
    pub fn in_box(&mut self, lo: f64, hi: f64) -> [f64; 3] {
        std::array::from_fn(|_| lo + (hi - lo) * self.unit())
    }
}

/// The mesh of surface `name` (a built-in or a file) at `level`, keeping
/// `keep` (one rank, corner balance, cut leaves kept by their centres,
/// walls cleaned), and the surface.
pub(crate) fn mesh_of(
    name: &str,
    level: u8,
    keep: crate::classify::Keep,
) -> (crate::mesh::Mesh, crate::geometry::Surface) {
    use crate::classify::{classify_leaves, CutRule};
    use crate::mesh::{Mesh, MeshOptions};
    use crate::octree::domain::{Domain, DEFAULT_FIT};
    use crate::octree::octant::Connectivity;
    use crate::parallel::comm::{CommRef, SerialComm};
    use crate::refine::{build_from_surface, SurfaceIndex, NO_LIMIT};
    let comm: CommRef = std::rc::Rc::new(SerialComm);
    let s = crate::geometry::load_surface(name).unwrap();
    let b = s.bbox();
    let domain = Domain::around(b.min, b.max, DEFAULT_FIT).unwrap();
    let index = SurfaceIndex::new(&s, &domain);
    let mut t = build_from_surface(comm, &index, level, NO_LIMIT).unwrap();
    t.balance(Connectivity::Corner).unwrap();
    let classes = classify_leaves(t.leaves(), &index);
    let opts = MeshOptions {
        keep,
        cut_rule: CutRule::Center,
        clean_walls: true,
    };
    (Mesh::build(&t, &domain, Some(&classes), &opts).unwrap(), s)
}

/// The fluid mesh around the built-in sphere at `level` ([`mesh_of`]).
pub(crate) fn sphere_mesh(level: u8) -> crate::mesh::Mesh {
    mesh_of("sphere", level, crate::classify::Keep::Outside).0
}
