//! An [`Estimate`] printed as `value ± σ`: the format's width, fill, sign and precision apply to
//! the value and the precision to σ as well, so `{:+9.3}` prints `   +1.234 ± 0.005`.

use crate::calib::result::estimate::Estimate;
use std::fmt;

/// `value ± σ` (see the module doc).
pub struct PlusMinus(pub Estimate);

impl fmt::Display for PlusMinus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(&self.0.value, f)?;
        match f.precision() {
            Some(p) => write!(f, " ± {:.p$}", self.0.sigma),
            None => write!(f, " ± {}", self.0.sigma),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn width_and_sign_go_to_the_value_precision_to_both() {
        let e = Estimate::new(1.23449, 0.00512);
        assert_eq!(format!("{:+9.3}", PlusMinus(e)), "   +1.234 ± 0.005");
        assert_eq!(format!("{:.1}", PlusMinus(Estimate::new(-2.0, 0.26))), "-2.0 ± 0.3");
    }
}
