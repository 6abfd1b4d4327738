//! `host configure-drive --port <pty>` against the firmware's virtual rig, step by step as
//! host/src/cli.rs runs it: the rig acknowledges a drive it can control, and the host says why
//! it refused one it cannot (a runaway it could not detect).

use e2e::LockstepRig;
use host::link::Link;
use host::session;
use protocol::DriveConfig;

#[test]
fn the_rig_takes_a_drive_it_can_control_and_the_host_says_why_it_refuses_one() {
    let rig = LockstepRig::spawn(env!("CARGO_BIN_EXE_virtual_rig"), &[]);
    let port = rig.path.clone();
    let clock = rig.clock();
    let mut link = Link::with_clock(rig, port.as_str(), Box::new(clock));
    session::identify(&mut link).expect("identify");
    session::configure_drive(&mut link, DriveConfig::from_si(33.0, 0.030, 24.0)).expect("a 33:1 drive");
    // 150:1 at 24 V tops out at 318 000 cps, below the 405 000 cps over-speed limit.
    let err = session::configure_drive(&mut link, DriveConfig::from_si(150.0, 0.012, 24.0)).unwrap_err();
    assert_eq!(
        err.to_string(),
        format!(
            "the rig on {port} refused the drive (150:1 gearhead, 0.012 kg·m² of load, 24 V): at full duty it would not exceed the rig's over-speed limit, so a runaway would go unnoticed (a lower ratio or a higher supply)"
        )
    );
}
