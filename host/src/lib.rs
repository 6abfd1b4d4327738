//! Host side of the gyro calibration rig.
pub mod capture;
pub mod geometry;
