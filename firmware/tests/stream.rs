//! What the host receives: every gyro sample timestamped and counted, index edges exact to one
//! timer tick, a stalled link's losses counted, commands acknowledged — across the 32-bit wrap
//! of both the µs timer and the encoder counter (the prototype starts each 3 s / 1 turn short).

mod common;
use common::{Session, MS, S};
use firmware::plant::l3g4200d_model::L3g4200dModel;
use firmware::plant::Plant;
use firmware::virtual_rig::VirtualRig;
use protocol::{
    Bandwidth, CmdResult, Command, Counters, Direction, Edge, FullScale, GyroConfig, Odr, RigMsg, StartRun,
    ENCODER_COUNTS_PER_REV,
};

fn start(s: &mut Session, run_tag: u8) -> u16 {
    s.command(Command::Start(StartRun { rate_mdps: 180_000, direction: Direction::Ccw, run_tag }))
}

fn last_counters(s: &Session) -> Counters {
    s.msgs()
        .filter_map(|m| match m {
            RigMsg::Counters(c) => Some(*c),
            _ => None,
        })
        .last()
        .expect("counters")
}

#[test]
fn every_sample_is_timestamped_counted_and_carries_its_encoder_count() {
    let mut s = Session::prototype();
    start(&mut s, 1);
    s.run(10 * S);
    let samples: Vec<_> = s
        .msgs()
        .filter_map(|m| match m {
            RigMsg::Sample(x) => Some(*x),
            _ => None,
        })
        .collect();
    let truth = &s.vr.truth.samples;
    // Every data-ready produced exactly one frame (none queued at the end: all drained).
    assert_eq!(samples.len(), truth.len());
    assert_eq!(u64::from(s.vr.gyro.spi_mut().samples), truth.len() as u64);
    for (got, (t_ns, encoder, outputs)) in samples.iter().zip(truth) {
        assert_eq!(got.t_us, s.vr.timer_us(*t_ns), "timestamp is the capture, floor(µs)");
        assert_eq!(got.encoder, *encoder);
        assert_eq!(got.rate_counts, *outputs);
        assert_eq!(got.status, 0, "no overrun, no stale data");
    }
    // The timestamps show the gyro's real rate (1.2 % fast), not the nominal 800 Hz.
    let first = s.unwrap_us(samples[0].t_us);
    let last = s.unwrap_us(samples.last().unwrap().t_us);
    assert!(last > 3_000_000, "the run crossed the timer wrap");
    let period_us = (last - first) as f64 / (samples.len() - 1) as f64;
    assert!((period_us - 1e6 / 809.6).abs() < 0.01, "period {period_us} µs");
    // The rig's own count agrees; the last Counters frame came at most 1 s before the end.
    let c = last_counters(&s);
    let at_counters = samples.iter().filter(|x| s.unwrap_us(x.t_us) <= s.unwrap_us(c.t_us)).count();
    assert_eq!(c.samples_read as usize, at_counters);
    assert_eq!((c.queue_drops, c.spi_errors, c.rx_errors, c.gyro_overruns), (0, 0, 0, 0));
    assert_eq!(s.seq_gaps, 0);
}

