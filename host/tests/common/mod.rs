//! What the live tests and the soak share: the `host` binary against `host virtual-rig` in
//! lockstep ([`LockstepBench`]), a host process read line by line ([`Running`]), scratch
//! directories.
#![allow(dead_code)] // each test crate uses its own part

use host::capture;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::Arc;
use std::thread;
use std::time::Duration;

pub fn host(args: &[&str]) -> Output {
    host_command().args(args).output().expect("host runs")
}

/// A test's scratch directory under the temp dir, with the files named after it beside it (its
/// records database, the lockstep clock's socket): removed when the test passes, kept for
/// inspection when it fails (the guard drops while the test panics).
pub struct Scratch(pub PathBuf);

impl std::ops::Deref for Scratch {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if thread::panicking() {
            return;
        }
        let _ = std::fs::remove_dir_all(&self.0);
        let (Some(parent), Some(name)) = (self.0.parent(), self.0.file_name()) else { return };
        let beside = format!("{}.", name.to_string_lossy());
        for entry in std::fs::read_dir(parent).into_iter().flatten().flatten() {
            if entry.file_name().to_string_lossy().starts_with(&beside) {
                let _ = std::fs::remove_file(entry.path());
            }
        }
    }
}

pub fn scratch_path(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("host-live-{}-{name}", std::process::id()))
}

pub fn scratch(name: &str) -> Scratch {
    let d = scratch_path(name);
    let _ = std::fs::remove_dir_all(&d);
    Scratch(d)
}

pub fn decode(path: &Path) -> capture::Capture {
    capture::decode(&std::fs::read(path).unwrap())
}

/// `host` running with its standard error read line by line, so a test can act when a line
/// appears. Killed when dropped.
pub struct Running {
    pub child: std::process::Child,
    pub lines: std::sync::mpsc::Receiver<String>,
    pub seen: Vec<String>,
}

impl Running {
    pub fn start(args: &[&str], stdin: std::process::Stdio) -> Self {
        Self::start_via(&[], args, stdin)
    }

    /// [`Self::start`] through `wrapper` (a program and its arguments, then the host's path and
    /// `args`), e.g. a shell that sets a resource limit first.
    pub fn start_via(wrapper: &[&str], args: &[&str], stdin: std::process::Stdio) -> Self {
        use std::io::BufRead;
        let mut command = match wrapper {
            [] => host_command(),
            [program, rest @ ..] => {
                let mut c = Command::new(program);
                c.args(rest).arg(env!("CARGO_BIN_EXE_host"));
                keep_out_of_the_users_data(&mut c);
                c
            }
        };
        let mut child = command
            .args(args)
            .stdin(stdin)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .expect("host runs");
        let err = child.stderr.take().unwrap();
        let (tx, lines) = std::sync::mpsc::channel();
        thread::spawn(move || {
            // The prompt ends without a newline: split at "\n" and at the prompt's final space.
            let mut r = std::io::BufReader::new(err);
            let mut buf = Vec::new();
            while r.read_until(b' ', &mut buf).map(|n| n > 0).unwrap_or(false) {
                if buf.ends_with(b"\n") || buf.ends_with(b"abort) ") {
                    let _ = tx.send(String::from_utf8_lossy(&buf).into_owned());
                    buf.clear();
                }
            }
            let _ = tx.send(String::from_utf8_lossy(&buf).into_owned());
        });
        Self { child, lines, seen: Vec::new() }
    }

    /// Lines of standard error that arrived since the last call (never blocks).
    pub fn drain(&mut self) -> Vec<String> {
        let new: Vec<String> = self.lines.try_iter().collect();
        self.seen.extend(new.iter().cloned());
        new
    }

    pub fn signal(&self, name: &str) {
        let ok = Command::new("kill").args([&format!("-{name}"), &self.child.id().to_string()]).status().unwrap();
        assert!(ok.success());
    }

