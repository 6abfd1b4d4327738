//! Prints the hex of representative frames (used to write the README's test vectors).
use protocol::*;

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect::<Vec<_>>().join(" ")
}

fn show<M: serde::Serialize + core::fmt::Debug>(seq: u16, m: &M) {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = encode_frame(seq, m, &mut buf).unwrap();
    let raw = postcard::to_allocvec(&(seq, m)).unwrap();
    println!(
        "{m:?}\n  seq {seq}\n  postcard {} ({} B)\n  crc {:08x}\n  frame {} ({} B)",
        hex(&raw),
        raw.len(),
        frame::crc32c(&raw),
        hex(&buf[..n]),
        n
    );
}

fn main() {
    show(
        0,
        &RigMsg::Hello(Hello {
            protocol_version: PROTOCOL_VERSION,
            firmware: Version { major: 0, minor: 1, patch: 0 },
            gyro: GyroConfig::DEFAULT,
            encoder_counts_per_rev: ENCODER_COUNTS_PER_REV,
            gear_ratio: GearRatio { num: 1, den: 1 },
            timestamp_hz: TIMESTAMP_HZ,
        }),
    );
    show(
        1,
        &RigMsg::Sample(Sample { t_us: 1_000_000, encoder: 4_294_967_000, rate_counts: [1000, -1000, 0], status: 0 }),
    );
    show(
        300,
        &RigMsg::Sample(Sample {
            t_us: 0xFFFF_FFFF,
            encoder: 0,
            rate_counts: [32767, -32768, -1],
            status: sample_status::OVERRUN,
        }),
    );
    show(2, &RigMsg::Index(IndexEdge { t_us: 123_456, encoder: 81_000, edge: Edge::Falling }));
    show(3, &RigMsg::Temperature(Temperature { t_us: 5, raw: -20 }));
    show(
        4,
        &RigMsg::Motor(MotorStatus {
            t_us: 2_000_000,
            speed_cps: 162_000,
            setpoint_cps: 162_000,
            duty_permille: 412,
            faults: 0,
            run_tag: 1,
        }),
    );
    show(
        5,
        &RigMsg::Counters(Counters {
            t_us: 3_000_000,
            frames_sent: 2412,
            queue_drops: 0,
            samples_read: 2400,
            gyro_overruns: 0,
            spi_errors: 0,
            rx_errors: 0,
        }),
    );
    show(6, &RigMsg::Ack(Ack { cmd_seq: 7, result: CmdResult::Ok }));
    show(
        7,
        &RigMsg::RunStarted(RunStarted {
            t_us: 10,
            run_tag: 2,
            rate_mdps: 180_000,
            direction: Direction::Cw,
            gyro: GyroConfig::DEFAULT,
        }),
    );
    show(8, &RigMsg::RunStopped(RunStopped { t_us: 11, run_tag: 2 }));
    show(9, &RigMsg::Fault(FaultReport { t_us: 12, fault: Fault::GyroAbsent { who_am_i: 0xFF } }));
    show(0, &Command::Identify);
    show(1, &Command::Start(StartRun { rate_mdps: 180_000, direction: Direction::Ccw, run_tag: 1 }));
    show(2, &Command::Stop);
    show(
        3,
        &Command::ConfigureGyro(GyroConfig {
            full_scale: FullScale::Dps2000,
            odr: Odr::Hz400,
            bandwidth: Bandwidth::Bw1,
        }),
    );
    show(4, &Command::Heartbeat);
    show(5, &Command::Start(StartRun::static_run(2)));
    show(6, &Command::ConfigureDrive(DriveConfig::PROTOTYPE));
}
