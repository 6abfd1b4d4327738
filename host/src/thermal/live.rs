//! The live thermal session: at each setpoint the chamber is set (by the operator, or a driver
//! behind [`Chamber`]), the host watches OUT_TEMP until the die has settled
//! ([`super::settle`]), then records the usual runs into the setpoint's folder; the manifest
//! (`thermal.json`) is rewritten after each setpoint, so an interrupted session keeps every
//! setpoint it finished, each capture with its setpoint.

use super::manifest::{SetpointEntry, ThermalManifest};
use super::settle::{SettleCriterion, SettleWatch};
use crate::link::Link;
use crate::session::{self, Operator, RunPlan};
use anyhow::{bail, Result};
use protocol::RigMsg;
use std::io::{Read, Write};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};

/// Longest wait for the die to settle at one setpoint, s: 6 h (engineering judgement: a chamber
/// that has not settled a board in six hours is faulty or mis-set, and the operator should know).
pub const MAX_SETTLE_S: f64 = 21_600.0;

/// How often the settle watch reports progress, s.
const PROGRESS_EVERY_S: f64 = 60.0;

/// A thermal chamber (or a heater on the sensor table): brought to a setpoint.
pub trait Chamber {
    /// Brings the chamber to `setpoint_c`. A manual chamber asks the operator through `ask`
    /// (the session's prompt, which keeps the link alive) and returns once they confirm; a
    /// driven one sends the command and returns.
    fn set(&mut self, setpoint_c: f64, ask: &mut dyn FnMut(&str) -> Result<()>) -> Result<()>;
}

/// A chamber the operator sets by hand.
pub struct ManualChamber;

impl Chamber for ManualChamber {
    fn set(&mut self, setpoint_c: f64, ask: &mut dyn FnMut(&str) -> Result<()>) -> Result<()> {
        ask(&format!(
            "Set the thermal chamber to {setpoint_c} °C and start it; the host then waits for the die to settle."
        ))
    }
}

/// What the watch saw when the die settled.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settled {
    /// Rig time from the start of the watch to the verdict, s.
    pub waited_s: f64,
    /// Mean die reading over the final window, −OUT_TEMP (°C up to OUT_TEMP's offset).
    pub reading_c: f64,
    /// Slope over the final window, °C/min.
    pub slope_c_per_min: f64,
}

/// Reads the link until the OUT_TEMP readings settle by `criterion` (times from the rig's µs
/// timer, unwrapped), reporting progress on standard error every minute. Fails on interrupt,
/// on a link failure, or after [`MAX_SETTLE_S`].
pub fn wait_settled<P: Read + Write>(
    link: &mut Link<P>,
    criterion: SettleCriterion,
    interrupted: &AtomicBool,
) -> Result<Settled> {
    let mut watch = SettleWatch::new(criterion);
    let mut clock = RigClock::default();
    let (mut first_s, mut next_report_s) = (None, 0.0);
    loop {
        if interrupted.load(Ordering::SeqCst) {
            bail!("interrupted while waiting for the die to settle");
        }
        link.keep_alive()?;
        let mut readings = Vec::new();
        link.poll(|m| {
            if let RigMsg::Temperature(t) = m {
                readings.push((t.t_us, t.raw));
            }
        })?;
        for (t_us, raw) in readings {
            let t_s = clock.seconds(t_us);
            let start = *first_s.get_or_insert(t_s);
            let settled = watch.push(t_s, -f64::from(raw));
            let slope = watch.slope_c_per_min().unwrap_or(f64::NAN);
            if settled {
                let reading_c = watch.mean_c().unwrap_or(f64::NAN);
                eprintln!(
                    "die settled: {reading_c:.1} (−OUT_TEMP), slope {slope:+.3} °C/min after {:.0} s",
                    t_s - start
                );
                return Ok(Settled { waited_s: t_s - start, reading_c, slope_c_per_min: slope });
            }
            if t_s - start >= next_report_s {
                eprintln!("waiting for the die: OUT_TEMP {raw}, slope {slope:+.3} °C/min, {:.0} s", t_s - start);
                next_report_s += PROGRESS_EVERY_S;
            }
            if t_s - start > MAX_SETTLE_S {
                bail!("the die did not settle within {MAX_SETTLE_S} s (slope {slope:+.3} °C/min): check the chamber");
            }
        }
    }
}

/// The rig's µs timer, unwrapped (it wraps every 2³² µs ≈ 71.6 min, shorter than some waits).
#[derive(Debug, Default)]
struct RigClock {
    last_us: Option<u32>,
    total_us: u64,
}

impl RigClock {
    fn seconds(&mut self, t_us: u32) -> f64 {
        if let Some(last) = self.last_us {
            self.total_us += u64::from(t_us.wrapping_sub(last));
        }
        self.last_us = Some(t_us);
        self.total_us as f64 * 1e-6
    }
}

