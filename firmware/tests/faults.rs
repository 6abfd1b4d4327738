//! Every fault ends in the right report, a RunStopped for the run it killed, and a motor that is
//! off and stays off.

mod common;
use common::{Session, MS, S};
use firmware::plant::l3g4200d_model::{BusFault, L3g4200dModel};
use firmware::plant::Plant;
use firmware::rig::{GYRO_BAD_READS, GYRO_SILENT_US, HOST_LINK_TIMEOUT_US};
use firmware::supervisor::STALL_PERIODS;
use firmware::virtual_rig::VirtualRig;
use protocol::{motor_faults, CmdResult, Command, Direction, Fault, RigMsg, StartRun};

const TAG: u8 = 0x21;

fn running() -> Session {
    let mut s = Session::prototype();
    s.command(Command::Start(StartRun { rate_mdps: 180_000, direction: Direction::Ccw, run_tag: TAG }));
    s.run(4 * S);
    assert!(s.faults().is_empty());
    s
}

/// The fault came once, the run was stopped, the bridge has been off since `within_ns` after
/// `since_ns`, and MotorStatus shows `bit`.
fn assert_tripped(s: &Session, fault: Fault, bit: u8, since_ns: u64, within_ns: u64) {
    assert_eq!(s.faults(), vec![fault]);
    let fault_at = s.position(|m| matches!(m, RigMsg::Fault(_))).unwrap();
    assert!(
        matches!(s.frames[fault_at + 1].2, RigMsg::RunStopped(r) if r.run_tag == TAG),
        "RunStopped right after the fault"
    );
    let off_from = s.probes.iter().rposition(|p| p.motor.enable).map(|i| s.probes[i + 1].t_ns).unwrap();
    assert!(off_from >= since_ns, "off before the fault was injected");
    let reaction = off_from - since_ns;
    println!("{fault:?}: motor off {:.1} ms after injection", reaction as f64 * 1e-6);
    assert!(reaction <= within_ns, "motor off only after {reaction} ns");
    let last_status = s
        .msgs()
        .filter_map(|m| match m {
            RigMsg::Motor(ms) => Some(*ms),
            _ => None,
        })
        .last()
        .unwrap();
    assert_eq!((last_status.faults, last_status.run_tag, last_status.duty_permille), (bit, 0, 0));
}

#[test]
fn stalled_motor_trips_within_the_stall_window() {
    let mut s = running();
    let t = s.vr.now_ns();
    s.vr.plant.motor.locked = true;
    s.run(S);
    let window = u64::from(STALL_PERIODS) * MS;
    assert_tripped(&s, Fault::Stall, motor_faults::STALL, t, window + MS);
    // A new start clears the motor fault and runs again.
    s.vr.plant.motor.locked = false;
    let again = s.command(Command::Start(StartRun { rate_mdps: 90_000, direction: Direction::Cw, run_tag: 2 }));
    s.run(3 * S);
    assert_eq!(s.ack_for(again), Some(CmdResult::Ok));
    assert!(s.probes.last().unwrap().speed_cps < -80_000.0);
}

#[test]
fn swapped_encoder_wires_run_away_into_over_speed() {
    let mut plant = Plant::prototype();
    plant.encoder.reversed = true;
    let mut s = Session::new(VirtualRig::new(plant, L3g4200dModel::new(), 0));
    let t = s.vr.now_ns();
    s.command(Command::Start(StartRun { rate_mdps: 180_000, direction: Direction::Ccw, run_tag: TAG }));
    s.run(2 * S);
    assert_tripped(&s, Fault::OverSpeed, motor_faults::OVER_SPEED, t, 2 * S);
    let peak = s.probes.iter().map(|p| p.speed_cps).fold(0.0, f64::max);
    // Caught within one period of crossing 405 000 cps; in that period full duty accelerates
    // the table by at most ≈ 990 rad/s² · 1 ms ≈ 51 000 cps, and then it only coasts down.
    let limit = f64::from(firmware::supervisor::OVER_SPEED_CPS);
    assert!(peak > limit && peak < limit + 51_000.0, "peak {peak} cps");
}

