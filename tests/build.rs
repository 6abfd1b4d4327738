//! Finds the validation captures from outside the project (`../shared/validation` beside the
//! checkout). Without them the validation tests are compiled as ignored, with the reason shown
//! by the test runner; under CI (`CI=true`) their absence fails the build instead, so that a test
//! that did not run can never pass as one that did.

use std::path::PathBuf;

fn main() {
    let dir =
        PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets it")).join("../../shared/validation");
    println!("cargo:rustc-check-cfg=cfg(has_validation)");
    println!("cargo:rerun-if-changed={}", dir.display());
    println!("cargo:rerun-if-env-changed=CI");
    if dir.join("realistic-2speed-s101").is_dir() && dir.join("clean-s101").is_dir() {
        println!("cargo:rustc-cfg=has_validation");
    } else if std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!("{} is missing: CI must run the validation tests on the captures from outside", dir.display());
    } else {
        println!("cargo:warning=validation captures not found at {}: the validation tests are ignored", dir.display());
    }
}
