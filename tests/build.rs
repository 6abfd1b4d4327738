//! Finds what some tests need beyond the workspace: the validation captures from outside the
//! project (`../shared/validation` beside the checkout), and QEMU with the thumbv7em target for
//! the firmware boot test. Without them those tests are compiled as ignored, with the reason
//! shown by the test runner; under CI (`CI=true`) their absence fails the build instead, so that
//! a test that did not run can never pass as one that did.

use std::path::{Path, PathBuf};
use std::process::Command;

fn ci() -> bool {
    std::env::var("CI").is_ok_and(|v| v == "true")
}

/// Why the QEMU boot test cannot run here, if it cannot.
fn qemu_missing() -> Option<String> {
    if Command::new("qemu-system-arm").arg("--version").output().map_or(true, |o| !o.status.success()) {
        return Some("qemu-system-arm is not runnable".into());
    }
    if Command::new("flip-link").output().is_err() {
        return Some("flip-link (the firmware's linker) is not installed: cargo install flip-link --locked".into());
    }
    let rustc = std::env::var_os("RUSTC").unwrap_or_else(|| "rustc".into());
    let out = Command::new(rustc).args(["--print", "target-libdir", "--target", "thumbv7em-none-eabihf"]).output();
    match out {
        Ok(o) if o.status.success() && Path::new(String::from_utf8_lossy(&o.stdout).trim()).is_dir() => None,
        _ => Some("the thumbv7em-none-eabihf target is not installed".into()),
    }
}

fn main() {
    println!("cargo:rustc-check-cfg=cfg(has_qemu)");
    println!("cargo:rerun-if-env-changed=PATH");
    match qemu_missing() {
        None => println!("cargo:rustc-cfg=has_qemu"),
        Some(why) if ci() => {
            panic!("{why}: CI must boot the firmware image (.ci/run installs QEMU, flip-link and the target)")
        }
        Some(why) => println!("cargo:warning={why}: the QEMU boot test is ignored"),
    }
    let dir =
        PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets it")).join("../../shared/validation");
    println!("cargo:rustc-check-cfg=cfg(has_validation)");
    println!("cargo:rerun-if-changed={}", dir.display());
    println!("cargo:rerun-if-env-changed=CI");
    if dir.join("realistic-2speed-s101").is_dir() && dir.join("clean-s101").is_dir() {
        println!("cargo:rustc-cfg=has_validation");
    } else if ci() {
        panic!("{} is missing: CI must run the validation tests on the captures from outside", dir.display());
    } else {
        println!("cargo:warning=validation captures not found at {}: the validation tests are ignored", dir.display());
    }
}