#[test]
fn silent_host_stops_the_motor_after_two_seconds() {
    let mut s = running();
    s.heartbeat = false;
    let t = s.vr.now_ns();
    s.run(3 * S);
    // The last heartbeat was sent at most 500 ms before `t`.
    assert_tripped(&s, Fault::HostLinkLost, motor_faults::HOST_LINK_LOST, t, u64::from(HOST_LINK_TIMEOUT_US) * 1_000);
    assert!(s.probes.iter().filter(|p| p.t_ns > t).filter(|p| p.motor.enable).count() >= 1_500);
}

#[test]
fn miso_stuck_low_is_a_dead_bus() {
    let mut s = running();
    let t = s.vr.now_ns();
    s.vr.gyro.spi_mut().fault = BusFault::MisoStuckLow;
    s.run(S);
    // Eight stale reads at 809.6 Hz, then the next control tick: < 11 ms.
    let window = (u64::from(GYRO_BAD_READS) + 1) * 1_000_000_000 / 809 + MS;
    assert_tripped(&s, Fault::GyroSpi, motor_faults::INTERLOCK, t, window);
    let stale =
        s.msgs().filter(|m| matches!(m, RigMsg::Sample(x) if x.status & protocol::sample_status::STALE != 0)).count();
    assert!(stale >= usize::from(GYRO_BAD_READS));
    // Refused to start again until the gyro is reconfigured successfully.
    let refused = s.command(Command::Start(StartRun { rate_mdps: 180_000, direction: Direction::Ccw, run_tag: 3 }));
    let reconfigure = s.command(Command::ConfigureGyro(protocol::GyroConfig::DEFAULT));
    s.run(200 * MS);
    assert_eq!(s.ack_for(refused), Some(CmdResult::Faulted));
    assert_eq!(s.ack_for(reconfigure), Some(CmdResult::Faulted));
    s.vr.gyro.spi_mut().fault = BusFault::None;
    let reconfigure = s.command(Command::ConfigureGyro(protocol::GyroConfig::DEFAULT));
    let accepted = s.command(Command::Start(StartRun { rate_mdps: 180_000, direction: Direction::Ccw, run_tag: 4 }));
    s.run(200 * MS);
    assert_eq!(s.ack_for(reconfigure), Some(CmdResult::Ok));
    assert_eq!(s.ack_for(accepted), Some(CmdResult::Ok));
}

/// Issue 28: a MISO stuck high reads 0xFF everywhere, which looks like a fresh sample (ZYXDA
/// set); it must trip `GyroSpi` within N = `GYRO_BAD_READS` = 8 samples (+ the next control
/// tick), and no all-0xFF burst is streamed as a sample.
#[test]
fn miso_stuck_high_is_a_dead_bus_within_eight_samples() {
    assert_eq!(GYRO_BAD_READS, 8);
    let mut s = running();
    let t = s.vr.now_ns();
    s.vr.gyro.spi_mut().fault = BusFault::MisoStuckHigh;
    s.run(S);
    // Eight bad reads at 809.6 Hz, then the next control tick: < 11 ms.
    let window = (u64::from(GYRO_BAD_READS) + 1) * 1_000_000_000 / 809 + MS;
    assert_tripped(&s, Fault::GyroSpi, motor_faults::INTERLOCK, t, window);
    let garbage = s.msgs().filter(|m| matches!(m, RigMsg::Sample(x) if x.rate_counts == [-1; 3])).count();
    assert_eq!(garbage, 0, "an all-0xFF burst was streamed as a sample");
}

