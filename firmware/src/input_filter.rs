//! The timers' input-capture digital filter (RM0090 §18.4.7/§17.4.7, TIMx_CCMRx ICxF): which
//! codes the board uses and how long a glitch each one rejects. Portable, so the host tests the
//! register values the rtic app writes (`board.rs`, `capture.rs`).

/// TIM2 and TIM5 kernel clock, Hz: APB1 at 42 MHz, doubled for the timers (RM0090 §7.2, the
/// clock tree `main.rs` configures: 168 MHz core, APB1 ÷4).
pub const TIMER_CLOCK_HZ: u32 = 84_000_000;

/// CR1.CKD of TIM2 and TIM5: f_DTS = f_CK_INT ÷ this (the code ÷4 is `0b10`).
pub const CKD_DIVIDER: u32 = 4;

/// ICxF of the encoder and data-ready channels: `0b0011`, 8 samples at f_CK_INT, 95 ns.
/// Identical on TIM2 and TIM5, so both latch the same edge after the same delay; the fastest
/// encoder edges (324 kHz at 1 Hz) are 3 µs apart.
pub const CAPTURE_ICF: u8 = 0b0011;

/// ICxF of the index channels (CH3 of TIM2 and TIM5): `0b1111`, 8 samples at f_DTS/32, 12.2 µs
/// with [`CKD_DIVIDER`]: a photo-interrupter's slow edge may ring for microseconds.
pub const INDEX_ICF: u8 = 0b1111;

/// (sampling clock divider of f_DTS, or 0 for f_CK_INT; samples N) for each ICxF code
/// (RM0090, TIMx_CCMR1 "IC1F").
const ICF_TABLE: [(u32, u32); 16] = [
    (0, 1), // 0000: no filter, sampled at f_DTS (one sample)
    (0, 2),
    (0, 4),
    (0, 8),
    (2, 6),
    (2, 8),
    (4, 6),
    (4, 8),
    (8, 6),
    (8, 8),
    (16, 5),
    (16, 6),
    (16, 8),
    (32, 5),
    (32, 6),
    (32, 8),
];

/// Shortest level the filter passes, ns: N consecutive samples at its sampling clock; codes
/// 0001-0011 sample at f_CK_INT, the others at f_DTS = f_CK_INT ÷ `ckd_divider` divided again.
/// Code 0000 (no filter) gives one f_DTS period. `icf` above 15 is read as its low 4 bits, as
/// the register field would hold it.
pub const fn filter_ns(icf: u8, timer_clock_hz: u32, ckd_divider: u32) -> u32 {
    let (div, n) = ICF_TABLE[(icf & 0x0F) as usize];
    let f_dts = timer_clock_hz / ckd_divider;
    let sample_hz = match (icf & 0x0F, div) {
        (0, _) => f_dts,
        (_, 0) => timer_clock_hz,
        _ => f_dts / div,
    };
    ((n as u64 * 1_000_000_000 + sample_hz as u64 / 2) / sample_hz as u64) as u32
}

/// The index filter as configured, ns.
pub const INDEX_FILTER_NS: u32 = filter_ns(INDEX_ICF, TIMER_CLOCK_HZ, CKD_DIVIDER);

/// The encoder and data-ready filter as configured, ns.
pub const CAPTURE_FILTER_NS: u32 = filter_ns(CAPTURE_ICF, TIMER_CLOCK_HZ, CKD_DIVIDER);

// The encoder's fastest edges (324 kHz at the 1 Hz limit, 3.09 µs apart) pass the capture filter
// with a tenfold margin; the index filter is a hundredth of the plate's passage (≈ 28 ms at 1 Hz).
const _: () = assert!(CAPTURE_FILTER_NS * 10 < 3_086, "the capture filter would eat encoder edges");
const _: () = assert!(INDEX_FILTER_NS < 28_000_000 / 100, "the index filter would eat the plate");

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_codes_reject_what_the_wiring_table_says() {
        // 8 / 84 MHz = 95.2 ns; 8 × 32 / 21 MHz = 12 190 ns.
        assert_eq!(CAPTURE_FILTER_NS, 95);
        assert_eq!(INDEX_FILTER_NS, 12_190);
        assert_eq!(crate::index::INDEX_FILTER_US, 12.19);
        // CKD slows only the f_DTS codes: the capture filter is the same at any CKD.
        assert_eq!(filter_ns(CAPTURE_ICF, TIMER_CLOCK_HZ, 1), CAPTURE_FILTER_NS);
        assert_eq!(filter_ns(INDEX_ICF, TIMER_CLOCK_HZ, 1), 3_048);
        // Table spot checks: 0100 = f_DTS/2, N=6; 1010 = f_DTS/16, N=5; 0000 = one f_DTS period.
        assert_eq!(filter_ns(0b0100, 84_000_000, 1), 143);
        assert_eq!(filter_ns(0b1010, 84_000_000, 1), 952);
        assert_eq!(filter_ns(0b0000, 84_000_000, 4), 48);
    }
}