#[test]
fn index_edges_are_exact_to_one_timer_tick_and_one_count() {
    let mut s = Session::prototype();
    start(&mut s, 1);
    s.run(12 * S);
    let edges: Vec<_> = s
        .msgs()
        .filter_map(|m| match m {
            RigMsg::Index(e) => Some(*e),
            _ => None,
        })
        .collect();
    let truth = &s.vr.truth.index_edges;
    assert_eq!(edges.len(), truth.len());
    assert!(edges.len() >= 9, "≈ 5 turns of θ2 in 12 s: {} edges", edges.len());
    for (e, (t_ns, encoder, level)) in edges.iter().zip(truth) {
        // Within one 1 µs tick of the true instant, never ahead of it.
        let true_us = t_ns / 1_000.0;
        let got_us = s.unwrap_us(e.t_us) as f64;
        assert!(got_us <= true_us && true_us - got_us < 1.0, "{got_us} vs {true_us}");
        assert_eq!(e.encoder, *encoder);
        assert_eq!(e.edge == Edge::Rising, *level);
    }
    // Physics check: once at speed, successive rising edges are one turn apart on the encoder
    // (1:1 gears) to within one count, and 2 s apart at 0.5 Hz to within 0.1 %.
    let rising: Vec<_> = edges.iter().filter(|e| e.edge == Edge::Rising).collect();
    for pair in rising.windows(2).skip(1) {
        let counts = pair[1].encoder.wrapping_sub(pair[0].encoder);
        assert!(counts.abs_diff(ENCODER_COUNTS_PER_REV) <= 1, "{counts}");
        let dt_us = pair[1].t_us.wrapping_sub(pair[0].t_us);
        assert!(dt_us.abs_diff(2_000_000) < 2_000, "{dt_us} µs per turn");
    }
    // Falling edges lead rising ones by the plate's 10° = 9 000 counts.
    let plate = edges
        .windows(2)
        .find(|p| p[0].edge == Edge::Rising && p[1].edge == Edge::Falling)
        .map(|p| p[1].encoder.wrapping_sub(p[0].encoder))
        .unwrap();
    assert!(plate.abs_diff(9_000) <= 1, "plate {plate} counts");
    assert_eq!(s.vr.rig.index_edges().1, 0, "no edge lost");
}

#[test]
fn a_stalled_link_drops_whole_frames_and_counts_every_one() {
    let mut s = Session::prototype();
    start(&mut s, 2);
    s.run(S);
    // The host stops reading for 1 s: 2 KiB of queue hold ≈ 100 of the ≈ 1 000 frames.
    s.vr.link_bytes_per_tick = 0;
    s.run(S);
    s.vr.link_bytes_per_tick = 1_024;
    s.run(2 * S);
    let c = last_counters(&s);
    assert!(c.queue_drops > 700, "{} drops", c.queue_drops);
    // Every drop is a sequence gap at the host, and nothing else is.
    assert_eq!(u64::from(c.queue_drops), s.seq_gaps);
    assert_eq!(c.frames_sent as usize + c.queue_drops as usize, {
        // frames offered up to that Counters frame = its own sequence number
        let (_, seq, _) = s.frames.iter().rfind(|(_, _, m)| matches!(m, RigMsg::Counters(_))).unwrap();
        usize::from(*seq)
    });
    // Sampling never stopped: the gyro never overran while the link was stalled.
    assert_eq!(c.gyro_overruns, 0);
    assert_eq!(c.samples_read as usize, {
        let t = s.unwrap_us(c.t_us) * 1_000;
        s.vr.truth.samples.iter().filter(|(ns, _, _)| *ns <= t).count()
    });
}