/// Issue 28: a trip in the data-ready interrupt (here a dead bus) cuts the bridge at that
/// sample, not at the next control tick up to 1 ms later: looked at every 20 µs, the drive is
/// never on once the fault is in force.
#[test]
fn a_trip_at_data_ready_cuts_the_drive_at_once() {
    let mut s = running();
    s.vr.gyro.spi_mut().fault = BusFault::MisoStuckLow;
    let mut driven_after_trip_ns = 0;
    let mut tripped = false;
    for _ in 0..1_000 {
        s.vr.run_until(s.vr.now_ns() + 20_000, &mut s.wire, |_| {});
        if s.vr.rig.gyro_fault().is_some() {
            tripped = true;
            if s.vr.plant.driven() {
                driven_after_trip_ns += 20_000;
            }
        }
    }
    assert!(tripped);
    assert_eq!(driven_after_trip_ns, 0, "the drive stayed on after the trip");
}

#[test]
fn spi_errors_are_counted_and_trip_the_run() {
    let mut s = running();
    let t = s.vr.now_ns();
    s.vr.gyro.spi_mut().fault = BusFault::Error;
    s.run(1100 * MS);
    let window = (u64::from(GYRO_BAD_READS) + 1) * 1_000_000_000 / 809 + MS;
    assert_tripped(&s, Fault::GyroSpi, motor_faults::INTERLOCK, t, window);
    let c = s
        .msgs()
        .filter_map(|m| match m {
            RigMsg::Counters(c) => Some(*c),
            _ => None,
        })
        .last()
        .unwrap();
    // Every data-ready after the injection failed and was counted; none became a Sample.
    assert!(c.spi_errors >= 800, "{} errors", c.spi_errors);
}

#[test]
fn a_gyro_that_stops_producing_is_silent() {
    let mut s = running();
    let t = s.vr.now_ns();
    s.vr.gyro.spi_mut().halted = true;
    s.run(S);
    let window = u64::from(GYRO_SILENT_US) * 1_000 + 2 * MS;
    assert_tripped(&s, Fault::GyroSilent, motor_faults::INTERLOCK, t, window);
}

#[test]
fn wrong_who_am_i_is_reported_at_power_up_and_blocks_runs() {
    let mut chip = L3g4200dModel::new();
    chip.set_who_am_i(0xD4);
    let mut s = Session::new(VirtualRig::new(Plant::prototype(), chip, 0));
    let start = s.command(Command::Start(StartRun { rate_mdps: 180_000, direction: Direction::Ccw, run_tag: 1 }));
    s.run(S);
    assert!(matches!(s.frames[0].2, RigMsg::Hello(_)));
    assert!(matches!(s.frames[1].2, RigMsg::Fault(f) if f.fault == Fault::GyroAbsent { who_am_i: 0xD4 }));
    assert_eq!(s.faults().len(), 1, "reported once, not as a silent gyro too");
    assert_eq!(s.ack_for(start), Some(CmdResult::Faulted));
    assert!(s.probes.iter().all(|p| !p.motor.enable));
}

/// B1: the data-ready task (priority 3) preempts the control task between its clock read and its
/// lock of the rig, and stamps a sample one tick *after* the control task's time. Unsigned, that
/// difference wrapped to ≈ 4 295 s of "silence" and tripped GyroSilent mid-run.
#[test]
fn a_sample_stamped_after_the_control_tick_time_is_not_silence() {
    use firmware::l3g4200d::Measurement;
    use firmware::rig::Rig;
    use protocol::GyroConfig;
    let mut rig = Rig::new(GyroConfig::DEFAULT);
    let t0 = u32::MAX - 10_000; // across the TIM5 wrap, too
    rig.power_up(t0, Ok(()), false);
    let m = Measurement { temp_raw: 20, status: 0x08, rate_counts: [1, 2, 3] };
    for k in 0..100u32 {
        let control_t = t0.wrapping_add(1_000 * k);
        // Interleaving: control reads TIM5 (control_t) → data-ready preempts, stamps control_t + 1
        // → control locks the rig and runs its tick with control_t.
        rig.data_ready(control_t.wrapping_add(1), 0, Ok::<_, ()>(m));
        rig.control_tick(control_t, 0);
        assert_eq!(rig.gyro_fault(), None, "tick {k}");
    }
    // Real silence is still caught.
    let late = t0.wrapping_add(1_000 * 99 + 1 + GYRO_SILENT_US + 1);
    rig.control_tick(late, 0);
    assert_eq!(rig.gyro_fault(), Some(Fault::GyroSilent));
}

