//! The accumulator of the quality figures: each rank adds its elements,
//! faces and cells, then [`Figures::reduce`] combines the ranks into a
//! [`Quality`] whose bits do not depend on the rank count (maxima and
//! minima are exact; the averages are sums of fixed-point integers, exact
//! and so independent of the order of the sum).
//!
//! The figures and their names are `checkMesh`'s (OpenFOAM v1912's
//! `primitiveMeshTools` and `polyMeshTools`), over the same faces and
//! cells: face statistics over the internal faces (a face between two
//! ranks once), flatness over every face, determinants over every cell
//! from its internal faces (a face to another rank counts as internal).
//! The limits are `meshQualityDict`'s defaults, which snappyHexMesh
//! enforces while it snaps.

use super::{
    boundary_face_skewness, face_orthogonality, face_skewness, histogram_bin, Histogram, Quality,
    HISTOGRAM_BINS,
};
use crate::geometry::cells::{face_flatness, face_twist, TINY};
use crate::geometry::vector::{dot, norm, scale, sub};
use crate::parallel::comm::Comm;

/// `meshQualityDict`'s default limits, which `--quality` counts the mesh
/// against.
pub mod limits {
    /// `maxNonOrtho`, degrees.
    pub const MAX_NON_ORTHO: f64 = 65.0;
    /// `maxBoundarySkewness`.
    pub const MAX_BOUNDARY_SKEWNESS: f64 = 20.0;
    /// `maxInternalSkewness`.
    pub const MAX_INTERNAL_SKEWNESS: f64 = 4.0;
    /// `minDeterminant`.
    pub const MIN_DETERMINANT: f64 = 0.001;
    /// `minFaceWeight`.
    pub const MIN_FACE_WEIGHT: f64 = 0.05;
    /// `minVolRatio`.
    pub const MIN_VOL_RATIO: f64 = 0.01;
    /// `minTwist`.
    pub const MIN_TWIST: f64 = 0.02;
}

/// What fails `meshQualityDict`'s default limits ([`limits`]): faces,
/// or cells for the determinant.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct LimitCounts {
    /// Internal faces more non-orthogonal than `maxNonOrtho` (65).
    pub non_orthogonal_faces: u64,
    /// Internal faces more skewed than `maxInternalSkewness` (4).
    pub skewed_internal_faces: u64,
    /// Boundary faces more skewed than `maxBoundarySkewness` (20).
    pub skewed_boundary_faces: u64,
    /// Cells whose determinant is below `minDeterminant` (0.001).
    pub low_determinant_cells: u64,
    /// Internal faces whose interpolation weight is below `minFaceWeight`
    /// (0.05).
    pub low_weight_faces: u64,
    /// Internal faces whose cells' volume ratio is below `minVolRatio`
    /// (0.01).
    pub low_volume_ratio_faces: u64,
    /// Faces twisted below `minTwist` (0.02).
    pub twisted_faces: u64,
}

impl LimitCounts {
    /// Whether nothing fails.
    pub fn passed(&self) -> bool {
        *self == LimitCounts::default()
    }
}

// Sums (u64, added over the ranks).
const ELEMENTS: usize = 0;
const INVERTED: usize = 1;
const FACES: usize = 2;
const FLAT_FACES: usize = 3;
const HIST: usize = 4;
/// Fixed-point words (high, low) of the summed cosines, weights, volume
/// ratios, flatness and determinants.
const WORDS: usize = HIST + HISTOGRAM_BINS;
const COSINE: usize = WORDS;
const WEIGHT: usize = WORDS + 2;
const VOL_RATIO: usize = WORDS + 4;
const FLATNESS: usize = WORDS + 6;
const DETERMINANT: usize = WORDS + 8;
const COUNTS: usize = WORDS + 10;
const NUM_SUMS: usize = COUNTS + 7;

// Maxima (f64, maximum over the ranks; minima stored negated).
const NEG_JACOBIAN: usize = 0;
const NEG_COSINE: usize = 1;
const SKEW: usize = 2;
const SKEW_INTERNAL: usize = 3;
const SKEW_BOUNDARY: usize = 4;
const NEG_WEIGHT: usize = 5;
const NEG_VOL_RATIO: usize = 6;
const NEG_FLATNESS: usize = 7;
const NEG_TWIST: usize = 8;
const NEG_DETERMINANT: usize = 9;
const NUM_MAX: usize = 10;

/// Fixed-point scale: a value `v` in `[-range, range]` is summed as the
/// integer `(v / range + 1) 2^52`, split into words of 26 bits that each
/// sum without overflow for 2^37 terms.
const ONE: f64 = (1u64 << 52) as f64;

fn words(v: f64, range: f64) -> [u64; 2] {
    // Rounded half up; `round` is a library call.
    let x = ((v / range).clamp(-1.0, 1.0) + 1.0) * ONE + 0.5;
    let x = x as u64;
    [x >> 26, x & ((1 << 26) - 1)]
}