#[test]
fn commands_are_executed_in_order_and_acknowledged_after_their_effects() {
    let mut s = Session::prototype();
    s.run(100 * MS);
    // Power-up hello comes first.
    assert!(matches!(s.frames[0].2, RigMsg::Hello(h) if h.gyro == GyroConfig::DEFAULT
        && h.encoder_counts_per_rev == 324_000 && h.timestamp_hz == 1_000_000));

    let identify = s.command(Command::Identify);
    s.run(100 * MS);
    let hello_at = s.position(|m| matches!(m, RigMsg::Hello(_))).unwrap();
    let hello2 = s.frames.iter().skip(hello_at + 1).position(|(_, _, m)| matches!(m, RigMsg::Hello(_)));
    let ack_at = s.position(|m| matches!(m, RigMsg::Ack(a) if a.cmd_seq == identify)).unwrap();
    assert!(hello_at + 1 + hello2.unwrap() < ack_at, "Hello before its Ack");

    let slow = GyroConfig { full_scale: FullScale::Dps2000, odr: Odr::Hz100, bandwidth: Bandwidth::Bw0 };
    let configure = s.command(Command::ConfigureGyro(slow));
    s.run(S);
    assert_eq!(s.ack_for(configure), Some(CmdResult::Ok));
    assert!(s.msgs().any(|m| matches!(m, RigMsg::Hello(h) if h.gyro == slow)));
    assert_eq!(s.vr.gyro.spi_mut().register(0x20), 0x0F, "DR=00 BW=00 PD XYZ");
    assert_eq!(s.vr.gyro.spi_mut().register(0x23), 0xA0, "BDU, ±2000 °/s");

    let go = start(&mut s, 0x5A);
    let busy = s.command(Command::ConfigureGyro(GyroConfig::DEFAULT));
    let twice = start(&mut s, 0x5B);
    let heartbeat = s.command(Command::Heartbeat);
    s.run(3 * S);
    assert_eq!(s.ack_for(go), Some(CmdResult::Ok));
    assert_eq!(s.ack_for(busy), Some(CmdResult::Busy));
    assert_eq!(s.ack_for(twice), Some(CmdResult::Busy));
    assert_eq!(s.ack_for(heartbeat), Some(CmdResult::Ok));
    let started = s
        .msgs()
        .find_map(|m| match m {
            RigMsg::RunStarted(r) => Some(*r),
            _ => None,
        })
        .unwrap();
    assert_eq!((started.run_tag, started.rate_mdps, started.gyro), (0x5A, 180_000, slow));
    // MotorStatus carries the tag while running.
    assert!(s.msgs().any(|m| matches!(m, RigMsg::Motor(ms) if ms.run_tag == 0x5A && ms.setpoint_cps == 162_000)));
    // Samples now arrive at the new ODR: ≈ 101.2 Hz.
    let per_s = s.vr.truth.samples.iter().filter(|(t, _, _)| *t > s.vr.now_ns() - S).count();
    assert!((100..=102).contains(&per_s), "{per_s} samples in the last second");

    let stop = s.command(Command::Stop);
    s.run(3 * S);
    assert_eq!(s.ack_for(stop), Some(CmdResult::Ok));
    assert!(s.msgs().any(|m| matches!(m, RigMsg::RunStopped(r) if r.run_tag == 0x5A)));
    let out_of_range = s.command(Command::Start(StartRun { rate_mdps: 360_001, direction: Direction::Cw, run_tag: 1 }));
    s.run(100 * MS);
    assert_eq!(s.ack_for(out_of_range), Some(CmdResult::InvalidArgument));
    assert_eq!(last_counters(&s).rx_errors, 0);

    // Garbage on the line is counted, and the next good frame still gets through.
    s.wire.to_rig.extend([0x13, 0x37, 0x00, 0x05, 0x00]);
    let after = s.command(Command::Identify);
    s.run(1100 * MS);
    assert_eq!(s.ack_for(after), Some(CmdResult::Ok));
    assert_eq!(last_counters(&s).rx_errors, 2);
}

#[test]
fn starts_near_the_wrap_of_everything() {
    // Sanity of the fixture the other tests rely on.
    let vr = VirtualRig::new(Plant::prototype(), L3g4200dModel::new(), u32::MAX - 5);
    assert_eq!(vr.timer_us(6_000), 0);
    assert_eq!(Plant::prototype().encoder_count(), u32::MAX - 324_000);
}