    /// Waits for the exit; returns the status, everything on standard error, and the wall time
    /// it took (reported, not asserted: a loaded machine may take longer; the in-process tests
    /// assert the 1 s in the rig's time).
    pub fn finish(mut self) -> (std::process::ExitStatus, String, Duration) {
        let t0 = std::time::Instant::now();
        let status = loop {
            if let Some(s) = self.child.try_wait().unwrap() {
                break s;
            }
            assert!(t0.elapsed() < Duration::from_secs(60), "host did not exit: {:?}", self.seen);
            thread::sleep(Duration::from_millis(5));
        };
        let took = t0.elapsed();
        while let Ok(l) = self.lines.recv_timeout(Duration::from_secs(5)) {
            self.seen.push(l);
        }
        (status, self.seen.concat(), took)
    }
}

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Starts `host virtual-rig ARGS` and returns it with the pty path it prints first.
pub fn spawn_virtual_rig(args: &[&str]) -> (std::process::Child, String) {
    use std::io::BufRead;
    let mut rig = host_command()
        .arg("virtual-rig")
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    std::io::BufReader::new(rig.stdout.take().unwrap()).read_line(&mut line).unwrap();
    (rig, line.trim().to_string())
}

/// `host virtual-rig --lockstep` and the Unix socket through which a `host` run with the hidden
/// `--lockstep-clock` asks it for time: the test relays every `step` line to the rig and every
/// `at` answer back, so it knows the simulated time the host lives in and can act at a given
/// moment of it (answer a prompt, send a signal).
///
/// Why nothing here can race the wall clock: the rig's time advances only when the host, finding
/// nothing to read, asks for the next 5 ms, after the rig has received every byte the host wrote
/// before asking; the host's timeouts, heartbeats and retries are measured in that same time
/// (`LockstepPort::clock`). A descheduled host, rig or test stops the simulation with it: a
/// loaded machine makes the test slower, never different. The operator's delays are counted in
/// simulated time from the `at` answer current when the test sees the prompt, which is never
/// earlier than the host's time when it printed it, so every answer comes ≥ 30 s after its
/// question. That one instant depends on the wall clock (the test reads the host's output
/// through a pipe): on a loaded machine the answer may come a few steps later, and the line's
/// seeded losses then fall on other bytes. A test of a session with answers asserts what holds
/// for any placement of the losses. Wall time is only measured (and bounded generously) for
/// the signal tests' exit.
pub struct LockstepBench {
    pub rig: std::process::Child,
    /// `None` once [`Self::advance`] ended the rig.
    pub control_in: Option<std::process::ChildStdin>,
    pub control_out: std::io::BufReader<std::process::ChildStdout>,
    pub path: String,
    /// The rig's standard error: its command log (`virtual rig: received Stop (seq 9) at 4.125 s`).
    pub log: Arc<std::sync::Mutex<Vec<String>>>,
    pub socket: PathBuf,
    pub listener: std::os::unix::net::UnixListener,
    /// Set by a test (from [`Self::relay`]'s callback, through a clone) to stall the host: the
    /// rig runs this many ns more in one step, with no byte from the host, before the host hears
    /// the time, as when a loaded machine deschedules the host.
    pub stall_ns: Arc<std::sync::atomic::AtomicU64>,
    /// Control lines for the rig (e.g. `chamber 15` of `--chamber`), pushed by a test (from
    /// [`Self::relay`]'s callback, through a clone) and sent before the host's next step.
    pub pending_control: Arc<std::sync::Mutex<Vec<String>>>,
    /// Cleared when the bench is dropped; until then [`hang_guard`] may end the rig.
    alive: Arc<std::sync::Mutex<bool>>,
}

/// Wall time after which a lockstep bench is taken to be deadlocked. Every lockstep test ends
/// in seconds of wall time; a loaded CI machine may take ten times that. A deadlock (the rig,
/// the host and the test each waiting for another) would otherwise hold CI for its whole budget.
const HANG_GUARD: Duration = Duration::from_secs(300);

