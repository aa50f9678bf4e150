//! Gives the shared library a SONAME (`liboctmesh.so.0`), so that programs
//! linked against it keep working across compatible releases.

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    let os = std::env::var("CARGO_CFG_TARGET_OS").unwrap_or_default();
    if os == "linux" {
        println!("cargo:rustc-cdylib-link-arg=-Wl,-soname,liboctmesh.so.0");
    }
}