/// A Start at 0 m°/s is a static run (noise figures): framed by RunStarted and RunStopped like
/// any run, samples streaming, the bridge disabled throughout; Stop ends it at once; the gyro
/// cannot be reconfigured under it; a silent host ends it with HostLinkLost.
#[test]
fn a_static_run_keeps_the_motor_off_and_is_framed_like_any_run() {
    let mut s = Session::prototype();
    s.run(200 * MS);
    let go_at = s.vr.now_ns();
    let go = s.command(Command::Start(StartRun::static_run(2)));
    s.run(10 * MS);
    let configure = s.command(Command::ConfigureGyro(GyroConfig::DEFAULT));
    s.run(3 * S);
    assert_eq!(s.ack_for(go), Some(CmdResult::Ok));
    assert_eq!(s.ack_for(configure), Some(CmdResult::Busy), "the run holds the gyro settings");
    let started = s
        .msgs()
        .find_map(|m| match m {
            RigMsg::RunStarted(r) => Some(*r),
            _ => None,
        })
        .expect("RunStarted");
    assert_eq!((started.run_tag, started.rate_mdps), (2, 0));
    let during: Vec<_> = s.probes.iter().filter(|p| p.t_ns > go_at).collect();
    assert!(during.len() > 2_900, "{} control ticks", during.len());
    assert!(during.iter().all(|p| !p.motor.enable && p.speed_cps == 0.0), "the bridge stays off, the table still");
    let motors: Vec<_> = s
        .msgs()
        .filter_map(|m| match m {
            RigMsg::Motor(ms) if ms.run_tag == 2 => Some(*ms),
            _ => None,
        })
        .collect();
    assert!(motors.len() >= 29, "{} Motor reports carry the run's tag", motors.len());
    assert!(motors.iter().all(|m| m.speed_cps == 0 && m.setpoint_cps == 0 && m.duty_permille == 0));

    // Stop: RunStopped before the Ack, with no ramp to wait for.
    let stop = s.command(Command::Stop);
    s.run(2 * MS);
    let pos = |pred: &dyn Fn(&RigMsg) -> bool| s.position(pred).expect("frame");
    let stopped = pos(&|m| matches!(m, RigMsg::RunStopped(r) if r.run_tag == 2));
    let acked = pos(&|m| matches!(m, RigMsg::Ack(a) if a.cmd_seq == stop));
    assert!(stopped < acked);
    assert!(s.faults().is_empty(), "{:?}", s.faults());

    // Another static run, then the host goes quiet: the link watchdog ends it, as any run.
    s.command(Command::Start(StartRun::static_run(3)));
    s.heartbeat = false;
    let quiet_from = s.vr.now_ns();
    s.run(2_500 * MS);
    assert_eq!(s.faults(), [protocol::Fault::HostLinkLost]);
    let t_stop_ns = s
        .msgs()
        .find_map(|m| match m {
            RigMsg::RunStopped(r) if r.run_tag == 3 => Some(s.unwrap_us(r.t_us) * 1_000),
            _ => None,
        })
        .expect("RunStopped after the trip");
    let after_ms = (t_stop_ns - quiet_from) / MS;
    assert!((2_000..=2_020).contains(&after_ms), "ended {after_ms} ms after the host fell silent");
}

/// ConfigureDrive is acknowledged: Ok when idle and in limits, InvalidArgument outside them (or
/// for a drive that could not reach the over-speed limit), Busy during a run.
#[test]
fn configure_drive_is_validated_and_refused_during_a_run() {
    use protocol::DriveConfig;
    let mut s = Session::prototype();
    let ok = s.command(Command::ConfigureDrive(DriveConfig::PROTOTYPE));
    let slow = s.command(Command::ConfigureDrive(DriveConfig { gear_ratio_milli: 150_000, ..DriveConfig::PROTOTYPE }));
    let zero = s.command(Command::ConfigureDrive(DriveConfig { supply_mv: 0, ..DriveConfig::PROTOTYPE }));
    s.run(10 * MS);
    start(&mut s, 1);
    s.run(10 * MS);
    let busy = s.command(Command::ConfigureDrive(DriveConfig::PROTOTYPE));
    s.run(10 * MS);
    assert_eq!(s.ack_for(ok), Some(CmdResult::Ok));
    assert_eq!(s.ack_for(slow), Some(CmdResult::InvalidArgument));
    assert_eq!(s.ack_for(zero), Some(CmdResult::InvalidArgument));
    assert_eq!(s.ack_for(busy), Some(CmdResult::Busy));
}
