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
    /// The largest skewness of the internal faces (`meshQualityDict`'s
    /// `maxInternalSkewness`, 4 by default, limits it).
    pub internal_skewness_max: f64,
    /// The largest skewness of the boundary faces (`maxBoundarySkewness`,
    /// 20).
    pub boundary_skewness_max: f64,
    /// The smallest cell determinant (`checkMesh`'s "Cell determinant";
    /// 1 for a cube; `minDeterminant`, 0.001).
    pub determinant_min: f64,
    /// The mean cell determinant.
    pub determinant_average: f64,
    /// The smallest face interpolation weight (0.5 between equal cubes;
    /// `minFaceWeight`, 0.05).
    pub face_weight_min: f64,
    /// The mean interpolation weight of the internal faces.
    pub face_weight_average: f64,
    /// The smallest ratio of a face's cells' volumes (`minVolRatio`, 0.01).
    pub volume_ratio_min: f64,
    /// The mean volume ratio of the internal faces.
    pub volume_ratio_average: f64,
    /// The smallest face flatness (1 for planar faces).
    pub face_flatness_min: f64,
    /// The mean face flatness over every face.
    pub face_flatness_average: f64,
    /// The smallest face twist (`minTwist`, 0.02; 1 for planar faces normal
    /// to the line between their cells' centres).
    pub face_twist_min: f64,
    /// Internal faces more non-orthogonal than 65 degrees.
    pub non_orthogonal_faces: octmesh_gloidx_t,
    /// Internal faces more skewed than 4.
    pub skewed_internal_faces: octmesh_gloidx_t,
    /// Boundary faces more skewed than 20.
    pub skewed_boundary_faces: octmesh_gloidx_t,
    /// Cells whose determinant is below 0.001.
    pub low_determinant_cells: octmesh_gloidx_t,
    /// Internal faces whose interpolation weight is below 0.05.
    pub low_weight_faces: octmesh_gloidx_t,
    /// Internal faces whose cells' volume ratio is below 0.01.
    pub low_volume_ratio_faces: octmesh_gloidx_t,
    /// Faces twisted below 0.02.
    pub twisted_faces: octmesh_gloidx_t,
}

/// Measures the current mesh's quality and writes it to `*out`: the scaled
/// Jacobian of each element from its node coordinates, and `checkMesh`'s
/// face and cell figures (non-orthogonality, skewness, determinant,
/// interpolation weight, volume ratio, flatness, twist) with the counts
/// against `meshQualityDict`'s default limits, over the finite-volume faces (those of
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
                internal_skewness_max: q.internal_skewness_max,
                boundary_skewness_max: q.boundary_skewness_max,
                determinant_min: q.determinant_min,
                determinant_average: q.determinant_average,
                face_weight_min: q.face_weight_min,
                face_weight_average: q.face_weight_average,
                volume_ratio_min: q.volume_ratio_min,
                volume_ratio_average: q.volume_ratio_average,
                face_flatness_min: q.face_flatness_min,
                face_flatness_average: q.face_flatness_average,
                face_twist_min: q.face_twist_min,
                non_orthogonal_faces: n(q.limits.non_orthogonal_faces),
                skewed_internal_faces: n(q.limits.skewed_internal_faces),
                skewed_boundary_faces: n(q.limits.skewed_boundary_faces),
                low_determinant_cells: n(q.limits.low_determinant_cells),
                low_weight_faces: n(q.limits.low_weight_faces),
                low_volume_ratio_faces: n(q.limits.low_volume_ratio_faces),
                twisted_faces: n(q.limits.twisted_faces),
            },
        );
        Ok(())
    })
}