/// Records a thermal session into `dir`: per setpoint, the chamber set, the die settled by
/// `criterion`, the runs of `plan` recorded into `dir/spN_Tc/`. Returns the manifest (also in
/// `dir/thermal.json`).
#[allow(clippy::too_many_arguments)] // the session's parts, each distinct; no natural grouping
pub fn record_thermal_session<P: Read + Write>(
    link: &mut Link<P>,
    setpoints_c: &[f64],
    plan: &[RunPlan],
    dir: &Path,
    operator: &mut dyn Operator,
    chamber: &mut dyn Chamber,
    criterion: SettleCriterion,
    interrupted: &AtomicBool,
) -> Result<ThermalManifest> {
    let mut manifest = ThermalManifest { criterion, setpoints: Vec::new() };
    for (i, &setpoint_c) in setpoints_c.iter().enumerate() {
        chamber.set(setpoint_c, &mut |msg| session::prompt(link, msg, operator, interrupted))?;
        let settled = wait_settled(link, criterion, interrupted)?;
        let name = ThermalManifest::folder_name(i + 1, setpoint_c);
        let files = session::record_session(link, plan, &dir.join(&name), operator, interrupted)?;
        let captures = files.iter().filter_map(|f| f.file_name().map(|n| n.to_string_lossy().into_owned())).collect();
        manifest.setpoints.push(SetpointEntry { setpoint_c, dir: name, captures, settle_s: Some(settled.waited_s) });
        manifest.write(dir)?;
    }
    Ok(manifest)
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::Temperature;
    use std::io::Cursor;

    /// A port that serves `bytes` in small reads and swallows what the host sends.
    struct Replay(Cursor<Vec<u8>>);

    impl Read for Replay {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            let n = buf.len().min(64);
            self.0.read(&mut buf[..n])
        }
    }

    impl Write for Replay {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    /// The rig's Temperature frames at 1 Hz for `secs` of a die following `die_c`, the timer
    /// starting near its wrap.
    fn stream(secs: u32, die_c: impl Fn(f64) -> f64) -> Vec<u8> {
        let mut w = crate::sim::FrameWriter::new(Vec::new());
        let start_us = u32::MAX - 5_000_000;
        for s in 0..secs {
            let raw = (40.0 - die_c(f64::from(s))).round() as i8;
            let t_us = start_us.wrapping_add(s.wrapping_mul(1_000_000));
            w.send(&RigMsg::Temperature(Temperature { t_us, raw })).unwrap();
        }
        w.into_inner()
    }

    #[test]
    fn the_watch_waits_for_a_settled_die_across_the_timer_wrap_and_refuses_a_drifting_one() {
        let settling = stream(4000, |t| 50.0 - 30.0 * (-t / 180.0).exp());
        let mut link = Link::new(Replay(Cursor::new(settling)), "test");
        let s = wait_settled(&mut link, SettleCriterion::default(), &AtomicBool::new(false)).unwrap();
        assert!((1200.0..2600.0).contains(&s.waited_s), "{s:?}");
        assert!(s.slope_c_per_min.abs() <= SettleCriterion::default().max_slope_c_per_min);
        // A die still drifting at 0.1 °C/min never settles: the stream ends first.
        let drifting = stream(3000, |t| 20.0 + 0.1 * t / 60.0);
        let mut link = Link::new(Replay(Cursor::new(drifting)), "test");
        let e = wait_settled(&mut link, SettleCriterion::default(), &AtomicBool::new(false)).unwrap_err();
        assert!(e.to_string().contains("closed"), "{e}");
        // Ctrl-C ends the wait at once.
        let mut link = Link::new(Replay(Cursor::new(stream(10, |_| 20.0))), "test");
        let e = wait_settled(&mut link, SettleCriterion::default(), &AtomicBool::new(true)).unwrap_err();
        assert!(e.to_string().contains("interrupted"), "{e}");
    }

    #[test]
    fn the_manual_chamber_asks_for_the_setpoint() {
        let mut asked = Vec::new();
        ManualChamber
            .set(-20.0, &mut |m| {
                asked.push(m.to_string());
                Ok(())
            })
            .unwrap();
        assert_eq!(asked.len(), 1);
        assert!(asked[0].contains("-20 °C"), "{asked:?}");
    }
}

/// The live thermal session against the simulator's live rig (the firmware's own core on the
/// simulated plant, `crate::sim::SimRig`) in its simulated time: a driven chamber, the settle
/// watch, the runs recorded per setpoint, the manifest, and the model from the captures.
#[cfg(test)]
mod session_tests {
    use super::*;
    use crate::session::AssumeYes;
    use crate::sim::{SimConfig, SimRig};
    use std::cell::RefCell;
    use std::rc::Rc;
    use std::time::Duration;

