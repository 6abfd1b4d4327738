//! The `host` program (`src/main.rs` only calls [`main`]): record, simulate, inspect and calibrate
//! the gyro exciter; apply a calibration. In the library rather than the binary's crate so that
//! the generic code both use (the JSON readers and writers of the same types, the iterators over
//! them) is compiled once: docs/performance.md, build time.
//!
//! Exit status: 0 success (for `calibrate`: calibrated, residual at the noise floor); 1 failed,
//! with a one-line `error:` on stderr; 2 wrong usage; 3 calibrated, but with structure in the
//! residual that no model explains, so the calibration is not to be trusted; 4 (`calibrate
//! --spec`) calibrated at the noise floor, but a specification limit fails.

use crate::calib;
use crate::capture::{self, Capture};
use crate::export;
use crate::files;
use crate::geometry::Pose;
use crate::link::{self, Link};
use crate::provenance::{self, Identity, Provenance, SessionManifest};
use crate::records;
use crate::session;
use crate::sim;
use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use std::fs;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

#[derive(Parser)]
#[command(
    name = "host",
    version,
    about = "Gyro calibration rig: calibrate, record, simulate, virtual-rig, inspect, apply, export, records, noise, configure-drive"
)]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Record the raw bytes of the wire to a file, optionally running one pose.
    Record {
        /// Serial port of the rig, e.g. /dev/ttyACM0.
        #[arg(long)]
        port: String,
        /// Capture file to write (never overwritten).
        #[arg(long)]
        out: PathBuf,
        /// Run this pose (1 or 2) and stop; without it, only listen.
        #[arg(long, value_parser = parse_pose)]
        pose: Option<Pose>,
        /// Base-table rate, °/s, negative for clockwise.
        #[arg(long, default_value_t = 180.0, allow_negative_numbers = true, value_parser = parse_rate)]
        rate_dps: f64,
        /// Seconds to record (at speed when running a pose).
        #[arg(long, default_value_t = 120.0, value_parser = parse_duration)]
        duration: f64,
        /// Baud rate (ignored by USB CDC-ACM).
        #[arg(long, default_value_t = link::DEFAULT_BAUD)]
        baud: u32,
        /// Tests: the link's time is a lockstep virtual rig's simulated time, stepped through
        /// this Unix socket (`host::virtual_rig::LockstepPort`); --port is that rig's pty.
        #[arg(long, hide = true, value_name = "SOCKET")]
        lockstep_clock: Option<PathBuf>,
    },
    /// Calibrate: live against the rig (--port) or from recorded captures (--replay).
    Calibrate(CalibrateArgs),
    /// Convert raw counts to rate vectors in the package frame with a calibration.
    Apply {
        /// The calibration.json written by `calibrate`.
        #[arg(long)]
        cal: PathBuf,
        /// One raw reading, x,y,z counts.
        #[arg(long, value_parser = parse_counts, allow_hyphen_values = true, conflicts_with = "capture", required_unless_present = "capture")]
        counts: Option<[i16; 3]>,
        /// A capture: prints t_s,pose,x_dps,y_dps,z_dps for every sample as CSV.
        #[arg(long)]
        capture: Option<PathBuf>,
        /// Die temperature, °C, for a calibration with a thermal model (`calibrate --replay` of a
        /// thermal session): the model at this temperature; outside its range, an error.
        #[arg(long, allow_negative_numbers = true)]
        temp_c: Option<f64>,
    },
    /// Export a calibration for a firmware or a toolchain: C header, Rust const, Kalibr YAML, JSON, CSV.
    Export {
        /// The calibration.json written by `calibrate` (default: the one `calibrate` writes
        /// without --out-dir).
        #[arg(long, default_value = "calibration/calibration.json")]
        cal: PathBuf,
        /// Output format.
        #[arg(long, value_enum)]
        format: export::Format,
        /// File to write (default: standard output).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Noise figures of a capture's static stretch (motor at rest): overlapping Allan deviation
    /// per axis, angle random walk, bias instability, rate random walk.
    Noise {
        /// Capture holding a static stretch: a static run of `host calibrate --static-s`, or of
        /// `host simulate --poses 1 --rates-dps 0`.
        #[arg(long)]
        capture: PathBuf,
        /// Calibration to turn counts into rates (default: the datasheet sensitivity).
        #[arg(long)]
        cal: Option<PathBuf>,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Tell the rig the drive train its speed loop is designed for: the gearhead, the inertia it
    /// turns, the bridge supply. Lasts until the rig resets (then the prototype's: 66:1,
    /// 0.012 kg·m², 24 V); send it after each power-up, before calibrating.
    ConfigureDrive {
        /// Serial port of the rig.
        #[arg(long)]
        port: String,
        /// Gearhead reduction, motor turns per base-table turn (66 for 66:1), 1 to 500.
        #[arg(long, value_parser = parse_gear_ratio)]
        gear_ratio: f64,
        /// Inertia the gearhead turns about the base-table axis, kg·m²: tables, magnetic gears,
        /// counterweight and gyro, not the motor's rotor (the rig adds it). 0.0001 to 1.
        #[arg(long, value_parser = parse_load_inertia)]
        load_inertia_kgm2: f64,
        /// Bridge supply, V, 6 to 48.
        #[arg(long, default_value_t = 24.0, value_parser = parse_supply)]
        supply_v: f64,
        /// Baud rate (ignored by USB CDC-ACM).
        #[arg(long, default_value_t = link::DEFAULT_BAUD)]
        baud: u32,
    },
    /// The records database: every calibration stored, listed, compared, summarised.
    Records {
        /// sqlite:PATH or postgres://… (default: $GYROCAL_DB, else
        /// sqlite:~/.local/share/gyrocal/records.sqlite). Before or after the subcommand.
        #[arg(long, global = true)]
        db: Option<String>,
        /// Output of list, show and compare: text, json or csv.
        #[arg(long, global = true, value_enum, default_value_t = records::views::Format::Text)]
        format: records::views::Format,
        #[command(subcommand)]
        command: RecordsCmd,
    },
    /// Simulate a session on the virtual exciter: a capture and, beside it, the truth.
    Simulate(SimulateArgs),
    /// The firmware's core and the simulated exciter on a pseudo-terminal, to try the live
    /// session without hardware: prints the device path, then serves `calibrate --port PATH`.
    VirtualRig(crate::virtual_rig::Options),
    /// Describe a capture: rig, settings, runs, rates, losses with their byte offsets.
    Inspect {
        /// Capture files.
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
}

/// `host calibrate`'s options.
#[derive(clap::Args)]
#[command(group(clap::ArgGroup::new("source").required(true).args(["port", "replay"])))]
struct CalibrateArgs {
    /// Serial port of the rig: runs the guided live session.
    #[arg(long, conflicts_with = "replay", requires = "sensor")]
    port: Option<String>,
    /// Capture files to compute from instead (each says which pose it holds).
    #[arg(long, num_args = 1..)]
    replay: Vec<PathBuf>,
    /// Where the captures (live), the JSON result and the report go.
    #[arg(long, default_value = "calibration")]
    out_dir: PathBuf,
    /// Live: seconds of data per run once at speed.
    #[arg(long, default_value_t = 120.0, value_parser = parse_duration)]
    duration: f64,
    /// Live: base-table rates to run in each pose, °/s, negative for clockwise. The default's
    /// three signed speeds separate every catalogued effect (docs/trust.md): two speeds tell a
    /// gyro delay from an index offset, and the scale seen at each signed speed holds three
    /// unknowns, M's, Earth's vertical rate (odd in the direction) and the filter's droop
    /// (growing with speed).
    #[arg(long, value_delimiter = ',', default_value = "180,90,-180", allow_negative_numbers = true, value_parser = parse_rate)]
    rates_dps: Vec<f64>,
    /// Live: end the session with a static run (motor off) of this many seconds in the last
    /// pose, for noise figures (Allan deviation, ARW, bias instability, RRW). An hour gives
    /// bias instability and RRW that are more than indicative.
    #[arg(long, value_parser = parse_duration, conflicts_with = "replay")]
    static_s: Option<f64>,
    /// Replay: the simulated truth to compare with (default: `x.truth.json` beside a single
    /// `x.cap`, if present).
    #[arg(long, requires = "replay")]
    truth: Option<PathBuf>,
    /// Serial number of the gyro under calibration. Required live (the operator confirms
    /// it); on replay it defaults to the session manifest beside the captures.
    #[arg(long)]
    sensor: Option<String>,
    /// Who runs the session.
    #[arg(long)]
    operator: Option<String>,
    /// Which rig runs it.
    #[arg(long)]
    rig: Option<String>,
    /// Records database the result is stored in after its files are written: sqlite:PATH or
    /// postgres://… (default: $GYROCAL_DB, else sqlite:~/.local/share/gyrocal/records.sqlite).
    #[arg(long)]
    db: Option<String>,
    /// Store the result in no records database (the files are still written): for demos,
    /// trials and tests.
    #[arg(long, conflicts_with = "db")]
    no_db: bool,
    /// Record this calibration even if one of its captures is already in a record (by
    /// SHA-256); without it such a capture is refused, naming the record.
    #[arg(long)]
    again: bool,
    /// Specification limits (JSON: sensitivity_tolerance_percent, max_tilt_deg,
    /// max_non_orthogonality_deg, max_arw_deg_per_sqrt_h, each optional): PASS/FAIL on the
    /// certificate, the summary and the record; exit 4 when a limit fails.
    #[arg(long, value_name = "FILE")]
    spec: Option<PathBuf>,
    /// Live: do not wait for Enter between poses (for scripted rigs with an automatic mount).
    #[arg(long)]
    yes: bool,
    /// Latitude of the lab, degrees (north positive): Earth's vertical rate is then known
    /// rather than fitted, which tightens every sensitivity's σ by 10-20 ppm.
    #[arg(long, allow_negative_numbers = true, value_parser = parse_latitude)]
    latitude_deg: Option<f64>,
    /// Plausible size (one σ, in the unit the notes give) of a catalogued effect the runs may
    /// not separate, replacing the built-in one, e.g. `--consider g_sensitivity=0.02` (°/s
    /// per g) for a part whose datasheet states it; 0 leaves the effect out. Repeatable.
    #[arg(long, value_name = "EFFECT=SIGMA")]
    consider: Vec<String>,
    /// Baud rate (ignored by USB CDC-ACM).
    #[arg(long, default_value_t = link::DEFAULT_BAUD)]
    baud: u32,
    /// Tests: the link's time is a lockstep virtual rig's simulated time, stepped through
    /// this Unix socket (`host::virtual_rig::LockstepPort`); --port is that rig's pty.
    #[arg(long, hide = true, requires = "port", value_name = "SOCKET")]
    lockstep_clock: Option<PathBuf>,
    /// Live: a thermal session at these chamber setpoints, °C, in order: at each the operator
    /// sets the chamber, the host waits for OUT_TEMP to settle (docs/thermal.md), then records
    /// the runs into a subfolder; the thermal model is fitted at the end.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true, value_parser = parse_setpoint, conflicts_with = "replay")]
    chamber_c: Vec<f64>,
}

/// `host simulate`'s options.
#[derive(clap::Args)]
struct SimulateArgs {
    /// Capture file to write; the truth goes to the same name with `.truth.json`.
    #[arg(long)]
    out: PathBuf,
    /// Seed: one seed is one simulated sensor.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Seconds per run, spin-up included.
    #[arg(long, default_value_t = 120.0)]
    duration: f64,
    /// Poses to run, in order.
    #[arg(long, value_delimiter = ',', default_value = "1,2", value_parser = parse_pose)]
    poses: Vec<Pose>,
    /// Base-table rates to run in each pose, °/s, negative for clockwise.
    #[arg(long, value_delimiter = ',', default_value = "180", allow_negative_numbers = true)]
    rates_dps: Vec<f64>,
    /// Gyro full scale, °/s: 250, 500 or 2000.
    #[arg(long, default_value_t = 500, value_parser = parse_full_scale)]
    full_scale: u16,
    /// Switch on an effect the ideal model lacks, NAME or NAME=VALUE (repeatable):
    /// filter_delay, filter_order, filter_cutoff_hz, delay_ms, index_offset_deg, offset_drift,
    /// speed_ripple, nonlinearity,
    /// nonlinearity_cubic, nonlinearity_square, gear_ratio_error, mystery_harmonic,
    /// mount_compliance, earth_rotation, gear_transmission, g_sensitivity, table_tilt,
    /// pose_fixture, bias_random_walk, axis_delay, rig_clock, encoder_eccentricity,
    /// encoder_ellipticity, timestamp_jitter, capture_level.
    #[arg(long = "effect")]
    effects: Vec<String>,
    /// Every effect of a real rig (the realistic set, the delays between the gyro's axes and the
    /// rig's clock) with each parameter drawn from the seed within its plausible range
    /// (docs/simulation.md); an --effect NAME=VALUE then sets that one's headline value.
    /// `--drawn-rig=SCALE` widens every size range SCALE times (0-10; not the latitude, the
    /// warm-up's time constant or the rig clock): the same seed's rig, grown.
    #[arg(long, value_name = "SCALE", num_args = 0..=1, require_equals = true, default_missing_value = "1",
          value_parser = parse_drawn_scale)]
    drawn_rig: Option<f64>,
    /// Full configuration as JSON (a `SimConfig`); overrides the options above.
    #[arg(long)]
    config: Option<PathBuf>,
    /// A thermal session: the runs at each of these chamber setpoints, °C, in order, each once
    /// the die has settled; --out is then a folder (one subfolder per setpoint, thermal.json).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true, value_parser = parse_setpoint)]
    chamber_c: Vec<f64>,
}

