//! Surfaces: from an STL file, from the caller's triangles, or built in.
//!
//! A new surface replaces the old one; the octree and mesh are kept (a
//! later mesh classifies against the new surface).

use std::ffi::{c_char, CStr};

use super::handle::octmesh_t;
use super::{
    non_null, octmesh_gloidx_t, octmesh_locidx_t, octmesh_status_t, path_arg, slice_arg, with_mut,
};
use crate::error::{Error, Result};
use crate::geometry::{shapes, stl, Surface, Triangle};

/// Installs a surface read (or not) on every rank.
fn install(h: &mut octmesh_t, name: &str, loaded: Result<Surface>) -> Result<()> {
    h.session.set_surface(name, loaded)
}

/// Reads the surface from an STL file (ASCII or binary); every rank reads
/// the file. Collective: a failure on any rank (a file missing on one node)
/// fails on every rank.
///
/// \param[in] h     the handle
/// \param[in] path  the file's path, NUL-terminated
#[no_mangle]
pub extern "C" fn octmesh_surface_from_stl(
    h: *mut octmesh_t,
    path: *const c_char,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let path = path_arg(path, "path");
        let name = path
            .as_ref()
            .map_or(String::new(), |p| p.display().to_string());
        let loaded = path.and_then(|p| stl::read_stl_file(&p));
        install(h, &name, loaded)
    })
}

/// Reads several surfaces as one, each a part with its own wall patch and
/// levels (`octmesh_octree_refine_surface_part`): STL files or built-in
/// names, like the command's surface argument followed by `--surface` for
/// each further one. A part is named after its file's stem, or its solids
/// when an ASCII file names them. Collective: a failure on any rank fails
/// on every rank.
///
/// \param[in] h      the handle
/// \param[in] n      number of surfaces, > 0
/// \param[in] specs  n NUL-terminated paths or built-in names
#[no_mangle]
pub extern "C" fn octmesh_surface_from_files(
    h: *mut octmesh_t,
    n: octmesh_locidx_t,
    specs: *const *const c_char,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let specs: Result<Vec<String>> = (|| {
            if n < 1 {
                return Err(Error::invalid(format!("n must be positive, got {n}")));
            }
            // SAFETY: NULL or n pointers (requirement of the C API).
            let ptrs = unsafe { super::slice_arg(specs, n as usize, "specs") }?;
            ptrs.iter()
                .map(|&p| super::str_arg(p, "specs[i]").map(str::to_string))
                .collect()
        })();
        let name = specs.as_ref().map_or(String::new(), |s| s.join(" + "));
        let loaded = specs.and_then(|s| crate::geometry::load_surfaces(&s));
        install(h, &name, loaded)
    })
}

/// Sets the surface from the caller's triangles. The data is copied.
/// Collective; each rank passes the whole surface.
///
/// \param[in] h     the handle
/// \param[in] ntri  number of triangles, > 0
/// \param[in] xyz   9 * ntri doubles: x, y, z of the three vertices of
///                  each triangle, user units
#[no_mangle]
pub extern "C" fn octmesh_surface_from_triangles(
    h: *mut octmesh_t,
    ntri: octmesh_gloidx_t,
    xyz: *const f64,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let loaded = non_null(xyz, "xyz").and_then(|_| {
            if ntri <= 0 || ntri as u64 > (isize::MAX as u64) / 72 {
                return Err(Error::invalid(format!("ntri must be positive, got {ntri}")));
            }
            // SAFETY: 9 * ntri values (requirement of the C API).
            let v = unsafe { slice_arg(xyz, 9 * ntri as usize, "xyz") }?;
            let tris = v
                .chunks_exact(9)
                .map(|t| Triangle::new([t[0], t[1], t[2]], [t[3], t[4], t[5]], [t[6], t[7], t[8]]))
                .collect();
            Surface::new(tris)
        });
        install(h, "triangles", loaded)
    })
}

/// Sets a built-in surface: `"sphere"` (radius 1 at the origin, 20,480
/// triangles), `"torus"` (radii 1 and 0.35, 9,216 triangles) or `"hull"`
/// (a Wigley hull of length 1 along x, beam 0.1, draft 0.0625, freeboard
/// 0.05, 7,870 triangles). Collective.
///
/// \param[in] h     the handle
/// \param[in] name  `"sphere"`, `"torus"` or `"hull"`, NUL-terminated
#[no_mangle]
pub extern "C" fn octmesh_surface_builtin(
    h: *mut octmesh_t,
    name: *const c_char,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let loaded = non_null(name, "name").and_then(|_| {
            // SAFETY: non-NULL, NUL-terminated (requirement of the C API).
            let name = unsafe { CStr::from_ptr(name) }.to_bytes();
            let name = String::from_utf8_lossy(name);
            shapes::builtin(&name).ok_or_else(|| {
                Error::invalid(format!(
                    "unknown built-in surface '{name}' (expected {})",
                    shapes::BUILTIN_NAMES.join(", ")
                ))
            })
        });
        let n = if name.is_null() {
            String::new()
        } else {
            // SAFETY: as above.
            unsafe { CStr::from_ptr(name) }
                .to_string_lossy()
                .into_owned()
        };
        install(h, &n, loaded)
    })
}
