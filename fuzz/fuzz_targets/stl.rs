#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| octmesh_fuzz::stl::run(data));
