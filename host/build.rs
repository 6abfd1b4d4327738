//! Compiles the PostgreSQL records tests in as ordinary tests when a server is configured
//! (`GYROCAL_TEST_PG`) or under CI (where they must then run, and fail without a server), and as
//! ignored tests with the reason otherwise, so a machine without PostgreSQL shows them as not
//! run instead of passed. The same for the report layout test that needs Chromium
//! (`has_chromium`): under CI a missing Chromium fails the build.

fn main() {
    println!("cargo::rustc-check-cfg=cfg(gyrocal_test_pg)");
    println!("cargo::rerun-if-env-changed=GYROCAL_TEST_PG");
    println!("cargo::rerun-if-env-changed=CI");
    let pg = std::env::var_os("GYROCAL_TEST_PG").is_some_and(|v| !v.is_empty());
    let ci = std::env::var("CI").is_ok_and(|v| v == "true");
    if pg || ci {
        println!("cargo::rustc-cfg=gyrocal_test_pg");
    }
    println!("cargo::rustc-check-cfg=cfg(has_chromium)");
    println!("cargo::rerun-if-env-changed=PATH");
    let chromium = std::process::Command::new("chromium").arg("--version").output().is_ok_and(|o| o.status.success());
    if chromium {
        println!("cargo::rustc-cfg=has_chromium");
    } else if ci {
        panic!("chromium is not runnable: CI must lay the report out at 1400 px (.ci/run installs it)");
    }
    // PyYAML, the reader Kalibr loads its IMU file with: the Kalibr export's load test.
    println!("cargo::rustc-check-cfg=cfg(has_pyyaml)");
    let pyyaml =
        std::process::Command::new("python3").args(["-c", "import yaml"]).output().is_ok_and(|o| o.status.success());
    if pyyaml {
        println!("cargo::rustc-cfg=has_pyyaml");
    } else if ci {
        panic!("python3 with PyYAML is not runnable: CI must load the Kalibr export (.ci/run installs python3-yaml)");
    }
}
