//! The speed loop against the simulated drive: settling, ripple under the plant's disturbances
//! (12-pole magnetic-gear cogging, sensor-table unbalance, dry friction, PWM and encoder
//! quantisation), both directions, a load step, and a commanded stop.

mod common;
use common::{Session, MS, S};
use firmware::virtual_rig::Probe;
use protocol::{Command, Direction, RigMsg, StartRun};

const TOLERANCE: f64 = 1e-3; // the 0.1 % of setpoint

struct Figures {
    settling_s: f64,
    ripple_pp_pct: f64,
    ripple_rms_pct: f64,
    worst_pct: f64,
}

/// Settling: from the start command until the true speed enters ±0.1 % of the target for
/// good. Ripple: over the last `window` after settling, peak-to-peak and RMS of the deviation.
fn figures(probes: &[Probe], start_ns: u64, target_cps: f64) -> Figures {
    let dev = |p: &Probe| (p.speed_cps - target_cps) / target_cps.abs();
    let last_out = probes.iter().rposition(|p| dev(p).abs() > TOLERANCE).expect("must start outside the band");
    let settled = &probes[last_out + 1..];
    assert!(settled.len() > 5_000, "settled only in the last {} ms", settled.len());
    let devs: Vec<f64> = settled.iter().map(dev).collect();
    let max = devs.iter().cloned().fold(f64::MIN, f64::max);
    let min = devs.iter().cloned().fold(f64::MAX, f64::min);
    let rms = (devs.iter().map(|d| d * d).sum::<f64>() / devs.len() as f64).sqrt();
    Figures {
        settling_s: (settled[0].t_ns - start_ns) as f64 * 1e-9,
        ripple_pp_pct: (max - min) * 100.0,
        ripple_rms_pct: rms * 100.0,
        worst_pct: max.abs().max(min.abs()) * 100.0,
    }
}

fn run_at(rate_mdps: u32, direction: Direction) -> (Session, Figures) {
    let mut s = Session::prototype();
    s.run(200 * MS);
    let start_ns = s.vr.now_ns();
    s.command(Command::Start(StartRun { rate_mdps, direction, run_tag: 3 }));
    s.run(12 * S);
    let target = f64::from(direction.sign()) * f64::from(firmware::commands::rate_cps(rate_mdps));
    let probes: Vec<Probe> = s.probes.iter().filter(|p| p.t_ns > start_ns).copied().collect();
    let f = figures(&probes, start_ns, target);
    println!(
        "{rate_mdps} m°/s {direction:?}: settling {:.3} s, ripple {:.4} % p-p, {:.4} % RMS, worst {:.4} %",
        f.settling_s, f.ripple_pp_pct, f.ripple_rms_pct, f.worst_pct
    );
    (s, f)
}

#[test]
fn settles_within_a_tenth_of_a_percent_at_half_a_hertz_both_ways() {
    for direction in [Direction::Ccw, Direction::Cw] {
        let (s, f) = run_at(180_000, direction);
        // The ramp alone takes 2.0 s (162 000 cps at 81 000 cps/s).
        assert!(f.settling_s > 2.0 && f.settling_s < 2.5, "settling {} s", f.settling_s);
        assert!(f.worst_pct < 0.1);
        // What the host sees: MotorStatus speed (100 ms mean from the encoder) in the band too.
        let target = direction.sign() * 162_000;
        let late: Vec<i32> = s
            .frames
            .iter()
            .filter(|(t, _, _)| *t > 4 * S)
            .filter_map(|(_, _, m)| match m {
                RigMsg::Motor(ms) => Some(ms.speed_cps),
                _ => None,
            })
            .collect();
        assert!(late.len() > 70);
        for v in late {
            assert!((v - target).abs() <= 162, "reported {v} vs {target}");
        }
    }
}

#[test]
fn holds_the_mean_at_a_tenth_of_the_speed() {
    // 18 °/s = 16 200 cps: the band is 16 cps, below the loop's ≈ ±60 cps quantisation floor
    // (one encoder count and one PWM tick), so the instantaneous speed cannot hold 0.1 %; the
    // 100 ms mean the host receives must.
    let mut s = Session::prototype();
    s.command(Command::Start(StartRun { rate_mdps: 18_000, direction: Direction::Ccw, run_tag: 4 }));
    s.run(6 * S);
    let means: Vec<i32> = s
        .frames
        .iter()
        .filter(|(t, _, _)| *t > 2 * S)
        .filter_map(|(_, _, m)| match m {
            RigMsg::Motor(ms) => Some(ms.speed_cps),
            _ => None,
        })
        .collect();
    assert!(means.len() > 30);
    let worst = means.iter().map(|v| (v - 16_200).abs()).max().unwrap();
    let late: Vec<f64> = s.probes.iter().filter(|p| p.t_ns > 2 * S).map(|p| p.speed_cps).collect();
    let (lo, hi) = late.iter().fold((f64::MAX, f64::MIN), |(l, h), &v| (l.min(v), h.max(v)));
    println!(
        "18000 m°/s: 100 ms means within {worst} cps ({:.3} %), instantaneous {:.0}..{:.0} cps",
        f64::from(worst) / 162.0,
        lo,
        hi
    );
    assert!(worst <= 16, "100 ms mean off by {worst} cps");
}