/// A drive value whose wire form (`to_wire`, through `DriveConfig::from_si`) lies in `range`,
/// the protocol's limit (`protocol::drive_limits`), said in the option's own units.
fn parse_drive(
    s: &str,
    to_wire: impl Fn(f64) -> u32,
    range: std::ops::RangeInclusive<u32>,
    what: &str,
) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && range.contains(&to_wire(v)) => Ok(v),
        _ => Err(format!("{s:?} is not {what}")),
    }
}

fn parse_gear_ratio(s: &str) -> Result<f64, String> {
    let wire = |v| protocol::DriveConfig::from_si(v, 0.0, 0.0).gear_ratio_milli;
    parse_drive(s, wire, protocol::drive_limits::GEAR_RATIO_MILLI, "a gear ratio from 1 to 500")
}

fn parse_load_inertia(s: &str) -> Result<f64, String> {
    let wire = |v| protocol::DriveConfig::from_si(0.0, v, 0.0).load_inertia_gcm2;
    parse_drive(s, wire, protocol::drive_limits::LOAD_INERTIA_GCM2, "an inertia from 0.0001 to 1 kg·m²")
}

fn parse_supply(s: &str) -> Result<f64, String> {
    let wire = |v| protocol::DriveConfig::from_si(0.0, 0.0, v).supply_mv;
    parse_drive(s, wire, protocol::drive_limits::SUPPLY_MV, "a supply from 6 to 48 V")
}

