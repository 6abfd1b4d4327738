//! Captures → what the model is fitted to: the tables' kinematics reconstructed from the encoder
//! and index edges (per run: θ2, the base's rate, the die temperature), and the runs' layout
//! (which pose, which signed speed, which of them share a parameter). Imports only
//! [`super::result`].

pub mod encoder_rate;
pub mod kinematics;
pub mod layout;
pub mod runs;
