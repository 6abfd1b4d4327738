//! Host side of the gyro calibration rig.
pub mod allan;
pub mod calib;
pub mod capture;
pub mod certificate;
pub mod export;
pub mod files;
pub mod geometry;
pub mod inspect;
pub mod link;
pub mod provenance;
pub mod records;
pub mod report;
pub mod session;
pub mod sim;
pub mod spec;
pub mod thermal;
pub mod virtual_rig;