fn parse_latitude(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if (-90.0..=90.0).contains(&v) => Ok(v),
        _ => Err(format!("latitude must be a number of degrees within ±90, not {s:?}")),
    }
}

#[derive(Subcommand)]
enum RecordsCmd {
    /// One line per calibration, oldest first.
    List {
        /// Only this sensor's calibrations.
        #[arg(long)]
        sensor: Option<String>,
    },
    /// One calibration in full.
    Show {
        /// Record id (from `list`).
        id: i64,
    },
    /// Every parameter's change from record A to record B, in units of their combined σ.
    Compare {
        /// Earlier record.
        a: i64,
        /// Later record.
        b: i64,
    },
    /// Distributions across sensors (latest calibration of each), outliers named.
    Summary {
        /// Also write an HTML page with a histogram of each parameter.
        #[arg(long)]
        html: Option<PathBuf>,
    },
}

fn parse_pose(s: &str) -> Result<Pose, String> {
    match s {
        "1" => Ok(Pose::One),
        "2" => Ok(Pose::Two),
        _ => Err(format!("pose must be 1 or 2, not {s:?}")),
    }
}

/// A duration in seconds: finite and positive (`nan` would record forever).
fn parse_duration(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("{s:?} is not a duration: give a positive number of seconds")),
    }
}

/// A base-table rate in °/s: finite, non-zero, at most the rig's limit (`nan` would send 0).
fn parse_rate(s: &str) -> Result<f64, String> {
    use protocol::units::{dps_from_mdps, mdps_from_dps};
    let max = dps_from_mdps(protocol::MAX_RATE_MDPS);
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v != 0.0 && v.abs() <= max && mdps_from_dps(v) >= 1 => Ok(v),
        _ => Err(format!("{s:?} is not a rate: give °/s, non-zero, between -{max} and {max}")),
    }
}

fn parse_counts(s: &str) -> Result<[i16; 3], String> {
    let v: Vec<i16> = s
        .split(',')
        .map(|x| x.trim().parse::<i16>().map_err(|_| format!("{x:?} is not a count in -32768..=32767")))
        .collect::<Result<_, _>>()?;
    v.try_into().map_err(|v: Vec<i16>| format!("expected 3 counts x,y,z, got {}", v.len()))
}

/// A chamber setpoint, °C: the L3G4200D's operating range, −40…85 °C (datasheet Table 4).
fn parse_setpoint(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if (-40.0..=85.0).contains(&v) => Ok(v),
        _ => Err(format!("{s:?} is not a setpoint: give °C within the gyro's −40…85 °C")),
    }
}

fn parse_full_scale(s: &str) -> Result<u16, String> {
    match s {
        "250" | "500" | "2000" => Ok(s.parse().expect("matched digits")),
        _ => Err(format!("full scale must be 250, 500 or 2000 °/s, not {s:?}")),
    }
}

/// `--drawn-rig=SCALE`: a finite multiple of the plausible ranges, 0 to [`sim::MAX_DRAWN_SCALE`].
fn parse_drawn_scale(text: &str) -> Result<f64, String> {
    let scale: f64 = text.parse().map_err(|_| format!("{text:?} is not a number"))?;
    if (0.0..=sim::MAX_DRAWN_SCALE).contains(&scale) {
        Ok(scale)
    } else {
        Err(format!("{text} is outside 0-{}", sim::MAX_DRAWN_SCALE))
    }
}

/// The program: parses the command line, runs the command, reports an error on stderr.
pub fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(code) => code,
        Err(e) => {
            // Not eprintln!: after SIGHUP the terminal may be gone, and a failed write must not
            // turn a clean failure into a panic.
            use std::io::Write as _;
            let _ = writeln!(std::io::stderr(), "error: {e:#}");
            if e.downcast_ref::<Usage>().is_some() {
                ExitCode::from(2)
            } else {
                ExitCode::FAILURE
            }
        }
    }
}

/// Wrong usage found after parsing: a configuration the command line names is unusable. Exit 2,
/// as for clap's own usage errors.
#[derive(Debug, thiserror::Error)]
#[error("{0:#}")]
struct Usage(anyhow::Error);

fn run(cli: Cli) -> Result<ExitCode> {
    match cli.command {
        Cmd::Record { port, out, pose, rate_dps, duration, baud, lockstep_clock } => {
            record(open_link(&port, baud, lockstep_clock.as_deref())?, &out, pose, rate_dps, duration)
        }
        Cmd::Calibrate(args) => calibrate_cmd(args),
        Cmd::Noise { capture, cal, json } => noise_cmd(&capture, cal.as_deref(), json),
        Cmd::Records { db, format, command } => records_cmd(&records::DbSpec::resolve(db.as_deref())?, format, command),
        Cmd::Export { cal, format, out } => export_cmd(&cal, format, out.as_deref()),
        Cmd::Simulate(args) => simulate_cmd(args),
        Cmd::Apply { cal, counts, capture, temp_c } => apply(&cal, counts, capture.as_deref(), temp_c),
        Cmd::VirtualRig(options) => crate::virtual_rig::serve(&options).map(|()| ExitCode::SUCCESS),
        Cmd::ConfigureDrive { port, gear_ratio, load_inertia_kgm2, supply_v, baud } => {
            configure_drive_cmd(&port, gear_ratio, load_inertia_kgm2, supply_v, baud)
        }
        Cmd::Inspect { files, json } => inspect_cmd(&files, json),
    }
}