/// The mean of `n` values summed as [`words`] at `at`.
fn mean(sums: &[u64], at: usize, n: u64, range: f64) -> f64 {
    if n == 0 {
        return 0.0;
    }
    let total = ((sums[at] as u128) << 26) + sums[at + 1] as u128;
    (total as f64 / ONE / n as f64 - 1.0) * range
}

/// The range of the summed determinants (a cube's is 1, a coarse cell of a
/// 2:1 interface's about 7).
const DETERMINANT_RANGE: f64 = 1024.0;

/// One cell's sum of `S S^T` and of `|S|` over its internal faces, for its
/// determinant.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct AreaTensor {
    t: [f64; 6],
    area: f64,
    faces: u32,
}

impl AreaTensor {
    /// Adds an internal face's area vector.
    pub(super) fn add(&mut self, s: [f64; 3]) {
        let t = &mut self.t;
        t[0] += s[0] * s[0];
        t[1] += s[0] * s[1];
        t[2] += s[0] * s[2];
        t[3] += s[1] * s[1];
        t[4] += s[1] * s[2];
        t[5] += s[2] * s[2];
        self.area += norm(s);
        self.faces += 1;
    }

    /// `checkMesh`'s cell determinant: the determinant of the sum of `S
    /// S^T` with each `S` divided by the mean area, over 8 (a cube's is
    /// 1); 0 without internal faces.
    pub(super) fn determinant(&self) -> f64 {
        let avg = self.area / self.faces.max(1) as f64;
        if self.faces == 0 || avg < TINY {
            return 0.0;
        }
        let t = self.t.map(|x| x / (avg * avg));
        let det = t[0] * (t[3] * t[5] - t[4] * t[4]) - t[1] * (t[1] * t[5] - t[4] * t[2])
            + t[2] * (t[1] * t[4] - t[3] * t[2]);
        det.abs() / 8.0
    }
}

/// One rank's share of the figures.
pub(super) struct Figures {
    sums: Vec<u64>,
    max: [f64; NUM_MAX],
}

impl Figures {
    pub(super) fn new() -> Figures {
        let mut max = [-f64::MAX; NUM_MAX];
        max[SKEW] = 0.0;
        max[SKEW_INTERNAL] = 0.0;
        max[SKEW_BOUNDARY] = 0.0;
        Figures {
            sums: vec![0; NUM_SUMS],
            max,
        }
    }

    /// An element's scaled Jacobian.
    pub(super) fn element(&mut self, j: f64) {
        self.sums[ELEMENTS] += 1;
        self.sums[INVERTED] += (j <= 0.0) as u64;
        self.sums[HIST + histogram_bin(j)] += 1;
        self.max[NEG_JACOBIAN] = self.max[NEG_JACOBIAN].max(-j);
    }

    /// A cell's determinant.
    pub(super) fn cell(&mut self, a: &AreaTensor) {
        let d = a.determinant();
        let w = words(d, DETERMINANT_RANGE);
        self.sums[DETERMINANT] += w[0];
        self.sums[DETERMINANT + 1] += w[1];
        self.sums[COUNTS + 3] += (d < limits::MIN_DETERMINANT) as u64;
        self.max[NEG_DETERMINANT] = self.max[NEG_DETERMINANT].max(-d);
    }

    fn add_words(&mut self, at: usize, v: f64) {
        let w = words(v, 1.0);
        self.sums[at] += w[0];
        self.sums[at + 1] += w[1];
    }

    /// Any face's flatness (faces of more than three points).
    fn flatness(&mut self, points: &[[f64; 3]], c: [f64; 3], s: [f64; 3]) {
        if points.len() > 3 {
            let f = face_flatness(points, c, s);
            self.sums[FLAT_FACES] += 1;
            self.add_words(FLATNESS, f);
            self.max[NEG_FLATNESS] = self.max[NEG_FLATNESS].max(-f);
        }
    }

    fn twist(&mut self, points: &[[f64; 3]], c: [f64; 3], towards: [f64; 3]) {
        if points.len() > 3 {
            let nf = scale(towards, 1.0 / (norm(towards) + TINY));
            let t = face_twist(points, c, nf);
            self.sums[COUNTS + 6] += (t < limits::MIN_TWIST) as u64;
            self.max[NEG_TWIST] = self.max[NEG_TWIST].max(-t);
        }
    }

