//! Files octmesh writes and reads (large ones around the page cache: `direct`): leaf lists, VTK XML meshes (`vtu`) and
//! boundary faces (`vtp`), JSON
//! statistics and reports (`json`), leak paths (`leak_path`), OpenFOAM cases
//! (`openfoam`), single-file finite-element meshes gathered on rank 0 (`gathered`) for Gmsh (`gmsh`),
//! Abaqus/CalculiX (`abaqus`), Exodus II (`exodus`, through netCDF) and CGNS (`cgns`, through the CGNS
//! library), and (in `geometry::stl`) STL.

pub mod abaqus;
pub mod cgns;
pub mod exodus;
pub mod gathered;
pub mod gmsh;
pub mod json;
pub mod leak_path;
pub mod leaves;
pub mod openfoam;
pub mod vtp;
pub mod vtu;