#[test]
fn rejects_a_load_step() {
    let mut s = Session::prototype();
    s.command(Command::Start(StartRun { rate_mdps: 180_000, direction: Direction::Ccw, run_tag: 1 }));
    s.run(5 * S);
    // 50 mN·m of extra drag on the table (a cable, a finger): a third of the total friction.
    s.vr.plant.motor.load_nm = 0.05;
    let step_ns = s.vr.now_ns();
    s.run(3 * S);
    let after: Vec<&Probe> = s.probes.iter().filter(|p| p.t_ns > step_ns).collect();
    let dev = |p: &Probe| (p.speed_cps - 162_000.0).abs() / 162_000.0;
    let dip = after.iter().map(|p| dev(p)).fold(0.0, f64::max);
    let back = after.iter().rposition(|p| dev(p) > TOLERANCE).map_or(0.0, |i| (after[i].t_ns - step_ns) as f64 * 1e-6);
    println!("load step 50 mN·m: dip {:.3} %, back within 0.1 % after {back:.1} ms", dip * 100.0);
    assert!(back < 200.0, "took {back} ms");
}

#[test]
fn stop_ramps_down_and_ends_the_run() {
    let mut s = Session::prototype();
    s.command(Command::Start(StartRun { rate_mdps: 180_000, direction: Direction::Cw, run_tag: 9 }));
    s.run(4 * S);
    let stop_ns = s.vr.now_ns();
    let stop = s.command(Command::Stop);
    s.run(3 * S);
    assert_eq!(s.ack_for(stop), Some(protocol::CmdResult::Ok));
    let stopped = s
        .frames
        .iter()
        .find_map(|(t, _, m)| match m {
            RigMsg::RunStopped(r) => Some((*t, r.run_tag)),
            _ => None,
        })
        .expect("RunStopped");
    assert_eq!(stopped.1, 9);
    let ramp_down_s = (stopped.0 - stop_ns) as f64 * 1e-9;
    // 2 s of ramp plus the 50 ms stillness check, delivered at the next 500 ms chunk.
    assert!((2.0..2.6).contains(&ramp_down_s), "stopped after {ramp_down_s} s");
    let last = s.probes.last().unwrap();
    assert!(!last.motor.enable);
    assert_eq!(last.speed_cps, 0.0);
    assert!(s.faults().is_empty());
}

/// Table-speed jitter the encoder cannot resolve: the speed loop turns the encoder's one-count
/// flicker (1 000 cps in a single period) into torque every millisecond, and the table's speed
/// jitters at 20-400 Hz by a few hundredths of a degree per second, a fraction of a count of
/// angle. A gyro sees it; the host's θ1' (a straight line through 20 ms of encoder counts,
/// host/src/calib/data/kinematics.rs) does not. The calibration treats it as sensor noise, which holds
/// while it stays well below the L3G4200D's own: 0.03 °/s/√Hz over the 405 Hz Nyquist band is
/// 0.60 °/s rms. The bar: under a tenth of that, at both default speeds.
#[test]
fn jitter_the_encoder_cannot_see_is_far_below_the_gyro_noise() {
    // A noiseless, ideal gyro in pose 1: the sum of its axes is √3·θ1' (EXCITER.md).
    const DPS_PER_LSB: f64 = 17.5e-3;
    const DPS_PER_COUNT: f64 = 360.0 / 324_000.0;
    const HALF_WINDOW: usize = 8; // 17 samples at 809.6 Hz: the host's 20 ms
    for rate_mdps in [180_000, 90_000] {
        let mut s = Session::prototype();
        s.command(Command::Start(StartRun { rate_mdps, direction: Direction::Ccw, run_tag: 1 }));
        s.run(4 * S);
        s.vr.truth.samples.clear();
        s.run(20 * S);
        let samples = &s.vr.truth.samples;
        let t: Vec<f64> = samples.iter().map(|x| x.0 as f64 * 1e-9).collect();
        let first = samples[0].1;
        let counts: Vec<f64> = samples.iter().map(|x| f64::from(x.1.wrapping_sub(first) as i32)).collect();
        let gyro_dps: Vec<f64> = samples
            .iter()
            .map(|x| x.2.iter().map(|&c| f64::from(c)).sum::<f64>() * DPS_PER_LSB / 3f64.sqrt())
            .collect();
        let mut sum_sq = 0.0;
        let n = samples.len() - 2 * HALF_WINDOW;
        for (i, gyro) in gyro_dps.iter().enumerate().take(samples.len() - HALF_WINDOW).skip(HALF_WINDOW) {
            let w = i - HALF_WINDOW..=i + HALF_WINDOW;
            let k = (2 * HALF_WINDOW + 1) as f64;
            let (mt, mc) = (t[w.clone()].iter().sum::<f64>() / k, counts[w.clone()].iter().sum::<f64>() / k);
            let (mut num, mut den) = (0.0, 0.0);
            for j in w {
                num += (t[j] - mt) * (counts[j] - mc);
                den += (t[j] - mt) * (t[j] - mt);
            }
            let unseen = gyro - num / den * DPS_PER_COUNT;
            sum_sq += unseen * unseen;
        }
        let rms = (sum_sq / n as f64).sqrt();
        println!("{rate_mdps} m°/s: gyro rate minus the 20 ms encoder rate, {rms:.4} °/s rms over {n} samples");
        // Floor: the gyro's own LSB rounding, 17.5 m°/s / √12 per axis, over √3 axes / √3.
        assert!(rms > DPS_PER_LSB / 12f64.sqrt(), "{rms} °/s: below the rounding floor, the test measures nothing");
        assert!(rms < 0.060, "{rate_mdps} m°/s: {rms:.4} °/s of jitter unseen by the encoder");
    }
}