/// Kills the rig `pid` if the bench is still alive after [`HANG_GUARD`]: its standard output
/// then ends, so the test's reads return and the test fails on what it asserts, with the rig's
/// log, instead of hanging.
fn hang_guard(pid: u32, alive: Arc<std::sync::Mutex<bool>>, guard: Duration) {
    thread::spawn(move || {
        let t0 = std::time::Instant::now();
        loop {
            let alive = alive.lock().unwrap();
            if !*alive {
                return;
            }
            if t0.elapsed() > guard {
                eprintln!("lockstep bench: no end after {guard:?} of wall time: the virtual rig is killed");
                // SAFETY: `pid` is the rig, still a child of this process: the bench reaps it only
                // after clearing `alive`, which waits for this lock, so no reused id is hit.
                unsafe { libc::kill(pid as libc::pid_t, libc::SIGKILL) };
                return;
            }
            drop(alive);
            thread::sleep(Duration::from_millis(100));
        }
    });
}

impl LockstepBench {
    pub fn start(name: &str, args: &[&str]) -> Self {
        Self::start_with_guard(name, args, HANG_GUARD)
    }

    /// [`Self::start`] for a test of hours of rig time (a thermal session's settle windows),
    /// whose wall time is minutes: the rig is taken to be deadlocked after `guard`.
    pub fn start_with_guard(name: &str, args: &[&str], guard: Duration) -> Self {
        use std::io::BufRead;
        let mut rig = host_command()
            .args(["virtual-rig", "--lockstep"])
            .args(args)
            .stdin(std::process::Stdio::piped())
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let control_in = rig.stdin.take().unwrap();
        let mut control_out = std::io::BufReader::new(rig.stdout.take().unwrap());
        let mut path = String::new();
        control_out.read_line(&mut path).unwrap();
        let log = Arc::new(std::sync::Mutex::new(Vec::new()));
        let sink = log.clone();
        let err = rig.stderr.take().unwrap();
        thread::spawn(move || {
            for line in std::io::BufReader::new(err).lines().map_while(Result::ok) {
                sink.lock().unwrap().push(line);
            }
        });
        let socket = scratch_path(name).with_extension("clock.sock");
        let _ = std::fs::remove_file(&socket);
        let listener = std::os::unix::net::UnixListener::bind(&socket).unwrap();
        let stall_ns = Arc::new(std::sync::atomic::AtomicU64::new(0));
        let alive = Arc::new(std::sync::Mutex::new(true));
        hang_guard(rig.id(), alive.clone(), guard);
        Self {
            rig,
            control_in: Some(control_in),
            control_out,
            path: path.trim().to_string(),
            log,
            socket,
            listener,
            stall_ns,
            pending_control: Arc::new(std::sync::Mutex::new(Vec::new())),
            alive,
        }
    }

    /// `host ARGS --port PTY --lockstep-clock SOCKET`, standard input piped.
    pub fn host(&self, args: &[&str]) -> Running {
        self.host_with(args, std::process::Stdio::piped())
    }

    pub fn host_with(&self, args: &[&str], stdin: std::process::Stdio) -> Running {
        self.host_via(&[], args, stdin)
    }

    /// [`Self::host_with`] through `wrapper` ([`Running::start_via`]).
    pub fn host_via(&self, wrapper: &[&str], args: &[&str], stdin: std::process::Stdio) -> Running {
        let mut all = args.to_vec();
        all.extend(["--port", &self.path, "--lockstep-clock", self.socket.to_str().unwrap()]);
        Running::start_via(wrapper, &all, stdin)
    }

    /// Runs `host ARGS` against the rig to its end; its exit status and standard error.
    pub fn run(&mut self, args: &[&str], stdin: std::process::Stdio) -> Output {
        let mut running = self.host_with(args, stdin);
        self.relay(&mut running, |_, _| {});
        let (status, err, _) = running.finish();
        Output { status, stdout: Vec::new(), stderr: err.into_bytes() }
    }

