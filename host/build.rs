//! Compiles the PostgreSQL records tests in as ordinary tests when a server is configured
//! (`GYROCAL_TEST_PG`) or under CI (where they must then run, and fail without a server), and as
//! ignored tests with the reason otherwise, so a machine without PostgreSQL shows them as not
//! run instead of passed.

fn main() {
    println!("cargo::rustc-check-cfg=cfg(gyrocal_test_pg)");
    println!("cargo::rerun-if-env-changed=GYROCAL_TEST_PG");
    println!("cargo::rerun-if-env-changed=CI");
    let pg = std::env::var_os("GYROCAL_TEST_PG").is_some_and(|v| !v.is_empty());
    let ci = std::env::var("CI").is_ok_and(|v| v == "true");
    if pg || ci {
        println!("cargo::rustc-cfg=gyrocal_test_pg");
    }
}
