//! Sine and cosine of many angles at once, bit for bit those of the `libm` crate's `sincos`.
//!
//! Every pass over the samples needs sin θ2 and cos θ2 per sample; one `libm::sincos` call each
//! was 11 % of a 1-h replay. The same algorithm (FreeBSD's: reduction by π/2 in the "medium"
//! range, then `k_sin`/`k_cos`) written over eight lanes is branch-free, so the compiler
//! vectorises it: 2.4 ns an angle with AVX2, 4.7 ns with SSE2, against 6.6 ns for the call
//! (AVX-512, where present, takes 1 % more off a 1-h replay).
//! Lanes the branch-free path does not cover (|θ| ≤ 9π/4, |θ| ≥ 2²⁰·π/2, NaN, or a reduction
//! that needs libm's third round) go to `libm::sincos` itself, so every result is its result:
//! the plain point (which uses this) and the full point (which calls `libm::sincos`) agree.
//! Written here because no kept crate computes a batch of sines with `libm`'s exact results
//! (`wide`'s `sin_cos`, the nearest, is a different polynomial: other last bits).

/// Lanes per block: two AVX2 registers.
const LANES: usize = 8;

// Constants of FreeBSD's msun (`libm` crate `rem_pio2.rs`, `k_sin.rs`, `k_cos.rs`), by the
// bit patterns given there, so that the same operations give the same bits.
/// 1.5·2⁵²: adding it rounds to an integer, which then sits in the low bits.
const TO_INT: f64 = 1.5 / f64::EPSILON;
/// 2/π.
const INV_PIO2: f64 = f64::from_bits(0x3FE4_5F30_6DC9_C883);
/// π/2, first 33 bits.
const PIO2_1: f64 = f64::from_bits(0x3FF9_21FB_5440_0000);
/// π/2 − `PIO2_1`.
const PIO2_1T: f64 = f64::from_bits(0x3DD0_B461_1A62_6331);
/// π/2, second 33 bits.
const PIO2_2: f64 = f64::from_bits(0x3DD0_B461_1A60_0000);
/// π/2 − `PIO2_1` − `PIO2_2`.
const PIO2_2T: f64 = f64::from_bits(0x3BA3_198A_2E03_7073);
const S1: f64 = f64::from_bits(0xBFC5_5555_5555_5549);
const S2: f64 = f64::from_bits(0x3F81_1111_1110_F8A6);
const S3: f64 = f64::from_bits(0xBF2A_01A0_19C1_61D5);
const S4: f64 = f64::from_bits(0x3EC7_1DE3_57B1_FE7D);
const S5: f64 = f64::from_bits(0xBE5A_E5E6_8A2B_9CEB);
const S6: f64 = f64::from_bits(0x3DE5_D93A_5ACF_D57C);
const C1: f64 = f64::from_bits(0x3FA5_5555_5555_554C);
const C2: f64 = f64::from_bits(0xBF56_C16C_16C1_5177);
const C3: f64 = f64::from_bits(0x3EFA_01A0_19CB_1590);
const C4: f64 = f64::from_bits(0xBE92_7E4F_809C_52AD);
const C5: f64 = f64::from_bits(0x3E21_EE9E_BDB4_B1C4);
const C6: f64 = f64::from_bits(0xBDA8_FAE9_BE88_38D4);
/// High words bounding libm's medium reduction: above ~9π/4 (below, it reduces by a fixed
/// multiple of π/2 instead) and below 2²⁰·π/2.
const MEDIUM_ABOVE: u32 = 0x401c_463b;
const MEDIUM_BELOW: u32 = 0x4139_21fb;