    /// Relays the host's time requests until it closes the socket (it exited); `at_step` is
    /// called with the simulated time (ns) after every step, before the host hears of it.
    /// Returns the simulated time of the host's last step.
    pub fn relay(&mut self, host: &mut Running, mut at_step: impl FnMut(u64, &mut Running)) -> u64 {
        use std::io::{BufRead, Write};
        self.listener.set_nonblocking(true).unwrap();
        let t0 = std::time::Instant::now();
        let stream = loop {
            match self.listener.accept() {
                Ok((s, _)) => break s,
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                    if host.child.try_wait().unwrap().is_some() {
                        return 0; // exited before asking for time
                    }
                    assert!(t0.elapsed() < Duration::from_secs(120), "the host never connected");
                    thread::sleep(Duration::from_millis(5));
                }
                Err(e) => panic!("accept: {e}"),
            }
        };
        stream.set_nonblocking(false).unwrap();
        // A hang guard: a host that stops asking for time has stopped reading the port (the rig's
        // time advances only through its reads), e.g. blocked at a prompt (F2).
        stream.set_read_timeout(Some(Duration::from_secs(120))).unwrap();
        let mut from_host = std::io::BufReader::new(stream.try_clone().unwrap());
        let mut to_host = stream;
        let mut now_ns = 0;
        loop {
            let mut step = String::new();
            match from_host.read_line(&mut step) {
                Ok(0) => return now_ns,
                Ok(_) => {}
                Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {
                    panic!(
                        "the host stopped asking for time at {now_ns} ns (blocked, not reading the port): {:?}",
                        host.seen
                    )
                }
                Err(_) => return now_ns,
            }
            let pending: Vec<String> = std::mem::take(&mut *self.pending_control.lock().unwrap());
            for line in pending {
                if writeln!(self.control(), "{line}").is_err() {
                    return now_ns; // the rig is gone (killed by the test)
                }
            }
            if self.control().write_all(step.as_bytes()).and_then(|()| self.control().flush()).is_err() {
                return now_ns; // the rig is gone (killed by the test)
            }
            let mut at = String::new();
            if self.control_out.read_line(&mut at).unwrap_or(0) == 0 {
                // The rig is gone (killed by the test): so is the host's clock.
                return now_ns;
            }
            now_ns = at.split_whitespace().nth(1).and_then(|t| t.parse().ok()).expect("at <ns> <bytes>");
            at_step(now_ns, host);
            let stall = self.stall_ns.swap(0, std::sync::atomic::Ordering::SeqCst);
            if stall > 0 {
                // The host wrote nothing since its step: the same byte total.
                let bytes = step.split_whitespace().nth(2).expect("step <ns> <bytes>");
                writeln!(self.control(), "step {stall} {bytes}").and_then(|()| self.control().flush()).unwrap();
                at.clear();
                assert!(self.control_out.read_line(&mut at).unwrap() > 0, "the virtual rig ended: {:?}", self.log());
                now_ns = at.split_whitespace().nth(1).and_then(|t| t.parse().ok()).expect("at <ns> <bytes>");
            }
            if to_host.write_all(at.as_bytes()).is_err() {
                return now_ns;
            }
        }
    }

    pub fn log(&self) -> Vec<String> {
        self.log.lock().unwrap().clone()
    }

    /// After the host has gone: one more step of rig time, so that bytes the host wrote just
    /// before exiting (a `Stop` at the prompt, sent 0 s of rig time before the exit) are handled
    /// rather than left in the pty, then waits (wall time, bounded) until the rig's log shows
    /// `command` or the rig answered. Without it the check below raced the rig's reading.
    pub fn settle(&mut self, command: &str) {
        use std::io::{BufRead, Write};
        if writeln!(self.control(), "step {} 0", 5_000_000).and_then(|()| self.control().flush()).is_ok() {
            let mut at = String::new();
            let _ = self.control_out.read_line(&mut at);
        }
        let t0 = std::time::Instant::now();
        while self.received(command).is_empty() && t0.elapsed() < Duration::from_secs(10) {
            thread::sleep(Duration::from_millis(10));
        }
    }

    pub fn control(&mut self) -> &mut std::process::ChildStdin {
        self.control_in.as_mut().expect("the virtual rig was ended")
    }

    /// After the host has gone: `ns` more of the rig's time with no host on the line, then ends
    /// the rig (its standard input closed) and waits until its last log line (`virtual rig
    /// done`) is read, so the log then holds everything the rig said.
    pub fn advance(&mut self, ns: u64) {
        use std::io::{BufRead, Read, Write};
        // Someone reads the pty, as the host did: a full pty would block the rig's writes.
        // Opened as the host opens it (raw, no echo: an echo would feed the rig its own frames).
        let mut pty = serialport::new(&self.path, 921_600).timeout(Duration::from_millis(100)).open_native().unwrap();
        thread::spawn(move || {
            let mut sink = [0u8; 4096];
            loop {
                match pty.read(&mut sink) {
                    Ok(n) if n > 0 => {}
                    Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
                    _ => return,
                }
            }
        });
        // The host's bytes all arrived (`settle`): nothing to wait for.
        writeln!(self.control(), "step {ns} 0").and_then(|()| self.control().flush()).unwrap();
        let mut at = String::new();
        assert!(self.control_out.read_line(&mut at).unwrap() > 0, "the virtual rig ended: {:?}", self.log());
        self.control_in = None;
        let t0 = std::time::Instant::now();
        while !self.log().iter().any(|l| l.starts_with("virtual rig done")) {
            assert!(t0.elapsed() < Duration::from_secs(60), "the virtual rig did not end: {:?}", self.log());
            thread::sleep(Duration::from_millis(10));
        }
    }

    /// For `--drop KIND:N`, `what` = `"KIND #N"`: the last command the rig received before it
    /// dropped that message (the one it answered) and the first it received after (the host's
    /// reply to the loss), by name. `None` if the rig never dropped it or heard nothing after.
    pub fn dropped_and_repeated(&self, what: &str) -> Option<(String, String)> {
        let log = self.log();
        let at = log.iter().position(|l| *l == format!("virtual rig: dropped {what}"))?;
        let name = |l: &String| Some(l.strip_prefix("virtual rig: received ")?.split(' ').next()?.to_string());
        let before = log[..at].iter().rev().find_map(name)?;
        let after = log[at + 1..].iter().find_map(name)?;
        Some((before, after))
    }

    /// Simulated times (s) at which the rig received `command`.
    pub fn received(&self, command: &str) -> Vec<f64> {
        let prefix = format!("virtual rig: received {command} (");
        self.log()
            .iter()
            .filter(|l| l.starts_with(&prefix))
            .filter_map(|l| l.rsplit(" at ").next()?.strip_suffix(" s")?.parse().ok())
            .collect()
    }
}

impl Drop for LockstepBench {
    fn drop(&mut self) {
        *self.alive.lock().unwrap_or_else(|e| e.into_inner()) = false;
        let _ = self.rig.kill();
        let _ = self.rig.wait();
        let _ = std::fs::remove_file(&self.socket);
    }
}

pub const NS: u64 = 1_000_000_000;

/// `host`, with the records database's default kept out of the user's data folder: a run
/// without `--db` records under the temporary directory, never in ~/.local/share.
pub fn host_command() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_host"));
    keep_out_of_the_users_data(&mut c);
    c
}

fn keep_out_of_the_users_data(c: &mut Command) {
    c.env_remove("GYROCAL_DB").env("XDG_DATA_HOME", std::env::temp_dir().join("gyrocal-tests-data"));
}