/// Where a calibration's captures come from.
enum Source {
    /// One session's captures, with the identity and start its manifest gives.
    Captures { files: Vec<PathBuf>, identity: Identity, started_utc: Option<String> },
    /// A thermal session's folder (its manifest names every setpoint's captures).
    Thermal { folder: PathBuf, identity: Identity },
}

/// `host calibrate`: a live session (`--port`, or a thermal one with `--chamber-c`) or captures
/// replayed (`--replay`, a thermal session's folder too), then the calibration.
fn calibrate_cmd(args: CalibrateArgs) -> Result<ExitCode> {
    let mut consider = calib::analysis::consider::ConsiderOverrides::default();
    for c in &args.consider {
        consider.add(c).map_err(|e| Usage(anyhow::anyhow!("--consider {c}: {e}")))?;
    }
    // Resolved first: a wrong --db must not cost a session.
    let db = if args.no_db { None } else { Some(records::DbSpec::resolve(args.db.as_deref())?) };
    // Read first too: a bad spec file must not cost a session.
    let spec = args.spec.as_deref().map(crate::spec::Spec::read).transpose().map_err(Usage)?;
    // Held until the process ends: a second calibration into this directory is refused
    // before it records or computes anything.
    let _lock = files::DirLock::acquire(&args.out_dir)?;
    let identity =
        Identity { sensor_serial: args.sensor.clone(), operator: args.operator.clone(), rig: args.rig.clone() };
    let source = match &args.port {
        Some(port) => live_session(port, &args, identity, db.as_ref())?,
        None => replayed(&args.replay, identity)?,
    };
    let opts = calib::LoopOptions { latitude_deg: args.latitude_deg, consider, ..calib::LoopOptions::default() };
    let record_to = RecordTo { db: db.as_ref(), again: args.again, spec: spec.as_ref() };
    match source {
        Source::Thermal { folder, identity } => calibrate_thermal(&folder, &args.out_dir, identity, record_to, &opts),
        Source::Captures { files, identity, started_utc } => {
            calibrate(&files, &args.out_dir, args.truth.as_deref(), identity, started_utc, record_to, &opts)
        }
    }
}

/// The guided live session on `port`: the operator checks the sensor's serial, then the runs
/// (at each chamber setpoint for a thermal session) are recorded into `--out-dir` with their
/// manifest.
fn live_session(port: &str, args: &CalibrateArgs, identity: Identity, db: Option<&records::DbSpec>) -> Result<Source> {
    let out_dir = &args.out_dir;
    let interrupted = interrupt_flag()?;
    // Checked now so the operator hears of it before the runs; the record is still attempted
    // (and the files kept) at the end.
    if let Some(Err(e)) = db.map(|db| db.open()) {
        note(&format!("warning: the records database is not usable now ({e:#}); the session runs anyway"));
    }
    let serial = identity.sensor_serial.clone().unwrap_or_default();
    // The port first: a port that cannot be opened must not leave a manifest behind, or the
    // retry in the same --out-dir would be refused.
    let mut link = open_link(port, args.baud, args.lockstep_clock.as_deref())?;
    let mut manifest = start_manifest(out_dir, identity)?;
    link.watch_interrupt(interrupted.clone());
    let mut operator: Box<dyn session::Operator> =
        if args.yes { Box::new(session::AssumeYes) } else { Box::new(session::Terminal::new()) };
    session::prompt(
        &mut link,
        &format!("Sensor under calibration: {serial}. Check it against the part's label."),
        operator.as_mut(),
        &interrupted,
    )?;
    let plan = session::plan_with_static(&Pose::ALL, &args.rates_dps, args.duration, args.static_s);
    let files = if args.chamber_c.is_empty() {
        session::record_session(&mut link, &plan, out_dir, operator.as_mut(), &interrupted)?
    } else {
        let m = crate::thermal::live::record_thermal_session(
            &mut link,
            &args.chamber_c,
            &plan,
            out_dir,
            operator.as_mut(),
            &mut crate::thermal::live::ManualChamber,
            crate::thermal::settle::SettleCriterion::default(),
            &interrupted,
        )?;
        m.paths(out_dir).into_iter().flat_map(|(_, _, f)| f).collect()
    };
    manifest.captures = files.iter().map(|f| provenance::digest_file(f)).collect::<Result<_>>()?;
    manifest.write(out_dir)?;
    Ok(if args.chamber_c.is_empty() {
        Source::Captures { files, identity: manifest.identity, started_utc: Some(manifest.started_utc) }
    } else {
        Source::Thermal { folder: out_dir.clone(), identity: manifest.identity }
    })
}

/// Captures given with `--replay`: a thermal session's folder, or captures with (or without) the
/// session manifest beside them, whose identity fills what the options leave out.
fn replayed(replay: &[PathBuf], identity: Identity) -> Result<Source> {
    if let [folder] = replay {
        if crate::thermal::manifest::ThermalManifest::read_in(folder)?.is_some() {
            return Ok(Source::Thermal { folder: folder.clone(), identity });
        }
    }
    Ok(match replay.first().map(|f| SessionManifest::read_beside(f)).transpose()?.flatten() {
        Some(m) => {
            for w in m.verify(replay)? {
                note(&format!("warning: {w}"));
            }
            Source::Captures {
                files: replay.to_vec(),
                identity: identity.or(m.identity),
                started_utc: Some(m.started_utc),
            }
        }
        None => Source::Captures { files: replay.to_vec(), identity, started_utc: None },
    })
}

/// `host simulate`: a capture of the simulated rig and its truth (a thermal session's folder
/// with `--chamber-c`), from the options or a whole `--config`.
fn simulate_cmd(args: SimulateArgs) -> Result<ExitCode> {
    let SimulateArgs { out, seed, duration, poses, rates_dps, full_scale, effects, drawn_rig, config, chamber_c } =
        args;
    let cfg = match config {
        Some(path) => {
            let text = fs::read_to_string(&path).with_context(|| format!("cannot read {}", path.display()))?;
            serde_json::from_str(&text)
                .with_context(|| format!("{} is not a simulation config", path.display()))
                .map_err(Usage)?
        }
        None => {
            let mut cfg = sim::SimConfig::with_runs(
                seed,
                session::plan(&poses, &rates_dps, duration)
                    .iter()
                    .map(|r| sim::RunSpec { pose: r.pose, rate_dps: r.rate_dps, duration_s: r.duration_s })
                    .collect(),
            );
            cfg.gyro.full_scale = match full_scale {
                250 => protocol::FullScale::Dps250,
                2000 => protocol::FullScale::Dps2000,
                _ => protocol::FullScale::Dps500,
            };
            if let Some(scale) = drawn_rig {
                cfg.effects = sim::Effects::drawn_scaled(&mut sim::effects_rng(seed), scale);
            }
            for e in &effects {
                cfg.effects.enable(e).map_err(|e| Usage(e.into()))?;
            }
            cfg
        }
    };
    if chamber_c.is_empty() {
        simulate(&cfg, &out)
    } else {
        simulate_thermal(&cfg, &chamber_c, &out)
    }
}

