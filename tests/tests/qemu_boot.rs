//! The firmware's QEMU image (`--features qemu`) booted in `qemu-system-arm -machine
//! netduinoplus2`: the rtic app, the portable core and the simulated plant all run on the
//! emulated Cortex-M4, and this test talks to it over its USART1 as a host would: Hello at
//! power-up, commands acknowledged, a run at 0.5 Hz started and stopped, every byte valid.
//!
//! Needs `qemu-system-arm` (Debian: `apt-get install qemu-system-arm`) and the
//! `thumbv7em-none-eabihf` target; builds the image itself, into its own target directory so the
//! outer `cargo test` holds no lock it needs. Without them it fails under CI (`CI` set) and is
//! reported as not run elsewhere.

use protocol::{
    encode_frame, Ack, CmdResult, Command, Counters, Direction, Edge, Event, GyroConfig, RigMsg, SeqTracker, StartRun,
    StreamDecoder, ENCODER_COUNTS_PER_REV, MAX_FRAME_LEN, PROTOCOL_VERSION, TIMESTAMP_HZ,
};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command as Process, Stdio};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

const QEMU: &str = "qemu-system-arm";

/// The run: 180 °/s (0.5 Hz), 162 000 counts/s at 324 000 counts/rev.
const RATE_MDPS: u32 = 180_000;
const TARGET_CPS: i32 = 162_000;

/// Wall-clock spacing of heartbeats. The rig stops a run after 2 s of its time without a host
/// frame; under `-icount` the emulation runs a few times faster than real time at most, so 50 ms
/// of wall time stays well inside that.
const HEARTBEAT: Duration = Duration::from_millis(50);

/// Rig time held at speed before the Stop: a full turn (2 s) plus margin, so every θ2 is seen at
/// full rate.
const HOLD_US: u32 = 2_500_000;

/// Bound on the whole session (≈ 7 s of rig time: 2 s ramp up, the hold, 2 s ramp down).
const SESSION_LIMIT: Duration = Duration::from_secs(45);

/// The gyro model runs 1.2 % fast: 800 Hz × 1.012 is a 1 235.2 µs period, so consecutive
/// timestamps (1 µs timer, floor) are 1 235 or 1 236 µs apart.
const SAMPLE_PERIOD_US: std::ops::RangeInclusive<u32> = 1_235..=1_236;

/// What this machine lacks to build and boot the image, if anything.
fn missing_prerequisite() -> Option<String> {
    if let Err(e) = Process::new(QEMU).arg("--version").output() {
        return Some(format!("{QEMU} is not runnable ({e})"));
    }
    // The firmware's linker (.cargo/config.toml); it runs, and fails on no input, when present.
    if let Err(e) = Process::new("flip-link").output() {
        return Some(format!("flip-link is not runnable ({e}): cargo install flip-link --locked"));
    }
    let rustc = std::env::var_os("RUSTC").unwrap_or_else(|| "rustc".into());
    let libdir = Process::new(rustc).args(["--print", "target-libdir", "--target", "thumbv7em-none-eabihf"]).output();
    match libdir {
        Ok(o) if o.status.success() && Path::new(String::from_utf8_lossy(&o.stdout).trim()).is_dir() => None,
        _ => Some("the thumbv7em-none-eabihf target is not installed".into()),
    }
}