/// B2: the MCU restarts (watchdog, panic, debugger) while the gyro keeps its power, its DRDY
/// high with an unread sample. The capture waits for a rising edge; the driver's discarded read
/// after configuring releases the line, so samples flow again without a power cycle.
#[test]
fn a_warm_reset_with_the_gyro_powered_and_drdy_high_recovers() {
    use firmware::l3g4200d::L3g4200d;
    use protocol::GyroConfig;
    // The gyro as the previous firmware left it: configured, a sample latched and never read.
    let mut before = L3g4200d::new(L3g4200dModel::new());
    before.configure(GyroConfig::DEFAULT).unwrap();
    let mut chip = before.release();
    assert!(chip.next_sample_s(0.0).is_some());
    chip.latch([0.0; 3], 20);
    assert!(chip.drdy(), "DRDY held high across the reset");
    let mut s = Session::new(VirtualRig::new(Plant::prototype(), chip, 0));
    s.run(S);
    assert!(s.faults().is_empty(), "{:?}", s.faults());
    let samples = s.msgs().filter(|m| matches!(m, RigMsg::Sample(_))).count();
    assert!(samples > 790, "{samples} samples in 1 s at 800 Hz");
}

/// B2: a data-ready edge the capture misses leaves DRDY high for good; once GyroSilent is in
/// force the core asks for the outputs to be read (`Rig::needs_drdy_release`), the next sample
/// raises an edge, and sampling resumes by itself, the fault cleared.
#[test]
fn a_missed_data_ready_edge_recovers_without_a_power_cycle() {
    let mut s = Session::prototype();
    s.run(S / 2);
    s.vr.missed_drdy_edges = 1;
    let lost_at = s.vr.now_ns();
    s.run(S / 2);
    assert_eq!(s.faults(), vec![Fault::GyroSilent], "reported once, while idle");
    assert_eq!(s.vr.rig.gyro_fault(), None, "cleared by the samples that followed");
    let after: Vec<u64> = s
        .frames
        .iter()
        .filter(|(t, _, m)| *t > lost_at + 100 * MS && matches!(m, RigMsg::Sample(_)))
        .map(|(t, _, _)| *t)
        .collect();
    assert!(after.len() > 300, "{} samples in the last 0.4 s", after.len());
}

/// The watchdog is fed only while the USB task runs: a hung USB task stops the feeding within
/// `TASK_ALIVE_US`, so the IWDG resets the MCU (bridge off through the EN pull-down).
#[test]
fn a_hung_usb_task_stops_the_watchdog_feed() {
    use firmware::rig::{Rig, TASK_ALIVE_US};
    use protocol::GyroConfig;
    let mut rig = Rig::new(GyroConfig::DEFAULT);
    let t0 = u32::MAX - 5_000; // across the TIM5 wrap
    rig.power_up(t0, Ok(()), false);
    let at = |ms: u32| t0.wrapping_add(1_000 * ms);
    for ms in 0..10 {
        rig.usb_task_ran(at(ms));
        rig.control_tick(at(ms), 0);
        assert!(rig.watchdog_may_feed(at(ms)), "{ms} ms");
    }
    // The USB task last ran at 9 ms, then hangs.
    let hung_until = 9 + TASK_ALIVE_US as u32 / 1_000;
    assert!(rig.watchdog_may_feed(at(hung_until)));
    assert!(!rig.watchdog_may_feed(at(hung_until + 1)));
    rig.usb_task_ran(at(hung_until + 2));
    assert!(rig.watchdog_may_feed(at(hung_until + 2)));
}
