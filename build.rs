//! Gives the shared library a SONAME (`liboctmesh.so.0`), so that programs
//! linked against it keep working across compatible releases, and makes the
//! Rust declarations of the CGNS C library (`cgnslib.h`, Debian
//! libcgns-dev) for `src/io/cgns`.

use std::path::PathBuf;

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    let os = std::env::var("CARGO_CFG_TARGET_OS").unwrap_or_default();
    if os == "linux" {
        println!("cargo:rustc-cdylib-link-arg=-Wl,-soname,liboctmesh.so.0");
    }
    cgns();
}

/// Binds the few CGNS mid-level calls the writer uses, and links libcgns.
fn cgns() {
    let include = std::env::var("CGNS_INCLUDE_DIR").unwrap_or_else(|_| "/usr/include".into());
    println!("cargo:rerun-if-env-changed=CGNS_INCLUDE_DIR");
    println!("cargo:rerun-if-env-changed=CGNS_LIB_DIR");
    if let Ok(dir) = std::env::var("CGNS_LIB_DIR") {
        println!("cargo:rustc-link-search=native={dir}");
    }
    println!("cargo:rustc-link-lib=cgns");
    let header = PathBuf::from(&include).join("cgnslib.h");
    println!("cargo:rerun-if-changed={}", header.display());
    let bindings = bindgen::Builder::default()
        // cgsize_t may be a macro (cgnstypes.h): name it as a type.
        .header_contents(
            "octmesh_cgns.h",
            &format!(
                "#include \"{}\"\ntypedef cgsize_t cg_size_type;\n",
                header.display()
            ),
        )
        .clang_arg(format!("-I{include}"))
        .allowlist_function(
            "cg_(open|close|get_error|base_write|zone_write|coord_write|section_write|\
             boco_write|boco_gridlocation_write|gopath|user_data_write|array_write|\
             descriptor_write|dataclass_write|exponents_write|gridlocation_write|family_write|fambc_write|famname_write|\
             subreg_ptset_write)",
        )
        .allowlist_type("cg_size_type")
        .allowlist_var("CG_(OK|ERROR|MODE_WRITE|MODE_READ|FILE_.*|SIZEOF_SIZE|BUILD_64BIT)")
        .default_enum_style(bindgen::EnumVariation::Consts)
        .prepend_enum_name(false)
        .layout_tests(false)
        .generate()
        .expect("cgnslib.h (Debian libcgns-dev) is needed to build octmesh");
    let out = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR"));
    bindings
        .write_to_file(out.join("cgns.rs"))
        .expect("writing the CGNS bindings");
}
