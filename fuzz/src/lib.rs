//! Bodies of the fuzz targets, plain functions so that
//! `tests/fuzz_regression.rs` can replay inputs without libFuzzer.

pub mod api;
pub mod stl;
