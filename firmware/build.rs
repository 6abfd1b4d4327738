//! Linker scripts for the MCU image only: host builds (tests, the virtual rig) are untouched.

use std::{env, fs, path::PathBuf};

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    if env::var("CARGO_CFG_TARGET_OS").as_deref() != Ok("none") {
        return;
    }
    // memory.x lives at the workspace root; cortex-m-rt's link.x includes it from the search path.
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("OUT_DIR"));
    let memory_x = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("manifest dir")).join("../memory.x");
    println!("cargo:rerun-if-changed={}", memory_x.display());
    fs::copy(&memory_x, out.join("memory.x")).expect("copy memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rustc-link-arg-bins=--nmagic");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
}
