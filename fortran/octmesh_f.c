/* C side of the Fortran module `octmesh`: converts a Fortran communicator
 * handle (INTEGER, or comm%MPI_VAL with mpi_f08) to a C MPI_Comm. Done in
 * C because MPI_Comm_f2c may be a macro (MPICH). */
#include <mpi.h>
#include "octmesh.h"

octmesh_status_t octmesh_create_f(MPI_Fint comm, const octmesh_options_t *opts, octmesh_t **out) {
  return octmesh_create(MPI_Comm_f2c(comm), opts, out);
}
