//! Host side of the gyro calibration rig.
pub mod calib;
pub mod capture;
pub mod geometry;
pub mod inspect;
pub mod link;
pub mod report;
pub mod session;
pub mod sim;
pub mod virtual_rig;