/// `host noise`: the noise figures (Allan deviation) of a capture's static stretch.
fn noise_cmd(capture: &Path, cal: Option<&Path>, json: bool) -> Result<ExitCode> {
    let cap = read_capture(capture)?;
    let cal = cal.map(load_calibration).transpose()?;
    let report =
        crate::allan::capture_noise(&cap, cal.as_ref()).map_err(|e| anyhow::anyhow!("{}: {e}", capture.display()))?;
    if json {
        files::stdout(&format!("{}\n", serde_json::to_string_pretty(&report)?))?;
    } else {
        files::stdout(&crate::text::wrap(&report.to_string(), crate::text::TEXT_WIDTH))?;
    }
    Ok(ExitCode::SUCCESS)
}

/// `host export`: a calibration in a firmware's or a tool's format, to a file or standard output.
fn export_cmd(cal: &Path, format: export::Format, out: Option<&Path>) -> Result<ExitCode> {
    let text = fs::read_to_string(cal).with_context(|| format!("cannot read calibration {}", cal.display()))?;
    let e = export::Export::from_json(&text).with_context(|| format!("{} is not a calibration", cal.display()))?;
    let rendered = e.render(format)?;
    match out {
        Some(path) => {
            files::write_atomic(path, rendered)?;
            note(&format!("wrote {}", path.display()));
        }
        None => files::stdout(&rendered)?,
    }
    Ok(ExitCode::SUCCESS)
}

/// `host configure-drive`: the rig's speed loop designed for the gearhead, load and supply given.
fn configure_drive_cmd(
    port: &str,
    gear_ratio: f64,
    load_inertia_kgm2: f64,
    supply_v: f64,
    baud: u32,
) -> Result<ExitCode> {
    let mut link = Link::new(link::open_port(port, baud)?, port);
    session::identify(&mut link)?;
    session::configure_drive(&mut link, protocol::DriveConfig::from_si(gear_ratio, load_inertia_kgm2, supply_v))?;
    note(&format!(
        "the rig on {port} designs its speed loop for a {gear_ratio}:1 gearhead, {load_inertia_kgm2} kg·m² of load, {supply_v} V until it resets"
    ));
    Ok(ExitCode::SUCCESS)
}

/// `host inspect`: what each capture holds, its losses and its runs.
fn inspect_cmd(files: &[PathBuf], json: bool) -> Result<ExitCode> {
    for f in files {
        let cap = read_capture(f)?;
        let report = crate::inspect::inspect(&f.display().to_string(), &cap);
        if json {
            files::stdout(&format!("{}\n", serde_json::to_string_pretty(&report)?))?;
        } else {
            files::stdout(&report.to_string())?;
        }
    }
    Ok(ExitCode::SUCCESS)
}

fn records_cmd(spec: &records::DbSpec, format: records::views::Format, cmd: RecordsCmd) -> Result<ExitCode> {
    use records::{store, views};
    // Reading never creates a database.
    let mut c = spec.open_existing()?;
    let get = |c: &mut dyn records::db::Conn, id: i64| -> Result<records::Record> {
        store::get(c, id)?.with_context(|| format!("no record {id} in {spec}"))
    };
    let text = match cmd {
        RecordsCmd::List { sensor } => views::list_as(&store::list(c.as_mut(), sensor.as_deref())?, format),
        RecordsCmd::Show { id } => {
            let r = get(c.as_mut(), id)?;
            let history = records::history(c.as_mut(), &r, Some(id))?;
            views::show_as(&r, &history, format)
        }
        RecordsCmd::Compare { a, b } => views::compare_as(&get(c.as_mut(), a)?, &get(c.as_mut(), b)?, format),
        RecordsCmd::Summary { html } => {
            let latest = store::latest_per_sensor(c.as_mut())?;
            if let Some(path) = html {
                files::write_atomic(&path, views::summary_html(&latest))?;
                note(&format!("wrote {}", path.display()));
            }
            views::summary(&latest)
        }
    };
    files::stdout(&text)?;
    Ok(ExitCode::SUCCESS)
}

/// Reads and decodes a capture file.
fn read_capture(path: &Path) -> Result<Capture> {
    let file = fs::File::open(path).with_context(|| format!("cannot read capture {}", path.display()))?;
    capture::decode_reader(file).with_context(|| format!("cannot read capture {}", path.display()))
}

/// Ctrl-C, SIGTERM and SIGHUP set a flag that the session loops check, so the motor is stopped
/// and the file closed.
fn interrupt_flag() -> Result<Arc<AtomicBool>> {
    let flag = Arc::new(AtomicBool::new(false));
    let f = flag.clone();
    ctrlc::set_handler(move || {
        // The first signal stops the run and waits (bounded) for the table to stop; a second one
        // is the operator insisting: leave now, the rig's link watchdog cuts the drive 2 s later.
        if f.swap(true, Ordering::SeqCst) {
            use std::io::Write as _;
            let _ = writeln!(
                std::io::stderr(),
                "\nerror: interrupted again: leaving without waiting for the table to stop (the rig cuts the drive 2 s after the last heartbeat)"
            );
            std::process::exit(1);
        }
    })
    .context("installing the Ctrl-C handler")?;
    Ok(flag)
}

/// The link to the rig on `port`: a serial port in wall-clock time, or with `lockstep` (tests)
/// a lockstep virtual rig's pty in its simulated time.
fn open_link(port: &str, baud: u32, lockstep: Option<&Path>) -> Result<Link<Box<dyn link::Port>>> {
    Ok(match lockstep {
        None => Link::new(Box::new(link::open_port(port, baud)?), port),
        Some(socket) => {
            let p = crate::virtual_rig::LockstepPort::connect(port, socket)?;
            let clock = p.clock();
            Link::with_clock(Box::new(p), port, Box::new(clock))
        }
    })
}

