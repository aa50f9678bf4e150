# Sourced by the scripts: lets Open MPI run as root and oversubscribe the cores.
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
export OMPI_MCA_rmaps_base_oversubscribe=1
# One node, shared memory: the default PML selection probes UCX first, about
# 0.2 s of every MPI start-up on a machine without a network fabric.
export OMPI_MCA_pml="${OMPI_MCA_pml:-ob1}"
export PATH="$HOME/.cargo/bin:$PATH"
