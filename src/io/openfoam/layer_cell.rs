//! A new cell between two polygons of wall points as OpenFOAM measures it:
//! its faces' area vectors and centres (the triangles of each face's fan),
//! its centre and its least face pyramid, on the stack for the faces of up
//! to [`MAXP`] points. The wall layer's improving pass and the boundary
//! layers' column check judge cells by it.

use crate::geometry::vector::{add, add_scaled, dot, norm, scale, sub};

/// The most points of a wall face whose new cell is measured without
/// allocating: under 2:1 balance a face has at most 8.
pub(super) const MAXP: usize = 8;

/// A face's area vector and centre.
pub(super) type FaceGeometry = ([f64; 3], [f64; 3]);

/// A face's area vector and centre as OpenFOAM computes them: the
/// triangles of its fan about its points' mean, the centre weighted by
/// their areas.
pub(super) fn face_geometry(f: &[[f64; 3]]) -> FaceGeometry {
    // The fan's triangles kept on the stack when they fit (a small buffer
    // for the quadrilaterals most faces are), else computed twice.
    match f.len() {
        0..=4 => fan::<4>(f),
        5..=MAXP => fan::<MAXP>(f),
        _ => fan::<0>(f),
    }
}

/// [`face_geometry`] with room for `K` triangles.
fn fan<const K: usize>(f: &[[f64; 3]]) -> FaceGeometry {
    use crate::geometry::vector::cross;
    let n = f.len();
    let m = scale(f.iter().copied().fold([0.0; 3], add), 1.0 / n as f64);
    let tri = |j: usize| {
        let (a, b) = (f[j], f[if j + 1 == n { 0 } else { j + 1 }]);
        (
            scale(cross(sub(a, m), sub(b, m)), 0.5),
            scale(add(add(a, b), m), 1.0 / 3.0),
        )
    };
    let mut buf = [([0.0; 3], [0.0; 3]); K];
    let kept = n <= K;
    if kept {
        for (j, t) in buf.iter_mut().take(n).enumerate() {
            *t = tri(j);
        }
    }
    let at = |j: usize| if kept { buf[j] } else { tri(j) };
    let area = (0..n).fold([0.0; 3], |s, j| add(s, at(j).0));
    let (mut sum_n, mut centre) = (0.0, [0.0; 3]);
    for j in 0..n {
        // OpenFOAM v1912 (what checkMesh runs here) weighs each triangle by
        // its area; later versions by its area along the face's, which
        // differs on warped slivers.
        let (a, c) = at(j);
        let w = norm(a);
        sum_n += w;
        centre = add_scaled(centre, c, w);
    }
    let centre = if sum_n.abs() > 0.0 {
        scale(centre, 1.0 / sum_n)
    } else {
        m
    };
    (area, centre)
}

/// Lays out the cell between polygon `poly`'s points in two layers (`lower`
/// and `upper` by wall point number) on the stack and calls `f` with the
/// upper polygon, the cell's faces (the lower face reversed, the upper
/// face, the sides, as OpenFOAM computes area vectors and centres), the
/// cell's centre as OpenFOAM computes it (pyramids from the mean of the
/// face centres) and its least face pyramid in cubes of `side` (negative:
/// a face points into the cell).
pub(super) fn with_prism<R>(
    poly: &[u32],
    lower: impl Fn(u32) -> [f64; 3],
    upper: impl Fn(u32) -> [f64; 3],
    side: f64,
    f: impl FnOnce(&[[f64; 3]], &[FaceGeometry], [f64; 3], f64) -> R,
) -> R {
    let n = poly.len();
    let (mut abuf, mut bbuf) = ([[0.0; 3]; MAXP], [[0.0; 3]; MAXP]);
    let mut fbuf: [FaceGeometry; MAXP + 2] = [([0.0; 3], [0.0; 3]); MAXP + 2];
    let (mut va, mut vb, mut vf) = (Vec::new(), Vec::new(), Vec::new());
    let (a, b, faces): (&mut [[f64; 3]], &mut [[f64; 3]], &mut [FaceGeometry]) = if n <= MAXP {
        (&mut abuf[..n], &mut bbuf[..n], &mut fbuf[..n + 2])
    } else {
        va.resize(n, [0.0; 3]);
        vb.resize(n, [0.0; 3]);
        vf.resize(n + 2, ([0.0; 3], [0.0; 3]));
        (&mut va, &mut vb, &mut vf)
    };
    for (j, &i) in poly.iter().enumerate() {
        a[j] = lower(i);
        b[j] = upper(i);
    }
    // The lower face points out of the cell: its polygon reversed.
    let (sa, ca) = face_geometry(a);
    faces[0] = (scale(sa, -1.0), ca);
    faces[1] = face_geometry(b);
    for j in 0..n {
        let jn = (j + 1) % n;
        faces[j + 2] = face_geometry(&[a[j], a[jn], b[jn], b[j]]);
    }
    let faces = &*faces;
    let est = scale(
        faces.iter().map(|f| f.1).fold([0.0; 3], add),
        1.0 / faces.len() as f64,
    );
    let (mut vol, mut centre) = (0.0, [0.0; 3]);
    for &(sf, cf) in faces {
        let v = dot(sf, sub(cf, est)).max(f64::MIN_POSITIVE);
        vol += v;
        centre = add_scaled(centre, add(scale(cf, 0.75), scale(est, 0.25)), v);
    }
    let c = scale(centre, 1.0 / vol);
    let pyramid = faces
        .iter()
        .map(|&(sf, cf)| dot(sf, sub(cf, c)))
        .fold(f64::INFINITY, f64::min)
        / side.powi(3);
    f(b, faces, c, pyramid)
}

/// The least face pyramid of the even cut's two end slabs of the cell
/// between the polygons `lower` and `upper` (each `slab` of the way, at the
/// surface and at the staircase, where a sheared or twisted cell is
/// thinnest; checking the slabs between too made no case valid that these
/// left invalid, on the shared models), per unit of the slab's share, in
/// cubes of `side`.
pub(super) fn end_slabs(
    poly: &[u32],
    (lower, upper): (
        impl Fn(u32) -> [f64; 3] + Copy,
        impl Fn(u32) -> [f64; 3] + Copy,
    ),
    side: f64,
    slab: f64,
) -> f64 {
    let cut = |w: f64| {
        move |i: u32| {
            let x = upper(i);
            add_scaled(x, sub(lower(i), x), w)
        }
    };
    let near = with_prism(poly, cut(slab), upper, side, |_, _, _, pyramid| pyramid);
    let far = with_prism(poly, lower, cut(1.0 - slab), side, |_, _, _, pyramid| {
        pyramid
    });
    near.min(far) / slab
}

/// How far the cell between the polygons of wall face `k` in the point
/// layers `lower` and `upper` is from having a face that points into it:
/// the least over its faces of the face's area vector dotted with the way
/// from the cell's centre to the face's, in cubes of the face's side
/// (checkMesh's face pyramids, with OpenFOAM's face and cell centres). The
/// boundary layers' cells are judged by it.
pub(super) fn cell_quality(
    wall: &super::layer::Wall,
    k: usize,
    lower: &[[f64; 3]],
    upper: &[[f64; 3]],
) -> f64 {
    with_prism(
        &wall.polys[k],
        |i| lower[i as usize],
        |i| upper[i as usize],
        wall.sides[k],
        |_, _, _, pyramid| pyramid,
    )
}