/// Builds the QEMU image with `features` (the same cargo that runs this test) and copies it to
/// `firmware-<features>.elf`: the tests of this file share one target directory, and the build
/// writes one path whatever the features, so building and copying hold a lock.
fn build_image(features: &str) -> PathBuf {
    static BUILD: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _one_at_a_time = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    let workspace = Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("workspace root");
    let target_dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("qemu-image");
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let out = Process::new(cargo)
        .current_dir(workspace)
        .args(["build", "-p", "firmware", "--release", "--target", "thumbv7em-none-eabihf"])
        .args(["--features", features])
        .env("CARGO_TARGET_DIR", &target_dir)
        .output()
        .expect("run cargo");
    assert!(
        out.status.success(),
        "building the QEMU image failed (needs `rustup target add thumbv7em-none-eabihf`):\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let image = target_dir.join(format!("firmware-{features}.elf"));
    std::fs::copy(target_dir.join("thumbv7em-none-eabihf/release/firmware"), &image).expect("copy the image");
    image
}

/// QEMU with the image, USART1 on its stdin/stdout. `-icount shift=0,sleep=off` derives QEMU's
/// clock from the instruction count: QEMU 7.2's real-time TIM3 interrupts arrive at ≈ 150 Hz
/// instead of 1 kHz (firmware/README.md, "QEMU"), and the instruction clock is reproducible.
struct Qemu {
    child: Child,
    stdin: ChildStdin,
    bytes: Receiver<Vec<u8>>,
}

impl Qemu {
    fn boot(image: &Path) -> Qemu {
        let mut child = Process::new(QEMU)
            .args(["-machine", "netduinoplus2", "-nographic", "-monitor", "none"])
            .args(["-icount", "shift=0,sleep=off", "-serial", "stdio", "-kernel"])
            .arg(image)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("spawn qemu-system-arm");
        let stdin = child.stdin.take().expect("stdin");
        let mut stdout = child.stdout.take().expect("stdout");
        let (tx, bytes) = mpsc::channel();
        std::thread::spawn(move || {
            let mut buf = [0u8; 4096];
            while let Ok(n @ 1..) = stdout.read(&mut buf) {
                if tx.send(buf[..n].to_vec()).is_err() {
                    break;
                }
            }
        });
        Qemu { child, stdin, bytes }
    }
}

impl Drop for Qemu {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Everything the host saw, in order.
#[derive(Default)]
struct Stream {
    decoder: StreamDecoder,
    seq: SeqTracker,
    frames: Vec<(u16, RigMsg)>,
    errors: Vec<String>,
    missing: u64,
    bytes: usize,
}

impl Stream {
    fn feed(&mut self, bytes: &[u8]) {
        self.bytes += bytes.len();
        let Stream { decoder, seq, frames, errors, missing, .. } = self;
        decoder.feed::<RigMsg>(bytes, |e| match e {
            Event::Frame { seq: s, msg, .. } => {
                *missing += u64::from(seq.observe(s));
                frames.push((s, msg));
            }
            Event::Error { offset, error, .. } => errors.push(format!("{offset}: {error}")),
        });
    }

    fn ack(&self, cmd_seq: u16) -> Option<CmdResult> {
        self.frames.iter().find_map(|(_, m)| match m {
            RigMsg::Ack(Ack { cmd_seq: s, result }) if *s == cmd_seq => Some(*result),
            _ => None,
        })
    }

    fn msgs(&self) -> impl DoubleEndedIterator<Item = &RigMsg> {
        self.frames.iter().map(|(_, m)| m)
    }
}

/// What the session is waiting for next.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    Boot,
    SpinUp,
    /// At speed since this sample time.
    Hold {
        since_us: u32,
    },
    SpinDown,
    /// Run over; one more Counters frame to check the totals against.
    Tally {
        counters_seen: usize,
    },
    Done,
}

/// Timestamp of the latest sample.
fn last_sample_us(stream: &Stream) -> u32 {
    stream
        .msgs()
        .rev()
        .find_map(|m| match m {
            RigMsg::Sample(s) => Some(s.t_us),
            _ => None,
        })
        .expect("samples flow")
}

#[test]
#[cfg_attr(
    not(has_qemu),
    ignore = "needs qemu-system-arm, flip-link and the thumbv7em-none-eabihf target (.ci/run installs them)"
)]
fn qemu_image_boots_and_speaks_the_protocol() {
    if let Some(missing) = missing_prerequisite() {
        // CI (`.ci/run`, which runs with CI=true) installs both, so there a missing one is a
        // failure; on a developer's machine the test says what to install and stands aside, so
        // that `cargo test --workspace` works on a fresh checkout.
        let how = "install it to run this test: `rustup target add thumbv7em-none-eabihf`, \
                   `apt-get install qemu-system-arm` (`.ci/run` does both)";
        if std::env::var_os("CI").is_some() {
            panic!("{missing}: {how}");
        }
        eprintln!("qemu_image_boots_and_speaks_the_protocol NOT RUN: {missing}; {how}");
        return;
    }
    let image = build_image("qemu");
    let mut qemu = Qemu::boot(&image);
    let mut stream = Stream::default();
    let mut next_cmd = 1u16;
    let mut send = |stdin: &mut ChildStdin, cmd: Command| {
        let seq = next_cmd;
        next_cmd += 1;
        let mut buf = [0u8; MAX_FRAME_LEN];
        let n = encode_frame(seq, &cmd, &mut buf).expect("command fits");
        stdin.write_all(&buf[..n]).and_then(|()| stdin.flush()).expect("write to qemu");
        seq
    };
    let counters_count = |s: &Stream| s.msgs().filter(|m| matches!(m, RigMsg::Counters(_))).count();

    let started = Instant::now();
    let mut phase = Phase::Boot;
    let (mut identify, mut configure, mut start, mut stop) = (0, 0, 0, 0);
    let mut beat = Instant::now();
    while phase != Phase::Done {
        assert!(
            started.elapsed() < SESSION_LIMIT,
            "session stuck in {phase:?} after {:?}: {} bytes, {} frames, last {:?}",
            started.elapsed(),
            stream.bytes,
            stream.frames.len(),
            stream.frames.last()
        );
        match qemu.bytes.recv_timeout(Duration::from_millis(10)) {
            Ok(bytes) => stream.feed(&bytes),
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => {
                panic!("qemu exited: {:?}", qemu.child.try_wait())
            }
        }
        let running = matches!(phase, Phase::SpinUp | Phase::Hold { .. } | Phase::SpinDown);
        if running && beat.elapsed() >= HEARTBEAT {
            send(&mut qemu.stdin, Command::Heartbeat);
            beat = Instant::now();
        }
        phase = match phase {
            Phase::Boot if stream.msgs().any(|m| matches!(m, RigMsg::Hello(_))) => {
                identify = send(&mut qemu.stdin, Command::Identify);
                configure = send(&mut qemu.stdin, Command::ConfigureGyro(GyroConfig::DEFAULT));
                start = send(
                    &mut qemu.stdin,
                    Command::Start(StartRun { rate_mdps: RATE_MDPS, direction: Direction::Ccw, run_tag: 1 }),
                );
                Phase::SpinUp
            }
            Phase::SpinUp
                if stream.msgs().any(|m| {
                    matches!(m, RigMsg::Motor(ms) if ms.run_tag == 1
                        && ms.setpoint_cps == TARGET_CPS
                        && (ms.speed_cps - TARGET_CPS).abs() <= TARGET_CPS / 1000)
                }) =>
            {
                Phase::Hold { since_us: last_sample_us(&stream) }
            }
            Phase::Hold { since_us } if last_sample_us(&stream).wrapping_sub(since_us) >= HOLD_US => {
                stop = send(&mut qemu.stdin, Command::Stop);
                Phase::SpinDown
            }
            Phase::SpinDown if stream.msgs().any(|m| matches!(m, RigMsg::RunStopped(r) if r.run_tag == 1)) => {
                Phase::Tally { counters_seen: counters_count(&stream) }
            }
            Phase::Tally { counters_seen } if counters_count(&stream) > counters_seen => Phase::Done,
            p => p,
        };
    }
    let wall = started.elapsed();
    drop(qemu);

    // Every byte decoded, no frame missing.
    assert_eq!(stream.errors, Vec::<String>::new(), "invalid bytes on the wire");
    assert_eq!(stream.missing, 0, "sequence gaps");
    let (seq0, first) = &stream.frames[0];
    let hello = match first {
        RigMsg::Hello(h) => *h,
        other => panic!("first frame is {other:?}, not Hello"),
    };
    assert_eq!(*seq0, 0, "power-up Hello is frame 0");
    assert_eq!(
        (hello.protocol_version, hello.encoder_counts_per_rev, hello.timestamp_hz, hello.gyro),
        (PROTOCOL_VERSION, ENCODER_COUNTS_PER_REV, TIMESTAMP_HZ, GyroConfig::DEFAULT)
    );
    assert_eq!(hello.firmware, firmware::FIRMWARE_VERSION);

    // Commands: acknowledged in order, the run announced and ended.
    for (name, seq) in [("Identify", identify), ("ConfigureGyro", configure), ("Start", start), ("Stop", stop)] {
        assert_eq!(stream.ack(seq), Some(CmdResult::Ok), "{name} (seq {seq})");
    }
    assert_eq!(
        stream.msgs().filter(|m| matches!(m, RigMsg::Hello(_))).count(),
        3,
        "power-up Hello, and one each for Identify and ConfigureGyro (the settings now in force)"
    );
    assert!(stream.msgs().any(|m| matches!(m, RigMsg::RunStarted(r) if r.run_tag == 1 && r.rate_mdps == RATE_MDPS)));
    assert!(
        !stream.msgs().any(|m| matches!(m, RigMsg::Fault(_))),
        "no fault: {:?}",
        stream.msgs().find(|m| matches!(m, RigMsg::Fault(_)))
    );

    // Samples: one per gyro period, timestamps strictly increasing through TIM5's wrap (the
    // image starts it 3 s short of 2^32).
    let samples: Vec<_> = stream
        .msgs()
        .filter_map(|m| match m {
            RigMsg::Sample(s) => Some(*s),
            _ => None,
        })
        .collect();
    let gaps: Vec<u32> = samples.windows(2).map(|w| w[1].t_us.wrapping_sub(w[0].t_us)).collect();
    if let Some(bad) = gaps.iter().position(|g| !SAMPLE_PERIOD_US.contains(g)) {
        panic!("sample {} follows after {} µs", bad + 1, gaps[bad]);
    }
    assert!(samples.windows(2).any(|w| w[1].t_us < w[0].t_us), "TIM5 wrapped during the session");
    assert!(samples.iter().all(|s| s.status == 0), "no stale or overrun sample");
    // The table turned: pose 1 at 0.5 Hz puts ±147 + 104 °/s on every axis (EXCITER.md).
    let peak = samples.iter().map(|s| s.rate_counts[0]).max().unwrap_or(0);
    assert!((12_000..=15_000).contains(&peak), "x peak {peak} counts (251 °/s at 17.5 m°/s per count is 14 343)");

    // Index: the plate passed, edges alternate.
    let edges: Vec<Edge> = stream
        .msgs()
        .filter_map(|m| match m {
            RigMsg::Index(e) => Some(e.edge),
            _ => None,
        })
        .collect();
    assert!(edges.len() >= 2, "{} index edges", edges.len());
    assert!(edges.windows(2).all(|w| w[0] != w[1]), "edges alternate: {edges:?}");

    // Counters: each one's totals are exactly what the host received before it.
    let mut counters = 0;
    for (i, (seq, m)) in stream.frames.iter().enumerate() {
        if let RigMsg::Counters(c) = m {
            let before = &stream.frames[..i];
            let samples_before = before.iter().filter(|(_, m)| matches!(m, RigMsg::Sample(_))).count();
            assert_eq!(
                *c,
                Counters {
                    t_us: c.t_us,
                    frames_sent: u32::from(*seq),
                    queue_drops: 0,
                    samples_read: samples_before as u32,
                    gyro_overruns: 0,
                    spi_errors: 0,
                    rx_errors: 0,
                },
                "Counters frame {seq} against the {i} frames before it"
            );
            assert_eq!(i, usize::from(*seq));
            counters += 1;
        }
    }
    assert!(counters >= 6, "{counters} Counters frames (1 Hz over ≈ 7 s)");
    eprintln!(
        "qemu: {} bytes, {} frames, {} samples, {} index edges, {counters} counters, 0 errors, \
         {:.1} s of rig time in {wall:.1?}",
        stream.bytes,
        stream.frames.len(),
        samples.len(),
        edges.len(),
        f64::from(samples.last().unwrap().t_us.wrapping_sub(samples[0].t_us)) * 1e-6,
    );
}