fn record(
    mut link: Link<Box<dyn link::Port>>,
    out: &Path,
    pose: Option<Pose>,
    rate_dps: f64,
    duration_s: f64,
) -> Result<ExitCode> {
    let interrupted = interrupt_flag()?;
    link.watch_interrupt(interrupted.clone());
    match pose {
        Some(pose) => {
            let run = session::RunPlan { pose, rate_dps, duration_s };
            let progress = indicatif::ProgressBar::new(0);
            session::record_run(&mut link, &run, out, &progress, &interrupted)?;
        }
        None => {
            link.record_to_named(Some(Box::new(session::create_capture(out)?)), out.display().to_string())?;
            session::identify(&mut link)?;
            let start = link.now();
            while (link.now() - start).as_secs_f64() < duration_s && !interrupted.load(Ordering::SeqCst) {
                link.poll(|_| {})?;
            }
            link.record_to(None)?;
        }
    }
    note(&format!("saved {}", out.display()));
    if interrupted.load(Ordering::SeqCst) {
        bail!("interrupted; capture so far kept in {}", out.display());
    }
    Ok(ExitCode::SUCCESS)
}

/// Writes the manifest of a live session before its first capture, so even an interrupted
/// session names its sensor; an existing one means the directory holds another session.
fn start_manifest(out_dir: &Path, identity: Identity) -> Result<SessionManifest> {
    fs::create_dir_all(out_dir).with_context(|| format!("cannot create {}", out_dir.display()))?;
    if out_dir.join(provenance::MANIFEST_FILE).exists() {
        bail!(
            "{} already holds a session ({}): choose another --out-dir",
            out_dir.display(),
            provenance::MANIFEST_FILE
        );
    }
    let manifest = SessionManifest::start(identity);
    manifest.write(out_dir)?;
    Ok(manifest)
}

/// Where `calibrate` records its result: nowhere (`--no-db`) or a database, and whether a
/// capture already recorded there may be recorded again (`--again`).
struct RecordTo<'a> {
    db: Option<&'a records::DbSpec>,
    again: bool,
    /// `--spec`: the limits the result is checked against.
    spec: Option<&'a crate::spec::Spec>,
}

/// Decodes the captures, reports their losses, runs the closed loop (fit, residual diagnostics,
/// effect models), writes `calibration.json` (with its provenance), `loop.json` and
/// `report.html`; the exit status carries the verdict.
fn calibrate(
    files: &[PathBuf],
    out_dir: &Path,
    truth_path: Option<&Path>,
    identity: Identity,
    session_started: Option<String>,
    record_to: RecordTo<'_>,
    opts: &calib::LoopOptions,
) -> Result<ExitCode> {
    let RecordTo { db, again, spec } = record_to;
    let mut loaded = crate::replay::load(files, opts.cal.kinematics, &mut |line| note(line))?;
    let prov = Provenance::gather(identity, session_started, &loaded.captures);
    if let (Some(db), false) = (db, again) {
        refuse_recorded_captures(db, &prov)?;
    }
    let runs = loaded.take_moving_runs();
    let truth = load_truth(files, truth_path)?;
    fs::create_dir_all(out_dir).with_context(|| format!("cannot create {}", out_dir.display()))?;
    let lr = calib::close_loop_reconstructed(&runs, loaded.kinematics, opts, truth.as_ref().map(sim::Truth::sensor))
        .context("calibration failed")?;
    let noise = crate::allan::session_noise(loaded.captures.iter().map(|(_, c)| c), &lr.final_report().calibration());
    // Files and the record first, the summary last: a closed or full standard output must not
    // cost the result.
    let json = out_dir.join("calibration.json");
    let mut value = prov.attach(serde_json::to_value(lr.final_report())?);
    if let (Some(n), Some(obj)) = (&noise, value.as_object_mut()) {
        obj.insert("noise".into(), serde_json::to_value(n)?);
    }
    if let (Some(g), Some(obj)) = (g_sensitivity(&lr), value.as_object_mut()) {
        obj.insert(export::G_SENSITIVITY_KEY.into(), serde_json::to_value(g)?);
    }
    let warm_up = temperature_sections(&lr, &runs, &mut value)?;
    let json_text = serde_json::to_string_pretty(&value)?;
    files::write_atomic(&json, &json_text)?;
    let loop_json = out_dir.join("loop.json");
    files::write_atomic(&loop_json, serde_json::to_string(&lr)?)?;
    let checks = spec.map(|s| s.check(lr.final_report(), noise.as_ref()));
    let verdict = match lr.verdict() {
        calib::Verdict::AtNoiseFloor => "at noise floor",
        calib::Verdict::UnexplainedStructure if lr.unvouched.is_some() => "not vouched for",
        calib::Verdict::UnexplainedStructure => "unexplained structure",
    };
    let mut rec = records::record_from(lr.final_report(), &prov, verdict, json_text);
    rec.noise = noise.iter().flat_map(|n| &n.axes).map(records::NoiseRow::from).collect();
    if let Some(c) = &checks {
        let pass = if crate::spec::passed(c) { 1.0 } else { 0.0 };
        rec.params.push(records::Param { name: "spec_pass".into(), value: pass, sigma: None, unit: "1".into() });
    }
    // The sensor's previous calibrations, from the database this one is recorded into.
    let history = records::history_before_recording(db, &rec);
    let extra = checks.as_deref().map(crate::spec::html_section).unwrap_or_default()
        + &crate::certificate::html_section(lr.final_report(), &history)
        + &noise.as_ref().map(|n| n.html_section()).unwrap_or_default()
        + &warm_up.as_ref().map(|w| w.html_section()).unwrap_or_default();
    let html = write_report(out_dir, &lr, &prov, &extra)
        .with_context(|| format!("cannot write the report in {}", out_dir.display()))?;
    note(&format!("wrote {}, {} and {}", json.display(), loop_json.display(), html.display()));
    let recorded = match db {
        None => {
            note("not recorded (--no-db)");
            Ok(())
        }
        Some(db) => match records::store_record(db, &rec) {
            Ok(id) => {
                note(&format!("recorded as {id} in {db}"));
                Ok(())
            }
            Err(e) => Err(anyhow::anyhow!(
                "the calibration is saved in {} but was not recorded in {db}: {e:#}",
                out_dir.display()
            )),
        },
    };
    let mut summary = format!("{prov}\n{}", lr.summary());
    if let Some(n) = &noise {
        summary.push_str(&format!("\nNoise figures:\n{}", n.figures()));
    }
    if let Some(c) = &checks {
        summary.push('\n');
        summary.push_str(&crate::spec::text(c));
    }
    if let Some(w) = &warm_up {
        summary.push('\n');
        summary.push_str(&w.text());
    }
    files::stdout(&crate::text::wrap(&summary, crate::text::TEXT_WIDTH))?;
    recorded?;
    Ok(match (lr.verdict(), checks.as_deref().is_some_and(|c| !crate::spec::passed(c))) {
        // A result not to be trusted says so first, whatever the limits.
        (calib::Verdict::UnexplainedStructure, _) => ExitCode::from(3),
        (calib::Verdict::AtNoiseFloor, true) => ExitCode::from(4),
        (calib::Verdict::AtNoiseFloor, false) => ExitCode::SUCCESS,
    })
}

