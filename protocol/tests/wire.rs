//! The wire format, byte for byte: these vectors are the ones printed in protocol/README.md.

use protocol::*;

fn unhex(s: &str) -> Vec<u8> {
    s.split_whitespace().map(|b| u8::from_str_radix(b, 16).unwrap()).collect()
}

fn encode<M: serde::Serialize>(seq: u16, msg: &M) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = encode_frame(seq, msg, &mut buf).unwrap();
    buf[..n].to_vec()
}

fn hello() -> RigMsg {
    RigMsg::Hello(Hello {
        protocol_version: 1,
        firmware: Version { major: 0, minor: 1, patch: 0 },
        gyro: GyroConfig::DEFAULT,
        encoder_counts_per_rev: 324_000,
        gear_ratio: GearRatio { num: 1, den: 1 },
        timestamp_hz: 1_000_000,
    })
}

fn vectors() -> Vec<(u16, RigMsg, &'static str)> {
    vec![
        (0, hello(), "01 01 02 01 02 01 10 01 03 03 a0 e3 13 01 01 c0 84 3d c0 3c db 0f 00"),
        (
            1,
            RigMsg::Sample(Sample {
                t_us: 1_000_000,
                encoder: 4_294_967_000,
                rate_counts: [1000, -1000, 0],
                status: 0,
            }),
            "0f 01 01 c0 84 3d d8 fd ff ff 0f d0 0f cf 0f 01 05 ac 83 68 ab 00",
        ),
        (
            300,
            RigMsg::Sample(Sample {
                t_us: u32::MAX,
                encoder: 0,
                rate_counts: [32767, -32768, -1],
                status: sample_status::OVERRUN,
            }),
            "09 ac 02 01 ff ff ff ff 0f 0d fe ff 03 ff ff 03 01 01 9e d0 e1 5e 00",
        ),
        (
            2,
            RigMsg::Index(IndexEdge { t_us: 123_456, encoder: 81_000, edge: Edge::Falling }),
            "0e 02 02 c0 c4 07 e8 f8 04 01 a7 d8 29 c2 00",
        ),
        (3, RigMsg::Temperature(Temperature { t_us: 5, raw: -20 }), "09 03 03 05 ec ec 9c 30 33 00"),
        (
            4,
            RigMsg::Motor(MotorStatus {
                t_us: 2_000_000,
                speed_cps: 162_000,
                setpoint_cps: 162_000,
                duty_permille: 412,
                faults: 0,
                run_tag: 1,
            }),
            "0e 04 04 80 89 7a a0 e3 13 a0 e3 13 b8 06 06 01 22 db 44 4b 00",
        ),
        (
            5,
            RigMsg::Counters(Counters {
                t_us: 3_000_000,
                frames_sent: 2412,
                queue_drops: 0,
                samples_read: 2400,
                gyro_overruns: 0,
                spi_errors: 0,
                rx_errors: 0,
            }),
            "09 05 05 c0 8d b7 01 ec 12 03 e0 12 01 01 05 4d 25 a9 dd 00",
        ),
        (6, RigMsg::Ack(Ack { cmd_seq: 7, result: CmdResult::Ok }), "04 06 06 07 05 e7 66 fe 27 00"),
        (
            7,
            RigMsg::RunStarted(RunStarted {
                t_us: 10,
                run_tag: 2,
                rate_mdps: 180_000,
                direction: Direction::Cw,
                gyro: GyroConfig::DEFAULT,
            }),
            "10 07 07 0a 02 a0 fe 0a 01 01 03 03 83 c8 19 80 00",
        ),
        (8, RigMsg::RunStopped(RunStopped { t_us: 11, run_tag: 2 }), "09 08 08 0b 02 32 0d ba ce 00"),
        (
            9,
            RigMsg::Fault(FaultReport { t_us: 12, fault: Fault::GyroAbsent { who_am_i: 0xFF } }),
            "04 09 09 0c 06 ff d8 12 f7 98 00",
        ),
    ]
}

fn command_vectors() -> Vec<(u16, Command, &'static str)> {
    vec![
        (0, Command::Identify, "01 01 05 d2 77 61 f1 00"),
        (
            1,
            Command::Start(StartRun { rate_mdps: 180_000, direction: Direction::Ccw, run_tag: 1 }),
            "06 01 01 a0 fe 0a 06 01 86 e0 14 39 00",
        ),
        (2, Command::Stop, "07 02 02 cb 37 1f 37 00"),
        (
            3,
            Command::ConfigureGyro(GyroConfig {
                full_scale: FullScale::Dps2000,
                odr: Odr::Hz400,
                bandwidth: Bandwidth::Bw1,
            }),
            "0a 03 03 02 02 01 18 ae 22 f5 00",
        ),
        (4, Command::Heartbeat, "07 04 04 11 81 71 78 00"),
        // A static run: rate 0, motor off.
        (5, Command::Start(StartRun::static_run(2)), "03 05 01 01 06 02 66 7d 58 a1 00"),
        (6, Command::ConfigureDrive(DriveConfig::PROTOTYPE), "10 06 05 d0 83 04 c0 a9 07 c0 bb 01 29 cf d9 58 00"),
    ]
}

