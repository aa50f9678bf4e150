//! Snapping the mesh to the surface ([`crate::mesh::snap`]) through the C
//! API.

use super::handle::octmesh_t;
use super::{non_null, octmesh_gloidx_t, octmesh_status_t, with_mut, write_out};
use crate::error::Error;
use crate::mesh::snap::{SnapOptions, SnapReport};

/// What `octmesh_mesh_snap` did, over all ranks (each node counted once),
/// the same on every rank.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct octmesh_snap_report_t {
    /// Independent nodes on the surface patch.
    pub surface_nodes: octmesh_gloidx_t,
    /// Of those, the ones moved onto the surface.
    pub snapped: octmesh_gloidx_t,
    /// Moved part of the way (no valid position nearer the surface).
    pub partial: octmesh_gloidx_t,
    /// Not moved (no valid position, on a side of the domain too, or no
    /// surface within reach).
    pub unsnapped: octmesh_gloidx_t,
    /// Snapped nodes that went to a feature edge or corner.
    pub feature_nodes: octmesh_gloidx_t,
    /// Interior nodes the relaxation moved.
    pub relaxed_nodes: octmesh_gloidx_t,
    /// Elements that depend on a partly or not snapped surface node.
    pub reported_elements: octmesh_gloidx_t,
    /// The smallest scaled Jacobian over all elements afterwards.
    pub min_scaled_jacobian: f64,
}

impl From<&SnapReport> for octmesh_snap_report_t {
    fn from(r: &SnapReport) -> Self {
        let n = |x: u64| x as octmesh_gloidx_t;
        octmesh_snap_report_t {
            surface_nodes: n(r.surface_nodes),
            snapped: n(r.snapped),
            partial: n(r.partial),
            unsnapped: n(r.unsnapped),
            feature_nodes: n(r.feature_nodes),
            relaxed_nodes: n(r.relaxed_nodes),
            reported_elements: n(r.reported_elements),
            min_scaled_jacobian: r.min_scaled_jacobian,
        }
    }
}

/// Snaps the current mesh to the surface: every node on the surface patch
/// moves to the closest point of the surface (to a feature edge or corner
/// where the surface is sharper than `feature_angle`), scaled back where an
/// element would have a corner with a scaled Jacobian below `min_jacobian`
/// (0.001 keeps the elements valid and near the surface; 0.1 keeps
/// OpenFOAM's skewness below 4), and the
/// interior nodes within `layers` element layers are relaxed for
/// `iterations` iterations. Hanging nodes stay the mean of their
/// dependencies. The coordinates, the VTU and the OpenFOAM output then
/// give the moved positions (arrays handed out before are replaced). The
/// positions are the same bits on any number of ranks. With
/// `octmesh_mesh_set_conforming` on, the conforming mesh is built and
/// snapped instead (by rank 0, with the same rules and report): the
/// single-file meshes written next are snapped, the mesh's own arrays keep
/// the lattice positions. Needs a mesh kept inside or outside and the
/// surface. Collective; every rank must pass the same values.
///
/// \param[in] h              the handle
/// \param[in] feature_angle  degrees, 0 to 180 (30 is usual; 180: no
///                           features)
/// \param[in] layers         element layers relaxed, 0 to 100 (2 is usual)
/// \param[in] iterations     relaxation iterations, 0 to 1000 (3 is usual)
/// \param[in] min_jacobian   the least scaled Jacobian of an element's
///                           corner afterwards, above 0 and at most 0.5
#[no_mangle]
pub extern "C" fn octmesh_mesh_snap(
    h: *mut octmesh_t,
    feature_angle: f64,
    layers: i32,
    iterations: i32,
    min_jacobian: f64,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let count = |v: i32, what: &str| {
            u32::try_from(v)
                .map_err(|_| Error::invalid(format!("{what} must not be negative (got {v})")))
        };
        let opts = count(layers, "layers").and_then(|l| {
            Ok(SnapOptions {
                feature_angle_deg: feature_angle,
                layers: l,
                iterations: count(iterations, "iterations")?,
                min_jacobian,
            })
        });
        let opts = h.agree(opts)?;
        h.session.snap(&opts).map(|_| ())
    })
}

/// Writes what the snap of the current mesh did to `*out`. Needs a mesh
/// snapped by `octmesh_mesh_snap`. Collective.
///
/// \param[in]  h    the handle
/// \param[out] out  the counts, the same on every rank
#[no_mangle]
pub extern "C" fn octmesh_mesh_get_snap_report(
    h: *mut octmesh_t,
    out: *mut octmesh_snap_report_t,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let checked = non_null(out, "out").and_then(|_| {
            h.session.current_snap().map(|_| ()).ok_or_else(|| {
                Error::new(
                    crate::error::ErrorKind::State,
                    "the mesh is not snapped: call octmesh_mesh_snap first",
                )
            })
        });
        h.agree(checked)?;
        if let Some(r) = h.session.current_snap() {
            write_out(out, octmesh_snap_report_t::from(r));
        }
        Ok(())
    })
}