    /// Simulated time advanced per read, s: a poll's worth of the rig's stream.
    const STEP_S: f64 = 0.02;
    /// The test chamber: fast, so the test stays short (a bench-top chamber ramps at 2 °C/min).
    const RAMP_C_PER_MIN: f64 = 60.0;
    const DIE_TAU_S: f64 = 20.0;

    /// The host's side of an in-process rig: each read advances simulated time by [`STEP_S`].
    struct InProcess {
        rig: Rc<RefCell<SimRig>>,
        pending: Vec<u8>,
    }

    impl Read for InProcess {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            if self.pending.is_empty() {
                let mut rig = self.rig.borrow_mut();
                let t = rig.now_s() + STEP_S;
                rig.advance_to(t);
                self.pending = rig.take_output();
            }
            let n = buf.len().min(self.pending.len());
            buf[..n].copy_from_slice(&self.pending[..n]);
            self.pending.drain(..n);
            Ok(n)
        }
    }

    impl Write for InProcess {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            self.rig.borrow_mut().receive(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    struct SimClock(Rc<RefCell<SimRig>>);

    impl crate::link::Clock for SimClock {
        fn now(&self) -> Duration {
            Duration::from_secs_f64(self.0.borrow().now_s())
        }
    }

    /// A driven chamber: the simulated one around the rig.
    struct SimChamber(Rc<RefCell<SimRig>>);

    impl Chamber for SimChamber {
        fn set(&mut self, setpoint_c: f64, _ask: &mut dyn FnMut(&str) -> Result<()>) -> Result<()> {
            self.0.borrow_mut().set_chamber(setpoint_c, RAMP_C_PER_MIN, DIE_TAU_S);
            Ok(())
        }
    }

    #[test]
    fn a_thermal_session_against_the_simulated_rig_settles_records_and_fits() {
        let mut cfg = SimConfig::with_runs(11, Vec::new());
        cfg.effects.temperature_dependence = Some(Default::default());
        let rig = Rc::new(RefCell::new(SimRig::new(&cfg).unwrap()));
        let port = InProcess { rig: rig.clone(), pending: Vec::new() };
        let mut link = Link::with_clock(port, "in-process rig", Box::new(SimClock(rig.clone())));
        let dir = tempfile::tempdir().unwrap();
        let plan = session::plan(&crate::geometry::Pose::ALL, &[180.0], 6.0);
        // A 2-minute window for a chamber that settles in a minute (the default is 20 min).
        let criterion = SettleCriterion { window_s: 120.0, ..SettleCriterion::default() };
        let setpoints = [0.0, 25.0, 50.0];
        let m = record_thermal_session(
            &mut link,
            &setpoints,
            &plan,
            dir.path(),
            &mut AssumeYes,
            &mut SimChamber(rig.clone()),
            criterion,
            &AtomicBool::new(false),
        )
        .unwrap();
        assert_eq!(ThermalManifest::read_in(dir.path()).unwrap().as_ref(), Some(&m));
        let mut cals = Vec::new();
        for (setpoint_c, _, files) in m.paths(dir.path()) {
            assert_eq!(files.len(), 2);
            let runs: Vec<_> =
                files.iter().flat_map(|f| crate::capture::decode(&std::fs::read(f).unwrap()).runs).collect();
            let report = crate::calib::calibrate(&runs, &Default::default()).unwrap();
            let temps: Vec<i8> = runs.iter().flat_map(|r| r.temperatures.iter().map(|t| t.raw)).collect();
            cals.push(super::super::SetpointCal::from_report(setpoint_c, &report, &temps).unwrap());
        }
        for e in &m.setpoints {
            // At least one window; the fast chamber settles within a few of its lags after it.
            let settle_s = e.settle_s.unwrap();
            assert!((120.0..600.0).contains(&settle_s), "{e:?}");
        }
        let model = super::super::ThermalModel::fit(&cals).unwrap();
        // The die temperatures are the setpoints (the chamber anchors OUT_TEMP's offset), and
        // the offsets follow the simulated 0.03 °/s/°C of x to a few σ.
        for (s, sp) in model.setpoints.iter().zip(setpoints) {
            assert!((s.die_c - sp).abs() <= 1.0, "{s:?}");
        }
        let offset = model.curve(0, super::super::Quantity::OffsetCounts);
        assert_eq!(offset.order, 1, "three setpoints: a line at most");
        let slope = offset.coef[1];
        let k = cals[1].values[0][1].value;
        assert!((slope.value / k - 0.03).abs() < 0.005, "{slope:?} counts/°C, k {k}");
    }
}