#[test]
fn crc_is_crc32c() {
    assert_eq!(frame::CRC32C.checksum(b"123456789"), 0xE306_9283);
    assert_eq!(frame::crc32c(b"123456789"), 0xE306_9283);
}

proptest::proptest! {
    /// The host's CRC (the CPU's instruction) and the firmware's (the byte table) agree on
    /// every frame length and content.
    #[test]
    fn host_and_firmware_crcs_agree(bytes in proptest::collection::vec(proptest::num::u8::ANY, 0..80)) {
        proptest::prop_assert_eq!(frame::crc32c(&bytes), frame::CRC32C.checksum(&bytes));
    }
}

#[test]
fn rig_messages_encode_to_the_documented_bytes() {
    for (seq, msg, hex) in vectors() {
        assert_eq!(encode(seq, &msg), unhex(hex), "{msg:?}");
    }
}

#[test]
fn host_commands_encode_to_the_documented_bytes() {
    for (seq, cmd, hex) in command_vectors() {
        assert_eq!(encode(seq, &cmd), unhex(hex), "{cmd:?}");
    }
}

#[test]
fn documented_bytes_decode_to_the_messages() {
    let stream: Vec<u8> = vectors().iter().flat_map(|(_, _, h)| unhex(h)).collect();
    let mut got = Vec::new();
    StreamDecoder::new().feed::<RigMsg>(&stream, |ev| got.push(ev));
    let mut offset = 0u64;
    for ((seq, msg, hex), ev) in vectors().into_iter().zip(&got) {
        assert_eq!(ev, &Event::Frame { offset, seq, msg });
        offset += unhex(hex).len() as u64;
    }
    assert_eq!(got.len(), vectors().len());
}

#[test]
fn the_readme_quotes_every_vector() {
    let readme = include_str!("../README.md");
    for hex in vectors().iter().map(|v| v.2).chain(command_vectors().iter().map(|v| v.2)) {
        assert!(readme.contains(hex), "README lacks vector {hex}");
    }
}

/// Every message with every field at its longest encoding.
fn worst_case() -> [RigMsg; 7] {
    let m = u32::MAX;
    [
        RigMsg::Hello(Hello {
            protocol_version: u16::MAX,
            firmware: Version { major: 255, minor: 255, patch: 255 },
            gyro: GyroConfig::DEFAULT,
            encoder_counts_per_rev: m,
            gear_ratio: GearRatio { num: u16::MAX, den: u16::MAX },
            timestamp_hz: m,
        }),
        RigMsg::Sample(Sample { t_us: m, encoder: m, rate_counts: [i16::MIN; 3], status: 255 }),
        RigMsg::Index(IndexEdge { t_us: m, encoder: m, edge: Edge::Falling }),
        RigMsg::Temperature(Temperature { t_us: m, raw: -128 }),
        RigMsg::Motor(MotorStatus {
            t_us: m,
            speed_cps: i32::MIN,
            setpoint_cps: i32::MIN,
            duty_permille: i16::MIN,
            faults: 255,
            run_tag: 255,
        }),
        RigMsg::Counters(Counters {
            t_us: m,
            frames_sent: m,
            queue_drops: m,
            samples_read: m,
            gyro_overruns: m,
            spi_errors: m,
            rx_errors: m,
        }),
        RigMsg::RunStarted(RunStarted {
            t_us: m,
            run_tag: 255,
            rate_mdps: m,
            direction: Direction::Cw,
            gyro: GyroConfig::DEFAULT,
        }),
    ]
}

/// The largest value of every field must still fit in [`MAX_FRAME_LEN`].
#[test]
fn worst_case_frames_fit() {
    for msg in worst_case() {
        let n = encode(u16::MAX, &msg).len();
        assert!(n <= MAX_FRAME_LEN, "{msg:?}: {n} > {MAX_FRAME_LEN}");
    }
    assert_eq!(MAX_FRAME_LEN, 54);
}

/// The link budget of protocol/README.md: worst-case bytes per second at ODR 800 Hz.
#[test]
fn link_budget_at_800_hz() {
    let len: Vec<u32> = worst_case().iter().map(|msg| encode(u16::MAX, msg).len() as u32).collect();
    let (sample, index, temp, motor, counters) = (len[1], len[2], len[3], len[4], len[5]);
    assert_eq!((sample, index, temp, motor, counters), (30, 21, 16, 30, 45));
    // Per second: 800 samples, 2 index edges per sensor-table turn at up to 1 Hz drive (4),
    // 1 temperature, 10 motor status, 1 counters.
    let bytes_per_s = 800 * sample + 4 * index + temp + 10 * motor + counters;
    assert_eq!(bytes_per_s, 24_445);
    // USART at 921 600 baud, 8N1: 10 bits per byte.
    let uart_bytes_per_s = 921_600 / 10;
    assert!(bytes_per_s * 100 / uart_bytes_per_s < 50);
}