/// The sections of `calibration.json` that rest on the die temperature: the drift model a
/// firmware can apply (`export::DriftModel`) and the session's own warm-up coefficients
/// (`thermal::warm_up`), which are returned for the summary and the report.
fn temperature_sections(
    lr: &calib::LoopReport,
    runs: &[capture::Run],
    value: &mut serde_json::Value,
) -> Result<Option<crate::thermal::warm_up::WarmUp>> {
    let out_temp_raw: Vec<i8> = runs.iter().flat_map(|r| r.temperatures.iter().map(|t| t.raw)).collect();
    let warm_up = crate::thermal::warm_up::WarmUp::of(lr, &out_temp_raw);
    // The runs' mean OUT_TEMP: where the temperature drift's column is zero (calib::engine::loop_data).
    let out_temp_mean = warm_up.as_ref().map(|w| w.reference_out_temp_lsb);
    if let (Some(d), Some(obj)) = (export::DriftModel::of(lr, out_temp_mean), value.as_object_mut()) {
        obj.insert(export::DRIFT_MODEL_KEY.into(), serde_json::to_value(d)?);
    }
    if let (Some(w), Some(obj)) = (&warm_up, value.as_object_mut()) {
        obj.insert(crate::thermal::warm_up::CALIBRATION_KEY.into(), serde_json::to_value(w)?);
    }
    Ok(warm_up)
}

/// `host calibrate --replay <thermal folder>`: each setpoint calibrated into its own subfolder of
/// `out_dir` (its files, record and summary as for one session), then the thermal model over
/// them in `out_dir/calibration.json` and on standard output. The exit status is the worst
/// setpoint's.
fn calibrate_thermal(
    dir: &Path,
    out_dir: &Path,
    identity: Identity,
    record_to: RecordTo<'_>,
    opts: &calib::LoopOptions,
) -> Result<ExitCode> {
    use crate::thermal::{manifest::ThermalManifest, present, session as thermal};
    let manifest = ThermalManifest::read_in(dir)?.context("not a thermal session folder")?;
    let mut setpoints = Vec::new();
    let mut status = ExitCode::SUCCESS;
    for (setpoint_c, sub, files) in manifest.paths(dir) {
        let name = sub.file_name().context("a setpoint folder without a name")?;
        let sub_out = out_dir.join(name);
        note(&format!("setpoint {setpoint_c} °C: {}", sub.display()));
        let rec = RecordTo { db: record_to.db, again: record_to.again, spec: record_to.spec };
        let code = calibrate(&files, &sub_out, None, identity.clone(), None, rec, opts)
            .with_context(|| format!("setpoint {setpoint_c} °C"))?;
        // The worst status is the session's: 3 (not to be trusted) before 4 (a limit fails).
        let rank = |c: ExitCode| [ExitCode::SUCCESS, ExitCode::from(4), ExitCode::from(3)].iter().position(|&r| r == c);
        if rank(code) > rank(status) {
            status = code;
        }
        let (cal, value) = thermal::setpoint_from_files(setpoint_c, &sub_out, &files)?;
        setpoints.push((cal.with_noise_floor(code != ExitCode::from(3)), value));
    }
    // Every setpoint's captures: the thermal model's record names them all.
    let captures: Vec<String> = setpoints
        .iter()
        .filter_map(|(_, v)| Provenance::from_calibration_json(&v.to_string()))
        .flat_map(|p| p.captures.into_iter().map(|c| c.sha256))
        .collect();
    let (model, beside) = thermal::write_model(out_dir, setpoints)?;
    note(&format!(
        "wrote {} with the thermal model and {}",
        out_dir.join("calibration.json").display(),
        out_dir.join(thermal::THERMAL_REPORT).display()
    ));
    let recorded = match record_to.db {
        None => {
            note("thermal model not recorded (--no-db)");
            Ok(())
        }
        Some(db) => record_thermal(db, out_dir, &captures, status == ExitCode::SUCCESS)
            .map(|id| note(&format!("thermal model recorded as {id} in {db}"))),
    };
    files::stdout(&(present::text(&model) + &crate::thermal::warm_up::beside_model_text(&beside)))?;
    recorded?;
    Ok(status)
}

/// Records a thermal calibration (`out_dir/calibration.json`: the base setpoint's calibration
/// with the thermal model) with every setpoint's captures; returns its id.
fn record_thermal(
    db: &records::DbSpec,
    out_dir: &Path,
    captures: &[String],
    every_setpoint_passed: bool,
) -> Result<i64> {
    let path = out_dir.join("calibration.json");
    let text = fs::read_to_string(&path).with_context(|| format!("cannot read {}", path.display()))?;
    let report: calib::CalReport =
        serde_json::from_str(&text).with_context(|| format!("{} is not a calibration report", path.display()))?;
    let prov =
        Provenance::from_calibration_json(&text).with_context(|| format!("{} holds no provenance", path.display()))?;
    let verdict = if every_setpoint_passed { "at noise floor" } else { "a setpoint did not pass (see its record)" };
    let mut rec = records::record_from(&report, &prov, verdict, text);
    rec.captures_sha256 = captures.join(",");
    records::store_record(db, &rec).with_context(|| {
        format!("the thermal calibration is saved in {} but was not recorded in {db}", out_dir.display())
    })
}

/// Refuses captures already in a record of `db` (same SHA-256), naming the record: the same
/// data recorded twice would count twice in the production statistics. A database that cannot
/// be read now is left to the record step, which keeps the files and says so.
fn refuse_recorded_captures(db: &records::DbSpec, prov: &Provenance) -> Result<()> {
    let Ok(mut c) = db.open_existing() else { return Ok(()) };
    for cap in &prov.captures {
        let ids = records::store::records_with_capture(c.as_mut(), &cap.sha256)?;
        if let Some(id) = ids.first() {
            bail!(
                "{} is already in record {id} of {db} (sha256 {}…): give --again to calibrate and record it again",
                cap.file,
                &cap.sha256[..12.min(cap.sha256.len())]
            );
        }
    }
    Ok(())
}

/// The fitted g-sensitivity of the final model, row = gyro axis, column = package axis of the
/// specific force, °/s per g; `None` when the model does not hold it. Read from the effect's
/// reported parameters, `g-sensitivity along package K, A` (calib's `GSensitivity::reported`).
fn g_sensitivity(lr: &calib::LoopReport) -> Option<[[f64; 3]; 3]> {
    use calib::result::axes::AXES;
    let params = &lr.steps.last()?.effect_params;
    let find = |a: usize, k: usize| {
        let name = format!("g-sensitivity along package {}, {}", AXES[k], AXES[a]);
        params.iter().find(|p| p.name == name).map(|p| p.estimate.value)
    };
    let rows: Option<Vec<[f64; 3]>> = (0..3).map(|a| Some([find(a, 0)?, find(a, 1)?, find(a, 2)?])).collect();
    rows.map(|r| [r[0], r[1], r[2]])
}