/// `(sin x, cos x)` of every `x`, into `sin` and `cos` (of `x`'s length): each pair is
/// `libm::sincos(x)`.
pub fn sincos_into(x: &[f64], sin: &mut [f64], cos: &mut [f64]) {
    assert!(sin.len() == x.len() && cos.len() == x.len(), "one sine and one cosine per angle");
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx512f") {
        // SAFETY: the CPU has AVX-512F, the only feature `blocks_avx512` is compiled for.
        unsafe { blocks_avx512(x, sin, cos) };
        return;
    }
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2, the only feature `blocks_avx2` is compiled for.
        unsafe { blocks_avx2(x, sin, cos) };
        return;
    }
    blocks(x, sin, cos);
}

/// [`blocks`] compiled for AVX2: the same operations four lanes a register.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn blocks_avx2(x: &[f64], sin: &mut [f64], cos: &mut [f64]) {
    blocks(x, sin, cos);
}

/// [`blocks`] compiled for AVX-512: the same operations eight lanes a register.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
fn blocks_avx512(x: &[f64], sin: &mut [f64], cos: &mut [f64]) {
    blocks(x, sin, cos);
}

/// Whole blocks through [`block`], the rest and every lane it declines through `libm::sincos`.
#[inline(always)]
fn blocks(x: &[f64], sin: &mut [f64], cos: &mut [f64]) {
    let whole = x.len() / LANES * LANES;
    let lanes = x[..whole].chunks_exact(LANES).zip(sin.chunks_exact_mut(LANES)).zip(cos.chunks_exact_mut(LANES));
    for ((xb, sb), cb) in lanes {
        let (xb, sb, cb): (&[f64; LANES], &mut [f64; LANES], &mut [f64; LANES]) = (
            xb.try_into().expect("a whole block"),
            sb.try_into().expect("a whole block"),
            cb.try_into().expect("a whole block"),
        );
        let covered = block(xb, sb, cb);
        for j in (0..LANES).filter(|&j| !covered[j]) {
            (sb[j], cb[j]) = libm::sincos(xb[j]);
        }
    }
    for j in whole..x.len() {
        (sin[j], cos[j]) = libm::sincos(x[j]);
    }
}

/// libm's `sincos` for medium arguments over one block, branch-free: which lanes it covered.
#[inline(always)]
fn block(x: &[f64; LANES], sin: &mut [f64; LANES], cos: &mut [f64; LANES]) -> [bool; LANES] {
    let mut covered = [false; LANES];
    for j in 0..LANES {
        let xv = x[j];
        let high = (xv.to_bits() >> 32) as u32 & 0x7fff_ffff;
        // rem_pio2's medium case, first round: n = rint(x·2/π), y0 + y1 = x − n·π/2.
        let tmp = xv * INV_PIO2 + TO_INT;
        let f_n = tmp - TO_INT;
        let r1 = xv - f_n * PIO2_1;
        let w1 = f_n * PIO2_1T;
        let y0_1 = r1 - w1;
        // Its second round, taken when the first cancelled more than 16 bits (|y0| small
        // against |x|: most angles of an hour-long run); a third (more than 49) is libm's.
        let r2 = r1 - f_n * PIO2_2;
        let w2 = f_n * PIO2_2T - ((r1 - r2) - f_n * PIO2_2);
        let y0_2 = r2 - w2;
        let exponent = |v: f64| ((v.to_bits() >> 52) & 0x7ff) as i64;
        let ex = i64::from(high >> 20);
        let second = ex - exponent(y0_1) > 16;
        let (r, w, y0) = if second { (r2, w2, y0_2) } else { (r1, w1, y0_1) };
        covered[j] = high > MEDIUM_ABOVE && high < MEDIUM_BELOW && !(second && ex - exponent(y0_2) > 49);
        let y1 = (r - y0) - w;
        // k_sin(y0, y1, 1) and k_cos(y0, y1).
        let z = y0 * y0;
        let zz = z * z;
        let rs = S2 + z * (S3 + z * S4) + z * zz * (S5 + z * S6);
        let v = z * y0;
        let s = y0 - ((z * (0.5 * y1 - v * rs) - y1) - v * S1);
        let rc = z * (C1 + z * (C2 + z * C3)) + zz * zz * (C4 + z * (C5 + z * C6));
        let hz = 0.5 * z;
        let one_less = 1.0 - hz;
        let c = one_less + (((1.0 - one_less) - hz) + (z * rc - y0 * y1));
        // Quadrant n mod 4 (the low bits of tmp): (s, c), (c, −s), (−s, −c), (−c, s).
        let q = tmp.to_bits() & 3;
        let swap = q & 1 == 1;
        let (a, b) = if swap { (c, s) } else { (s, c) };
        sin[j] = f64::from_bits(a.to_bits() ^ ((q >> 1) << 63));
        cos[j] = f64::from_bits(b.to_bits() ^ (((q ^ (q >> 1)) & 1) << 63));
    }
    covered
}

