//! `host`: record, simulate, inspect and calibrate the gyro exciter; apply a calibration. The
//! program is the library's `cli` module (exit statuses there).

fn main() -> std::process::ExitCode {
    host::cli::main()
}