/// B5 on the emulated MCU: a panic makes the motor safe before anything else, through
/// `firmware::safe_state::make_motor_safe` (enable low, then PWM 0), and the HardFault it ends in
/// does it again. The image built with `qemu-panic-test` panics 100 ms into its simulated time;
/// QEMU's STM32F405 has no GPIO or TIM1 model, so the image's stand-ins for the bridge enable
/// and the PWM report each write on USART1, which is what this test reads.
#[test]
#[cfg_attr(
    not(has_qemu),
    ignore = "needs qemu-system-arm, flip-link and the thumbv7em-none-eabihf target (.ci/run installs them)"
)]
fn qemu_panic_and_hardfault_make_the_motor_safe() {
    if let Some(missing) = missing_prerequisite() {
        if std::env::var_os("CI").is_some() {
            panic!("{missing}");
        }
        eprintln!("qemu_panic_and_hardfault_make_the_motor_safe NOT RUN: {missing}");
        return;
    }
    let image = build_image("qemu-panic-test");
    let qemu = Qemu::boot(&image);
    const EXPECTED: &str = "\nsafe state (panic): enable low, pwm 0\npanic: qemu-panic-test: a deliberate panic\n\
                            \nsafe state (HardFault): enable low, pwm 0\n";
    let mut seen = Vec::new();
    let started = Instant::now();
    let text = loop {
        let text = String::from_utf8_lossy(&seen).into_owned();
        if text.contains("safe state (HardFault)") && text.ends_with('\n') {
            break text;
        }
        // A hang guard: the panic comes 100 ms into the image's simulated time.
        assert!(started.elapsed() < SESSION_LIMIT, "no safe-state report after {:?}: {text:?}", started.elapsed());
        match qemu.bytes.recv_timeout(Duration::from_millis(10)) {
            Ok(bytes) => seen.extend(bytes),
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => panic!("qemu exited: {text:?}"),
        }
    };
    let report = &text[text.find("\nsafe state (panic)").expect("the panic's report")..];
    // The report ends with the HardFault's line; the reset that follows restarts the image.
    let end = report.find("(HardFault): enable low, pwm 0\n").expect("the HardFault's report") + 31;
    assert_eq!(&report[..end], EXPECTED);
    eprintln!("qemu: {:?} after {:?}", &report[..end], started.elapsed());
}

