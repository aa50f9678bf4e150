#![no_main]

libfuzzer_sys::fuzz_target!(
    init: octmesh_fuzz::api::init_mpi(),
    |data: &[u8]| octmesh_fuzz::api::run(data)
);