    /// An internal face (a face between ranks on one of them): its
    /// `points`, centre `c` and area vector `s` pointing from the cell
    /// with centre `p` and volume `vp` to the one with `n` and `vn`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn internal_face(
        &mut self,
        points: &[[f64; 3]],
        c: [f64; 3],
        s: [f64; 3],
        (p, vp): ([f64; 3], f64),
        (n, vn): ([f64; 3], f64),
    ) {
        let cos = face_orthogonality(p, n, s);
        let skew = face_skewness(c, s, points, p, n);
        let d_own = dot(s, sub(c, p)).abs();
        let d_nei = dot(s, sub(n, c)).abs();
        let weight = d_own.min(d_nei) / (d_own + d_nei + TINY);
        let ratio = vp.min(vn) / (vp.max(vn) + TINY);
        self.sums[FACES] += 1;
        let w = words(cos, 1.0);
        self.sums[COSINE] += w[0];
        self.sums[COSINE + 1] += w[1];
        self.add_words(WEIGHT, weight);
        self.add_words(VOL_RATIO, ratio);
        // More than maxNonOrtho degrees: a cosine below the limit's.
        let limit = limits::MAX_NON_ORTHO.to_radians().cos();
        self.sums[COUNTS] += (cos < limit) as u64;
        self.sums[COUNTS + 1] += (skew > limits::MAX_INTERNAL_SKEWNESS) as u64;
        self.sums[COUNTS + 4] += (weight < limits::MIN_FACE_WEIGHT) as u64;
        self.sums[COUNTS + 5] += (ratio < limits::MIN_VOL_RATIO) as u64;
        let m = &mut self.max;
        m[NEG_COSINE] = m[NEG_COSINE].max(-cos);
        m[SKEW] = m[SKEW].max(skew);
        m[SKEW_INTERNAL] = m[SKEW_INTERNAL].max(skew);
        m[NEG_WEIGHT] = m[NEG_WEIGHT].max(-weight);
        m[NEG_VOL_RATIO] = m[NEG_VOL_RATIO].max(-ratio);
        self.flatness(points, c, s);
        self.twist(points, c, sub(n, p));
    }

    /// A boundary face of the cell with centre `p`, `s` out of the mesh.
    pub(super) fn boundary_face(
        &mut self,
        points: &[[f64; 3]],
        c: [f64; 3],
        s: [f64; 3],
        p: [f64; 3],
    ) {
        let skew = boundary_face_skewness(c, s, points, p);
        self.sums[COUNTS + 2] += (skew > limits::MAX_BOUNDARY_SKEWNESS) as u64;
        self.max[SKEW] = self.max[SKEW].max(skew);
        self.max[SKEW_BOUNDARY] = self.max[SKEW_BOUNDARY].max(skew);
        self.flatness(points, c, s);
        self.twist(points, c, sub(c, p));
    }

    /// The figures over all ranks. Collective.
    pub(super) fn reduce(mut self, comm: &dyn Comm) -> Quality {
        comm.sum_u64(&mut self.sums);
        comm.max_f64(&mut self.max);
        let (s, m) = (&self.sums, &self.max);
        let (elements, faces, flat) = (s[ELEMENTS], s[FACES], s[FLAT_FACES]);
        // A minimum over nothing is 1 (0 for the non-orthogonality).
        let min = |k: usize, n: u64| if n == 0 { 1.0 } else { -m[k] };
        let degrees = |c: f64| c.clamp(-1.0, 1.0).acos().to_degrees();
        let (nonorth_max, nonorth_mean) = if faces == 0 {
            (0.0, 0.0)
        } else {
            (
                degrees(-m[NEG_COSINE]),
                degrees(mean(s, COSINE, faces, 1.0)),
            )
        };
        let twisted = flat > 0 && m[NEG_TWIST] > -f64::MAX;
        Quality {
            elements,
            scaled_jacobian_min: min(NEG_JACOBIAN, elements),
            inverted_elements: s[INVERTED],
            scaled_jacobian_histogram: Histogram {
                edges: (0..=HISTOGRAM_BINS)
                    .map(|k| (k as f64 - 10.0) / 10.0)
                    .collect(),
                counts: s[HIST..HIST + HISTOGRAM_BINS].to_vec(),
            },
            internal_faces: faces,
            non_orthogonality_max: nonorth_max,
            non_orthogonality_average: nonorth_mean,
            skewness_max: m[SKEW],
            internal_skewness_max: m[SKEW_INTERNAL],
            boundary_skewness_max: m[SKEW_BOUNDARY],
            determinant_min: min(NEG_DETERMINANT, elements),
            determinant_average: mean(s, DETERMINANT, elements, DETERMINANT_RANGE),
            face_weight_min: min(NEG_WEIGHT, faces),
            face_weight_average: mean(s, WEIGHT, faces, 1.0),
            volume_ratio_min: min(NEG_VOL_RATIO, faces),
            volume_ratio_average: mean(s, VOL_RATIO, faces, 1.0),
            face_flatness_min: min(NEG_FLATNESS, flat),
            face_flatness_average: mean(s, FLATNESS, flat, 1.0),
            face_twist_min: if twisted { -m[NEG_TWIST] } else { 1.0 },
            limits: LimitCounts {
                non_orthogonal_faces: s[COUNTS],
                skewed_internal_faces: s[COUNTS + 1],
                skewed_boundary_faces: s[COUNTS + 2],
                low_determinant_cells: s[COUNTS + 3],
                low_weight_faces: s[COUNTS + 4],
                low_volume_ratio_faces: s[COUNTS + 5],
                twisted_faces: s[COUNTS + 6],
            },
        }
    }
}