/// Issue 28: a panic in `init` (before the board's watchdog used to start) makes the motor safe
/// and ends in a reset, not a hang: the report comes twice, the second time from the image
/// started again. On the board the watchdog, now started first in `init`, makes that reset; QEMU
/// models no IWDG, so the image's HardFault handler requests it (SYSRESETREQ).
#[test]
#[cfg_attr(
    not(has_qemu),
    ignore = "needs qemu-system-arm, flip-link and the thumbv7em-none-eabihf target (.ci/run installs them)"
)]
fn qemu_a_panic_in_init_ends_in_a_reset() {
    if let Some(missing) = missing_prerequisite() {
        if std::env::var_os("CI").is_some() {
            panic!("{missing}");
        }
        eprintln!("qemu_a_panic_in_init_ends_in_a_reset NOT RUN: {missing}");
        return;
    }
    let image = build_image("qemu-init-panic-test");
    let qemu = Qemu::boot(&image);
    const REPORT: &str =
        "\nsafe state (panic): enable low, pwm 0\npanic: qemu-init-panic-test: a deliberate panic in init\n\
                          \nsafe state (HardFault): enable low, pwm 0\n";
    let started = Instant::now();
    let text = until_reported_twice(&qemu, REPORT);
    // Nothing but the reports (a third may be on its way): init never got as far as the protocol.
    assert!(text.starts_with(&REPORT.repeat(2)), "{text:?}");
    eprintln!("qemu: the init panic's report twice after {:?}", started.elapsed());
}