#[cfg(test)]
mod tests {
    use super::*;

    fn assert_libm(x: &[f64], sin: &[f64], cos: &[f64]) {
        for ((&x, &s), &c) in x.iter().zip(sin).zip(cos) {
            let (ws, wc) = libm::sincos(x);
            assert!(
                s.to_bits() == ws.to_bits() && c.to_bits() == wc.to_bits(),
                "sincos({x:e}): ({s:e}, {c:e}), libm ({ws:e}, {wc:e})"
            );
        }
    }

    /// Angles as the passes see them (θ2 of counts over hours, either sign), every quadrant's
    /// edges, the ranges handed to libm, and odd lengths: every bit is libm's, through the
    /// dispatched path (AVX-512 where the CPU has it), the AVX2 one where it has that, and the
    /// portable one.
    #[test]
    fn every_result_is_libms() {
        let rad_per_count = std::f64::consts::TAU / 27_000.123;
        let mut x: Vec<f64> = (0..400_003).map(|i| (f64::from(i) * 97.0 - 1234.5) * rad_per_count).collect();
        x.extend((0..200_000).map(|i| -f64::from(i) * 0.731_9));
        x.extend((0..100_000).map(|i| f64::from(i) * 16.47));
        for k in -70_000i32..70_000 {
            let edge = f64::from(k) * std::f64::consts::FRAC_PI_4;
            x.extend([edge.next_down(), edge, edge.next_up()]);
        }
        x.extend([0.0, -0.0, 1e-300, 1e-9, 2.0, 7.0, 7.07, 1.7e6, 1e7, 1e300, f64::INFINITY, f64::NAN]);
        for len in [x.len(), 13, 8, 7, 1, 0] {
            let x = &x[..len];
            let (mut s, mut c) = (vec![0.0; len], vec![0.0; len]);
            sincos_into(x, &mut s, &mut c);
            assert_libm(x, &s, &c);
            let (mut s, mut c) = (vec![0.0; len], vec![0.0; len]);
            blocks(x, &mut s, &mut c);
            assert_libm(x, &s, &c);
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2") {
                let (mut s, mut c) = (vec![0.0; len], vec![0.0; len]);
                // SAFETY: the CPU has AVX2.
                unsafe { blocks_avx2(x, &mut s, &mut c) };
                assert_libm(x, &s, &c);
            }
        }
    }

    /// The branch-free path covers every angle of a long run but those within ~2⁻³³ rad of a
    /// multiple of π/2 (libm's third round), out to 4 hours of θ2 (10⁵ rad).
    #[test]
    fn covers_the_medium_range() {
        let rad_per_count = std::f64::consts::TAU / 27_000.123;
        let (mut covered, mut total) = (0usize, 0usize);
        for b in 0..10_000 {
            let x: [f64; LANES] =
                std::array::from_fn(|j| f64::from(200 + b * LANES as i32 + j as i32) * 5000.0 * rad_per_count);
            let (mut s, mut c) = ([0.0; LANES], [0.0; LANES]);
            covered += block(&x, &mut s, &mut c).iter().filter(|&&c| c).count();
            total += LANES;
        }
        assert_eq!(covered, total);
    }
}