/// A rig built with another gearhead and heavier tables (33:1, 0.030 kg·m² of load): told so
/// with `ConfigureDrive`, the loop is designed for it and its 100 ms means hold ±0.1 %; left with
/// the prototype's gains, its feed-forward asks for twice the speed and it overshoots twice as
/// far.
#[test]
fn configure_drive_designs_the_loop_for_the_rig_it_runs() {
    use firmware::plant::l3g4200d_model::L3g4200dModel;
    use firmware::plant::motor::DriveParams;
    use firmware::plant::Plant;
    use firmware::virtual_rig::VirtualRig;
    use protocol::DriveConfig;
    let run = |configure: bool| {
        let mut plant = Plant::prototype();
        plant.motor.params = DriveParams {
            gear_ratio: 33.0,
            j_kgm2: 0.030 + 33.5e-7 * 33.0 * 33.0,
            coulomb_nm: 1.91e-3 * 33.0 + 0.020,
            ..DriveParams::PROTOTYPE
        };
        let mut s = Session::new(VirtualRig::new(plant, L3g4200dModel::new(), 0));
        s.run(100 * MS);
        if configure {
            let c = s.command(Command::ConfigureDrive(DriveConfig {
                gear_ratio_milli: 33_000,
                load_inertia_gcm2: 300_000,
                ..DriveConfig::PROTOTYPE
            }));
            s.run(100 * MS);
            assert_eq!(s.ack_for(c), Some(protocol::CmdResult::Ok));
        }
        let start_ns = s.vr.now_ns();
        s.command(Command::Start(StartRun { rate_mdps: 180_000, direction: Direction::Ccw, run_tag: 1 }));
        s.run(12 * S);
        let probes: Vec<Probe> = s.probes.iter().filter(|p| p.t_ns > start_ns).copied().collect();
        let dev: Vec<f64> = probes.iter().map(|p| (p.speed_cps / 162_000.0 - 1.0) * 100.0).collect();
        let late = &dev[6_000..];
        let worst = late.iter().fold(0.0f64, |m, d| m.max(d.abs()));
        let rms = (late.iter().map(|d| d * d).sum::<f64>() / late.len() as f64).sqrt();
        let overshoot = dev.iter().fold(0.0f64, |m, d| m.max(*d));
        // 100 ms means, as MotorStatus reports them.
        let means = late.chunks_exact(100).map(|c| c.iter().sum::<f64>() / 100.0);
        let worst_mean = means.fold(0.0f64, |m, d| m.max(d.abs()));
        println!(
            "33:1, configured {configure}: after 6 s worst {worst:.4} %, rms {rms:.4} %, 100 ms means within {worst_mean:.4} %; overshoot {overshoot:.4} %"
        );
        (worst_mean, rms, overshoot)
    };
    let (designed_means, _, designed_overshoot) = run(true);
    let (_, _, mismatched_overshoot) = run(false);
    // Measured: overshoot 0.20 % designed vs 0.41 % mismatched; the 100 ms means within 0.07 %
    // (steady ripple, 0.10 % RMS, is the same either way: with half the ratio the back-EMF damps
    // the cogging four times less).
    assert!(designed_means < 0.1, "100 ms means within {designed_means} %");
    assert!(
        designed_overshoot < 0.6 * mismatched_overshoot,
        "overshoot {designed_overshoot} % designed vs {mismatched_overshoot} % with the prototype's gains"
    );
}