/// Issue 28: a stack overflow ends in the safe state, then a reset. flip-link puts the stack at
/// the bottom of RAM, so the overflow faults there instead of overwriting the rig's state; the
/// HardFault entry moves the stack pointer back to the top of the stack region before anything
/// is pushed (a handler pushing below RAM locked the core up: "Lockup: can't escalate 3 to
/// HardFault"), so the safe-state writes run. The image built with `qemu-stack-overflow-test`
/// recurses without end in `init`: the report comes, the image restarts, and it comes again.
#[test]
#[cfg_attr(
    not(has_qemu),
    ignore = "needs qemu-system-arm, flip-link and the thumbv7em-none-eabihf target (.ci/run installs them)"
)]
fn qemu_a_stack_overflow_ends_in_the_safe_state() {
    if let Some(missing) = missing_prerequisite() {
        if std::env::var_os("CI").is_some() {
            panic!("{missing}");
        }
        eprintln!("qemu_a_stack_overflow_ends_in_the_safe_state NOT RUN: {missing}");
        return;
    }
    let image = build_image("qemu-stack-overflow-test");
    let qemu = Qemu::boot(&image);
    const REPORT: &str = "\nsafe state (HardFault): enable low, pwm 0\n";
    let started = Instant::now();
    let text = until_reported_twice(&qemu, REPORT);
    assert!(text.starts_with(&REPORT.repeat(2)), "{text:?}");
    eprintln!("qemu: the stack overflow's safe state twice after {:?}", started.elapsed());
}

/// What `qemu` printed until `report` is in it twice (the image restarted after it once).
fn until_reported_twice(qemu: &Qemu, report: &str) -> String {
    let mut seen = Vec::new();
    let started = Instant::now();
    loop {
        let text = String::from_utf8_lossy(&seen).into_owned();
        if text.matches(report).count() >= 2 {
            return text;
        }
        assert!(started.elapsed() < SESSION_LIMIT, "no second report after {:?}: {text:?}", started.elapsed());
        match qemu.bytes.recv_timeout(Duration::from_millis(10)) {
            Ok(bytes) => seen.extend(bytes),
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => panic!("qemu exited: {text:?}"),
        }
    }
}
