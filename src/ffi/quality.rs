//! The mesh's quality ([`crate::mesh::quality`]) through the C API.

use super::handle::octmesh_t;
use super::{non_null, octmesh_gloidx_t, octmesh_status_t, with_mut, write_out};
use crate::error::{Error, ErrorKind};
use crate::mesh::quality::HISTOGRAM_BINS;

// The C struct's histogram has a literal length (cbindgen reads no
// constants from other modules).
const _: () = assert!(HISTOGRAM_BINS == 20);

/// The quality figures of a mesh, the same on every rank (and on every
/// number of ranks).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct octmesh_mesh_quality_t {
    /// Elements over all ranks.
    pub elements: octmesh_gloidx_t,
    /// The smallest scaled Jacobian (Knupp's: at each corner of an element
    /// the determinant of its three unit edge vectors, the element's value
    /// the minimum over its 8 corners; 1 for a cube, at most 0 when
    /// inverted).
    pub scaled_jacobian_min: f64,
    /// Elements whose scaled Jacobian is at most 0.
    pub inverted_elements: octmesh_gloidx_t,
    /// Elements per bin of width 0.1 over [-1, 1]: bin `k` holds
    /// `-1 + k/10 <= J < -1 + (k+1)/10`, the last bin also 1.
    pub scaled_jacobian_histogram: [octmesh_gloidx_t; 20],
    /// Internal faces, faces between ranks counted once.
    pub internal_faces: octmesh_gloidx_t,
    /// The largest non-orthogonality, degrees (`checkMesh`'s "Max").
    pub non_orthogonality_max: f64,
    /// The angle of the mean cosine over the internal faces, degrees
    /// (`checkMesh`'s "average").
    pub non_orthogonality_average: f64,
    /// The largest skewness over all faces (`checkMesh`'s "Max skewness").
    pub skewness_max: f64,
}

/// Measures the current mesh's quality and writes it to `*out`: the scaled
/// Jacobian of each element from its node coordinates, and `checkMesh`'s
/// non-orthogonality and skewness over the finite-volume faces (those of
/// `octmesh_mesh_build_faces`; after `octmesh_mesh_snap`, measured on the
/// moved points as `checkMesh` measures the written OpenFOAM case). Needs
/// a mesh. Collective.
///
/// \param[in]  h    the handle
/// \param[out] out  the figures, the same on every rank
#[no_mangle]
pub extern "C" fn octmesh_mesh_get_quality(
    h: *mut octmesh_t,
    out: *mut octmesh_mesh_quality_t,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let checked = non_null(out, "out").and_then(|_| {
            h.session.mesh().map(|_| ()).ok_or_else(|| {
                Error::new(
                    ErrorKind::State,
                    "there is no mesh: call octmesh_mesh_build first",
                )
            })
        });
        h.agree(checked)?;
        let q = h.session.quality()?;
        let n = |x: u64| x as octmesh_gloidx_t;
        let mut histogram = [0; 20];
        for (to, &from) in histogram
            .iter_mut()
            .zip(&q.scaled_jacobian_histogram.counts)
        {
            *to = n(from);
        }
        write_out(
            out,
            octmesh_mesh_quality_t {
                elements: n(q.elements),
                scaled_jacobian_min: q.scaled_jacobian_min,
                inverted_elements: n(q.inverted_elements),
                scaled_jacobian_histogram: histogram,
                internal_faces: n(q.internal_faces),
                non_orthogonality_max: q.non_orthogonality_max,
                non_orthogonality_average: q.non_orthogonality_average,
                skewness_max: q.skewness_max,
            },
        );
        Ok(())
    })
}
