#!/usr/bin/python3
"""Solves a Poisson problem with dolfinx on a hexahedral Gmsh MSH 4.1 file.

An oracle for octmesh's meshes: a finite-element code without hanging-node
support reads the file through Gmsh's API (dolfinx.io.gmshio), builds the
trilinear (Q1) space on its hexahedra and solves -laplace(u) = f with u
prescribed on the nodes of the physical surfaces (the patches), for two
manufactured solutions:

- linear: u = 1 + x' + 2 y' + 3 z'. The patch test: on a conforming mesh the
  discrete solution is u at every node, to rounding. Its gradient has a
  component across every face, so at a hanging node (a corner of the fine
  elements the coarse neighbour does not have) the fine and the coarse side
  disagree and the test fails.
- smooth: u = sin(2 x' + 0.5) cos(1.5 y') exp(z'), whose L2 error falls
  about 4 times per halving of the elements on conforming meshes.

x' = (x - x0) / L are the coordinates in a frame (by default the nodes'
bounding box: its lower corner and largest extent; --frame gives it, so that
meshes of different levels solve for the same function). Only the physical
surfaces fix values: faces used once that are no patch (the two sides of a
2:1 interface, read as a conforming code reads them) stay free.

Prints one line per field:
  poisson_dolfinx: field NAME, cells C, dofs D, fixed F, max_nodal_error E, l2_error R
with the largest nodal error and the L2 error, both relative to the exact
solution's largest nodal value and L2 norm. Serial (one process).
"""

import argparse
import logging
import sys

import numpy as np


def field(name, x, lib):
    """The manufactured solution at the frame coordinates x (lib: numpy or ufl)."""
    if name == "linear":
        return 1.0 + x[0] + 2.0 * x[1] + 3.0 * x[2]
    return lib.sin(2.0 * x[0] + 0.5) * lib.cos(1.5 * x[1]) * lib.exp(x[2])


def read(path):
    """The dolfinx mesh and its facet tags, read through Gmsh."""
    import gmsh
    from mpi4py import MPI
    from dolfinx.io import gmshio

    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.open(path)
    mesh, _, facets = gmshio.model_to_mesh(gmsh.model, MPI.COMM_SELF, 0, gdim=3)
    gmsh.finalize()
    return mesh, facets


def solve(mesh, facets, frame, name):
    import ufl
    from dolfinx import fem
    from dolfinx.fem.petsc import LinearProblem

    origin, length = np.array(frame[:3]), frame[3]
    V = fem.FunctionSpace(mesh, ("Q", 1))
    xs = ufl.SpatialCoordinate(mesh)
    # The frame as constants, so that one compiled form serves every mesh.
    o, s = fem.Constant(mesh, origin), fem.Constant(mesh, 1.0 / length)
    exact = field(name, [(xs[k] - o[k]) * s for k in range(3)], ufl)

    def exact_np(x):
        return field(name, [(x[k] - origin[k]) / length for k in range(3)], np)

    fdim = mesh.topology.dim - 1
    fixed = fem.locate_dofs_topological(V, fdim, facets.indices)
    g = fem.Function(V)
    g.interpolate(exact_np)
    bc = fem.dirichletbc(g, fixed)

    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    f = -ufl.div(ufl.grad(exact))
    dx = ufl.dx(metadata={"quadrature_degree": 6})
    a = ufl.inner(ufl.grad(u), ufl.grad(v)) * ufl.dx
    L = f * v * dx
    options = {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}
    uh = LinearProblem(a, L, bcs=[bc], petsc_options=options).solve()

    nodal = np.abs(uh.x.array - g.x.array).max() / np.abs(g.x.array).max()
    err2 = fem.assemble_scalar(fem.form((uh - exact) ** 2 * dx))
    norm2 = fem.assemble_scalar(fem.form(exact**2 * dx))
    cells = mesh.topology.index_map(mesh.topology.dim).size_local
    dofs = V.dofmap.index_map.size_local
    print(
        f"poisson_dolfinx: field {name}, cells {cells}, dofs {dofs}, fixed {len(fixed)}, "
        f"max_nodal_error {nodal:.6e}, l2_error {np.sqrt(err2 / norm2):.6e}"
    )


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("msh", help="a Gmsh MSH 4.1 file of hexahedra with physical surfaces")
    p.add_argument("--field", choices=["linear", "smooth", "both"], default="both")
    p.add_argument("--frame", help="X0,Y0,Z0,L: the frame of the manufactured solutions")
    args = p.parse_args()
    # The form compiler's build log.
    logging.disable(logging.INFO)
    mesh, facets = read(args.msh)
    if len(facets.indices) == 0:
        sys.exit(f"{args.msh}: no boundary faces in a physical surface")
    if args.frame:
        frame = [float(t) for t in args.frame.split(",")]
    else:
        x = mesh.geometry.x
        lo, hi = x.min(axis=0), x.max(axis=0)
        frame = [*lo, float((hi - lo).max())]
    names = ["linear", "smooth"] if args.field == "both" else [args.field]
    for name in names:
        solve(mesh, facets, frame, name)


if __name__ == "__main__":
    main()