/// Writes `out_dir/report.html`, with the provenance block and `extra` under its title, and its
/// figures `report-figN.svg`. The loop's report is drawn into a private temporary directory, the
/// page completed in memory, and every file renamed into `out_dir` whole.
fn write_report(out_dir: &Path, lr: &calib::LoopReport, prov: &Provenance, extra: &str) -> Result<PathBuf> {
    let tmp = tempfile::Builder::new().prefix(".report.").tempdir_in(out_dir)?;
    let drawn = crate::present::write_report(tmp.path(), lr)?;
    let page = fs::read_to_string(&drawn)?;
    let html = out_dir.join("report.html");
    for svg in fs::read_dir(tmp.path())? {
        let svg = svg?.path();
        if svg != drawn {
            let name = svg.file_name().context("a figure without a name")?;
            files::write_atomic(&out_dir.join(name), fs::read(&svg)?)?;
        }
    }
    files::write_atomic(&html, prov.into_report(&page, extra))?;
    Ok(html)
}

/// An informational line on standard error. Not `eprintln!`, which panics when standard error
/// is closed: a line nobody can read must not fail a calibration whose files are written.
fn note(line: &str) {
    use std::io::Write as _;
    let _ = writeln!(std::io::stderr(), "{line}");
}

/// The truth of a simulated capture: `--truth`, or `x.truth.json` beside a single `x.cap`.
fn load_truth(files: &[PathBuf], explicit: Option<&Path>) -> Result<Option<sim::Truth>> {
    let path = match (explicit, files) {
        (Some(p), _) => p.to_path_buf(),
        (None, [one]) if truth_path(one).exists() => truth_path(one),
        _ => return Ok(None),
    };
    let text = fs::read_to_string(&path).with_context(|| format!("cannot read truth {}", path.display()))?;
    let truth = serde_json::from_str(&text).with_context(|| format!("{} is not a simulation truth", path.display()))?;
    note(&format!("comparing with the simulated truth in {}", path.display()));
    Ok(Some(truth))
}

/// Loads a calibration from `calibrate`'s JSON (the full report) or a bare calibration.
fn load_calibration(path: &Path) -> Result<calib::Calibration> {
    let text = fs::read_to_string(path).with_context(|| format!("cannot read calibration {}", path.display()))?;
    if let Ok(report) = serde_json::from_str::<calib::CalReport>(&text) {
        return Ok(report.calibration());
    }
    calib::Calibration::from_json(&text).with_context(|| format!("{} is not a calibration", path.display()))
}

/// The calibration at `temp_c` from the thermal model in `path`.
fn thermal_calibration(path: &Path, temp_c: f64) -> Result<calib::Calibration> {
    let text = fs::read_to_string(path).with_context(|| format!("cannot read calibration {}", path.display()))?;
    let model = crate::thermal::session::model_in(&text).with_context(|| format!("{}", path.display()))?.with_context(
        || format!("{} holds no thermal model (--temp-c needs the calibration of a thermal session)", path.display()),
    )?;
    model.calibration_at(temp_c).with_context(|| format!("{}", path.display()))
}

fn apply(
    cal_path: &Path,
    counts: Option<[i16; 3]>,
    capture_path: Option<&Path>,
    temp_c: Option<f64>,
) -> Result<ExitCode> {
    let cal = match temp_c {
        None => load_calibration(cal_path)?,
        Some(t) => thermal_calibration(cal_path, t)?,
    };
    if let Some(c) = counts {
        let w = cal.apply(c);
        files::stdout(&format!("{:.4},{:.4},{:.4}\n", w[0], w[1], w[2]))?;
        return Ok(ExitCode::SUCCESS);
    }
    let path = capture_path.expect("clap requires --counts or --capture");
    let cap = read_capture(path)?;
    let samples: usize = cap.runs.iter().map(|r| r.samples.len()).sum();
    if samples == 0 {
        bail!(
            "{} holds no sample of any run ({} bytes, {} valid frames, {} runs): nothing to apply the calibration to",
            path.display(),
            cap.loss.bytes,
            cap.loss.frames_ok,
            cap.runs.len()
        );
    }
    if let Some(run) = cap.runs.iter().find(|r| r.gyro.full_scale != cal.full_scale) {
        bail!(
            "{} was recorded at ±{} °/s but the calibration is for ±{} °/s",
            path.display(),
            run.gyro.full_scale.range_dps(),
            cal.full_scale.range_dps()
        );
    }
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    use std::io::Write as _;
    writeln!(out, "t_s,pose,x_dps,y_dps,z_dps")?;
    for run in &cap.runs {
        for s in &run.samples {
            let w = cal.apply(s.rate_counts);
            writeln!(out, "{:.6},{},{:.4},{:.4},{:.4}", s.t_us as f64 * 1e-6, run.pose.number(), w[0], w[1], w[2])?;
        }
    }
    out.flush()?;
    Ok(ExitCode::SUCCESS)
}

/// Path of the truth written beside a simulated capture: `x.cap` → `x.truth.json`.
fn truth_path(capture: &Path) -> PathBuf {
    capture.with_extension("truth.json")
}

/// `host simulate --chamber-c`: one folder per setpoint and the thermal manifest.
fn simulate_thermal(cfg: &sim::SimConfig, setpoints_c: &[f64], out: &Path) -> Result<ExitCode> {
    cfg.validate().map_err(|e| Usage(anyhow::Error::new(e).context("invalid simulation")))?;
    let m = crate::thermal::session::simulate_programme(cfg, setpoints_c, out)?;
    let waits: Vec<String> =
        m.setpoints.iter().map(|s| format!("{} °C after {:.0} s", s.setpoint_c, s.settle_s.unwrap_or(0.0))).collect();
    note(&format!("wrote {} setpoints in {} (settled: {})", m.setpoints.len(), out.display(), waits.join(", ")));
    Ok(ExitCode::SUCCESS)
}

fn simulate(cfg: &sim::SimConfig, out: &Path) -> Result<ExitCode> {
    cfg.validate().map_err(|e| Usage(anyhow::Error::new(e).context("invalid simulation")))?;
    let file = fs::File::create(out).with_context(|| format!("cannot create {}", out.display()))?;
    let truth = sim::simulate_to(cfg, &mut std::io::BufWriter::new(file))
        .with_context(|| format!("writing {}", out.display()))?;
    let tp = truth_path(out);
    files::write_atomic(&tp, serde_json::to_string_pretty(&truth)?)?;
    note(&format!("wrote {} ({} runs, seed {}) and {}", out.display(), cfg.runs.len(), cfg.seed, tp.display()));
    Ok(ExitCode::SUCCESS)
}
