//! Rust source: the correction as a `const` item with an `apply` method, `no_std` and free of
//! dependencies, to `include!` or copy into a firmware crate. `f32` for the same reason as the C
//! header (single-precision FPU on Cortex-M4F), with the same split coefficients and the same
//! bound ([`super::SplitRow`]): `apply_split` agrees with `host apply` to 2^(e−19) °/s over the
//! whole int16 range, `apply` adds its own rounding. Rust neither contracts nor reassociates
//! float operations, so the error-free sums hold as written. `apply_with` also removes the
//! offset drift and the g-sensitivity (zero terms where the calibration's model has none), and
//! the header lists what it leaves out.
//!
//! A thermal calibration's module ([`render_thermal`]) takes the OUT_TEMP reading as an input,
//! `GYROCAL.apply(raw, temp_raw)`: the same split rows, one per reading of the calibrated range
//! ([`super::ThermalTable`]), the range in the comment and in fields, `Err(OutOfRange)` outside.

use super::{f32_literal, sanitise, Export, ThermalRow, ThermalTable};
use std::fmt::Write as _;

fn row(r: [f64; 3]) -> String {
    format!("[{}, {}, {}]", f32_literal(r[0]), f32_literal(r[1]), f32_literal(r[2]))
}

/// The identity, model, `extra` lines, provenance and what it leaves out, as `//` comments.
fn head(e: &Export, extra: &[String]) -> String {
    super::header_comment(e, "rust", extra, ("// ", "// "))
}

/// `exp_neg`, the warm-up's exponential in the generated module.
const EXP_NEG: &str = r#"/// e^(−x) for x ≥ 0 in f32 without `std` (core has no `exp`): x = n ln 2 + r, |r| ≤ ln 2 / 2,
/// e^(−r) by its Taylor series to r⁷ (remainder below 2e-8 relative), 2^(−n) from the bits.
fn exp_neg(x: f32) -> f32 {
    if !(x < 87.0) {
        return if x >= 87.0 { 0.0 } else { f32::NAN };
    }
    let x = if x < 0.0 { 0.0 } else { x };
    let n = (x * core::f32::consts::LOG2_E + 0.5) as i32;
    let r = -(x - n as f32 * core::f32::consts::LN_2);
    let mut p = 1.0f32;
    let mut k = 7;
    while k > 0 {
        p = 1.0 + r * p / k as f32;
        k -= 1;
    }
    p * f32::from_bits(((127 - n) as u32) << 23)
}
"#;

/// Renders the module text.
pub fn render(e: &Export) -> String {
    let mut o = head(e, &[]);
    let serial = sanitise(e.serial());
    let date = sanitise(e.date());
    let odr = e.gyro.map_or("None".to_string(), |g| format!("Some({})", g.odr.hz()));
    let bw = e.gyro.map_or("None".to_string(), |g| format!("Some({})", g.bandwidth.bw_bits()));
    let m = &e.m_inv_dps_per_count;
    let off = e.calibration.offset_counts;
    let b = e.offset_rate_dps();
    let sp = e.split();
    let t = e.rate_terms();
    let _ = writeln!(
        o,
        r#"
/// A gyro calibration: `rate = m_inv * raw - offset_rate` (°/s, package frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GyroCal {{
    /// Serial of the sensor it belongs to.
    pub sensor_serial: &'static str,
    /// When it was computed, UTC, RFC 3339.
    pub date_utc: &'static str,
    /// Full scale the raw counts must be taken at, °/s.
    pub full_scale_dps: u16,
    /// Output data rate it was calibrated at, Hz (None: not recorded).
    pub odr_hz: Option<u16>,
    /// CTRL_REG1 BW[1:0] it was calibrated at (None: not recorded).
    pub bandwidth_bits: Option<u8>,
    /// (K S)⁻¹, °/s per count; row i gives axis i.
    pub m_inv_dps_per_count: [[f32; 3]; 3],
    /// Offsets, counts.
    pub offset_counts: [f32; 3],
    /// (K S)⁻¹ times the offsets, °/s.
    pub offset_rate_dps: [f32; 3],
    /// `m_inv_dps_per_count` split in three per row: high parts on a grid of 2^(e−7) and…
    pub m_inv_hi: [[f32; 3]; 3],
    /// …middle parts on 2^(e−14), each with at most 7 significant bits, so every product with a
    /// raw count and every partial sum is exact in f32…
    pub m_inv_mid: [[f32; 3]; 3],
    /// …and the remainder, the only part that rounds.
    pub m_inv_lo: [[f32; 3]; 3],
    /// `offset_rate_dps` split on the same grids: high…
    pub offset_rate_hi: [f32; 3],
    /// …middle…
    pub offset_rate_mid: [f32; 3],
    /// …and the remainder.
    pub offset_rate_lo: [f32; 3],
    /// Proven bound on `|hi + lo − (K S)⁻¹ (raw − v_off)|` of [`GyroCal::apply_split`], °/s,
    /// for every raw reading.
    pub split_bound_dps: f64,
    /// Warm-up drift in the rate at power-up, `(K S)⁻¹ c`, °/s, decaying as exp(−t/T) (zero
    /// without a warm-up model).
    pub warm_up_rate_dps: [f32; 3],
    /// The warm-up's T, s.
    pub warm_up_tau_s: f32,
    /// Temperature drift in the rate, `(K S)⁻¹ β`, °/s per °C (zero without one).
    pub temp_rate_dps_per_c: [f32; 3],
    /// The OUT_TEMP reading where the temperature drift is zero, LSB (OUT_TEMP falls 1 LSB per
    /// °C, L3G4200D datasheet Table 5).
    pub temp_reference_lsb: f32,
    /// g-sensitivity in the rate, `(K S)⁻¹ diag(k) G`, °/s per g of specific force along
    /// package x, y, z (zero without a fitted one).
    pub g_rate_dps_per_g: [[f32; 3]; 3],
}}

{EXP_NEG}
impl GyroCal {{
    /// Rate vector in the package frame, °/s, from one raw reading (counts), as the unevaluated
    /// sum `hi + lo` of two f32 (|lo| ≤ half an ulp of hi): this is what agrees with `host apply`
    /// (f64) to `split_bound_dps` over the whole i16 range, which one f32 cannot above 256 °/s.
    #[inline]
    pub fn apply_split(&self, raw: [i16; 3]) -> ([f32; 3], [f32; 3]) {{
        let (x, y, z) = (raw[0] as f32, raw[1] as f32, raw[2] as f32);
        let (mut hi, mut lo) = ([0.0f32; 3], [0.0f32; 3]);
        let mut i = 0;
        while i < 3 {{
            let (h, m, l) = (&self.m_inv_hi[i], &self.m_inv_mid[i], &self.m_inv_lo[i]);
            // Exact: multiples of the row's grid below 2^24 steps.
            let a = h[0] * x + h[1] * y + h[2] * z - self.offset_rate_hi[i];
            let b = m[0] * x + m[1] * y + m[2] * z - self.offset_rate_mid[i];
            // The one sum that rounds: its terms are below 2^e.
            let c = l[0] * x + l[1] * y + l[2] * z - self.offset_rate_lo[i];
            // TwoSum (Knuth): s + t == a + b exactly; then once more to normalise hi + lo.
            let s = a + b;
            let bv = s - a;
            let t = (a - (s - bv)) + (b - bv);
            let u = t + c;
            hi[i] = s + u;
            let bv = hi[i] - s;
            lo[i] = (s - (hi[i] - bv)) + (u - bv);
            i += 1;
        }}
        (hi, lo)
    }}

    /// Rate vector in the package frame, °/s: `hi` of [`GyroCal::apply_split`], its sum rounded
    /// once; within half an f32 ulp plus `split_bound_dps` of `host apply`.
    #[inline]
    pub fn apply(&self, raw: [i16; 3]) -> [f32; 3] {{
        self.apply_split(raw).0
    }}

    /// [`GyroCal::apply`] with the drift and the g-sensitivity removed: `t_s` seconds since
    /// power-up (the calibration takes its session's first sample as power-up), `out_temp_lsb`
    /// the die temperature as OUT_TEMP (the calibration averaged it over 20 s),
    /// `specific_force_g` what an accelerometer on the same package reads, g (+1 g up at rest;
    /// None: no g-sensitivity applied). Within half an f32 ulp plus `split_bound_dps` plus the
    /// f32 rounding of the terms (about 1e-7 of their size) of `host`'s double-precision
    /// reference (`Export::apply_with`).
    pub fn apply_with(&self, raw: [i16; 3], t_s: f32, out_temp_lsb: f32, specific_force_g: Option<[f32; 3]>) -> [f32; 3] {{
        let (hi, lo) = self.apply_split(raw);
        let decay = exp_neg(t_s / self.warm_up_tau_s);
        let dtemp_c = -(out_temp_lsb - self.temp_reference_lsb);
        let mut out = [0.0f32; 3];
        let mut i = 0;
        while i < 3 {{
            let mut terms = self.warm_up_rate_dps[i] * decay + self.temp_rate_dps_per_c[i] * dtemp_c;
            if let Some(f) = specific_force_g {{
                let g = &self.g_rate_dps_per_g[i];
                terms += g[0] * f[0] + g[1] * f[1] + g[2] * f[2];
            }}
            out[i] = hi[i] + (lo[i] - terms);
            i += 1;
        }}
        out
    }}
}}

/// The calibration of sensor {serial}.
pub const GYROCAL: GyroCal = GyroCal {{
    sensor_serial: "{serial}",
    date_utc: "{date}",
    full_scale_dps: {fs},
    odr_hz: {odr},
    bandwidth_bits: {bw},
    m_inv_dps_per_count: [{r0}, {r1}, {r2}],
    offset_counts: {off},
    offset_rate_dps: {b},
    m_inv_hi: [{h0}, {h1}, {h2}],
    m_inv_mid: [{d0}, {d1}, {d2}],
    m_inv_lo: [{l0}, {l1}, {l2}],
    offset_rate_hi: {bh},
    offset_rate_mid: {bd},
    offset_rate_lo: {bl},
    split_bound_dps: {bound:e},
    warm_up_rate_dps: {wu},
    warm_up_tau_s: {tau},
    temp_rate_dps_per_c: {tc},
    temp_reference_lsb: {tref},
    g_rate_dps_per_g: [{g0}, {g1}, {g2}],
}};"#,
        fs = e.calibration.full_scale.range_dps(),
        r0 = row(m[0]),
        r1 = row(m[1]),
        r2 = row(m[2]),
        off = row(off),
        b = row(b),
        h0 = row(sp.rows[0].m_hi),
        h1 = row(sp.rows[1].m_hi),
        h2 = row(sp.rows[2].m_hi),
        d0 = row(sp.rows[0].m_mid),
        d1 = row(sp.rows[1].m_mid),
        d2 = row(sp.rows[2].m_mid),
        l0 = row(sp.rows[0].m_lo),
        l1 = row(sp.rows[1].m_lo),
        l2 = row(sp.rows[2].m_lo),
        bh = row([sp.rows[0].b_hi, sp.rows[1].b_hi, sp.rows[2].b_hi]),
        bd = row([sp.rows[0].b_mid, sp.rows[1].b_mid, sp.rows[2].b_mid]),
        bl = row([sp.rows[0].b_lo, sp.rows[1].b_lo, sp.rows[2].b_lo]),
        bound = sp.rows.iter().map(super::SplitRow::bound_dps).fold(0.0, f64::max),
        wu = row(t.warm_up_dps),
        tau = f32_literal(t.warm_up_tau_s),
        tc = row(t.temperature_dps_per_c),
        tref = f32_literal(t.reference_out_temp_lsb),
        g0 = row(t.g_dps_per_g[0]),
        g1 = row(t.g_dps_per_g[1]),
        g2 = row(t.g_dps_per_g[2]),
    );
    o
}

/// Renders the module of a thermal calibration: the correction at each OUT_TEMP reading of the
/// calibrated range ([`ThermalTable`]) and `GyroCal::apply(raw, temp_raw)`, its split and drift
/// forms, each `Err(OutOfRange)` outside the range.
pub fn render_thermal(e: &Export, t: &ThermalTable) -> String {
    let mut o = head(e, &super::temperature::header_lines(t));
    let serial = sanitise(e.serial());
    let [min_lsb, max_lsb] = t.out_temp_range_lsb();
    let terms = e.rate_terms();
    let _ = writeln!(o, "{THERMAL_ITEMS}\n{EXP_NEG}");
    let _ = writeln!(
        o,
        r#"/// The calibration of sensor {serial}.
pub const GYROCAL: GyroCal = GyroCal {{
    sensor_serial: "{serial}",
    date_utc: "{date}",
    full_scale_dps: {fs},
    odr_hz: {odr},
    bandwidth_bits: {bw},
    out_temp_min_lsb: {min_lsb},
    out_temp_max_lsb: {max_lsb},
    out_temp_at_0c: {c0},
    temp_range_c: [{cold}, {warm}],
    rows: &GYROCAL_ROWS,
    split_bound_dps: {bound:e},
    warm_up_rate_dps: {wu},
    warm_up_tau_s: {tau},
    g_rate_dps_per_g: [{g0}, {g1}, {g2}],
}};

/// The thermal model's calibration at each OUT_TEMP reading, `out_temp_min_lsb` first.
const GYROCAL_ROWS: [GyroCalRow; {n}] = [
{rows}];"#,
        date = sanitise(e.date()),
        fs = e.calibration.full_scale.range_dps(),
        odr = e.gyro.map_or("None".to_string(), |g| format!("Some({})", g.odr.hz())),
        bw = e.gyro.map_or("None".to_string(), |g| format!("Some({})", g.bandwidth.bw_bits())),
        c0 = f32_literal(t.model.out_temp_at_0c),
        cold = f32_literal(t.temp_range_c()[0]),
        warm = f32_literal(t.temp_range_c()[1]),
        bound = t.bound_dps(),
        wu = row(terms.warm_up_dps),
        tau = f32_literal(terms.warm_up_tau_s),
        g0 = row(terms.g_dps_per_g[0]),
        g1 = row(terms.g_dps_per_g[1]),
        g2 = row(terms.g_dps_per_g[2]),
        n = t.rows.len(),
        rows = t.rows.iter().map(rust_row).collect::<String>(),
    );
    o
}

/// One row of the Rust table, with its reading and die temperature as a comment.
fn rust_row(r: &ThermalRow) -> String {
    let m = |f: &dyn Fn(&super::SplitRow) -> [f64; 3]| {
        format!("[{}, {}, {}]", row(f(&r.split.rows[0])), row(f(&r.split.rows[1])), row(f(&r.split.rows[2])))
    };
    let b = |f: &dyn Fn(&super::SplitRow) -> f64| row(r.split.rows.map(|s| f(&s)));
    format!(
        "    // OUT_TEMP {}: die {:.2} °C\n    GyroCalRow {{ m_inv_hi: {}, m_inv_mid: {}, m_inv_lo: {}, \
         offset_rate_hi: {}, offset_rate_mid: {}, offset_rate_lo: {} }},\n",
        r.out_temp_lsb,
        r.temp_c,
        m(&|s| s.m_hi),
        m(&|s| s.m_mid),
        m(&|s| s.m_lo),
        b(&|s| s.b_hi),
        b(&|s| s.b_mid),
        b(&|s| s.b_lo),
    )
}

/// The thermal module's types and methods (everything but the numbers).
const THERMAL_ITEMS: &str = r#"
/// The correction at one OUT_TEMP reading: `rate = m_inv * raw - offset_rate` (°/s, package
/// frame), each row split in three: high parts on a grid of 2^(e−7) and middle parts on
/// 2^(e−14), each with at most 7 significant bits, so that every product with a raw count and
/// every partial sum is exact in f32; the low parts the remainder, the only part that rounds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GyroCalRow {
    /// (K S)⁻¹ at this reading, °/s per count: high parts…
    pub m_inv_hi: [[f32; 3]; 3],
    /// …middle parts…
    pub m_inv_mid: [[f32; 3]; 3],
    /// …and the remainder.
    pub m_inv_lo: [[f32; 3]; 3],
    /// (K S)⁻¹ v_off at this reading, °/s: high…
    pub offset_rate_hi: [f32; 3],
    /// …middle…
    pub offset_rate_mid: [f32; 3],
    /// …and the remainder.
    pub offset_rate_lo: [f32; 3],
}

/// An OUT_TEMP reading outside the calibrated range: the thermal model is not extrapolated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutOfRange {
    /// The reading, LSB.
    pub temp_raw: i8,
}

/// A gyro calibration over temperature: the correction at each OUT_TEMP reading of its range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GyroCal {
    /// Serial of the sensor it belongs to.
    pub sensor_serial: &'static str,
    /// When it was computed, UTC, RFC 3339.
    pub date_utc: &'static str,
    /// Full scale the raw counts must be taken at, °/s.
    pub full_scale_dps: u16,
    /// Output data rate it was calibrated at, Hz (None: not recorded).
    pub odr_hz: Option<u16>,
    /// CTRL_REG1 BW[1:0] it was calibrated at (None: not recorded).
    pub bandwidth_bits: Option<u8>,
    /// The lowest OUT_TEMP reading it holds for, LSB.
    pub out_temp_min_lsb: i8,
    /// The highest OUT_TEMP reading it holds for, LSB.
    pub out_temp_max_lsb: i8,
    /// Die temperature = `out_temp_at_0c − OUT_TEMP`, °C (the thermal model's scale).
    pub out_temp_at_0c: f32,
    /// Die temperatures of the range's readings, °C, coldest first.
    pub temp_range_c: [f32; 2],
    /// The correction at each reading, `out_temp_min_lsb` first.
    pub rows: &'static [GyroCalRow],
    /// Proven bound on `|hi + lo − (K S)⁻¹ (raw − v_off)|` of [`GyroCal::apply_split`], °/s,
    /// for every raw reading at every reading of the range.
    pub split_bound_dps: f64,
    /// Warm-up drift in the rate at power-up, `(K S)⁻¹ c` of the base calibration, °/s,
    /// decaying as exp(−t/T) (zero without a warm-up model).
    pub warm_up_rate_dps: [f32; 3],
    /// The warm-up's T, s.
    pub warm_up_tau_s: f32,
    /// g-sensitivity in the rate, `(K S)⁻¹ diag(k) G` of the base calibration, °/s per g of
    /// specific force along package x, y, z (zero without a fitted one).
    pub g_rate_dps_per_g: [[f32; 3]; 3],
}

impl GyroCal {
    /// The row of an OUT_TEMP reading, or `Err` outside the calibrated range.
    pub fn row(&self, temp_raw: i8) -> Result<&GyroCalRow, OutOfRange> {
        if temp_raw < self.out_temp_min_lsb || temp_raw > self.out_temp_max_lsb {
            return Err(OutOfRange { temp_raw });
        }
        self.rows.get((temp_raw as i16 - self.out_temp_min_lsb as i16) as usize).ok_or(OutOfRange { temp_raw })
    }

    /// Rate vector in the package frame, °/s, from one raw reading (counts) at the OUT_TEMP
    /// reading `temp_raw`, as the unevaluated sum `hi + lo` of two f32 (|lo| ≤ half an ulp of
    /// hi): within `split_bound_dps` of `host apply --temp-c` at that reading's die temperature
    /// over the whole i16 range. `Err` outside the calibrated range.
    #[inline]
    pub fn apply_split(&self, raw: [i16; 3], temp_raw: i8) -> Result<([f32; 3], [f32; 3]), OutOfRange> {
        let r = self.row(temp_raw)?;
        let (x, y, z) = (raw[0] as f32, raw[1] as f32, raw[2] as f32);
        let (mut hi, mut lo) = ([0.0f32; 3], [0.0f32; 3]);
        let mut i = 0;
        while i < 3 {
            let (h, m, l) = (&r.m_inv_hi[i], &r.m_inv_mid[i], &r.m_inv_lo[i]);
            // Exact: multiples of the row's grid below 2^24 steps.
            let a = h[0] * x + h[1] * y + h[2] * z - r.offset_rate_hi[i];
            let b = m[0] * x + m[1] * y + m[2] * z - r.offset_rate_mid[i];
            // The one sum that rounds: its terms are below 2^e.
            let c = l[0] * x + l[1] * y + l[2] * z - r.offset_rate_lo[i];
            // TwoSum (Knuth): s + t == a + b exactly; then once more to normalise hi + lo.
            let s = a + b;
            let bv = s - a;
            let t = (a - (s - bv)) + (b - bv);
            let u = t + c;
            hi[i] = s + u;
            let bv = hi[i] - s;
            lo[i] = (s - (hi[i] - bv)) + (u - bv);
            i += 1;
        }
        Ok((hi, lo))
    }

    /// Rate vector in the package frame, °/s: `hi` of [`GyroCal::apply_split`], its sum rounded
    /// once (half an f32 ulp). `Err` outside the calibrated range.
    #[inline]
    pub fn apply(&self, raw: [i16; 3], temp_raw: i8) -> Result<[f32; 3], OutOfRange> {
        Ok(self.apply_split(raw, temp_raw)?.0)
    }

    /// [`GyroCal::apply`] with the warm-up and the g-sensitivity removed (the thermal model is
    /// the temperature dependence): `t_s` seconds since power-up, `specific_force_g` what an
    /// accelerometer on the same package reads, g (+1 g up at rest; None: no g-sensitivity
    /// applied). Within half an f32 ulp plus `split_bound_dps` plus the terms' f32 rounding of
    /// `host`'s double-precision reference (`Export::apply_thermal_with`).
    pub fn apply_with(
        &self,
        raw: [i16; 3],
        temp_raw: i8,
        t_s: f32,
        specific_force_g: Option<[f32; 3]>,
    ) -> Result<[f32; 3], OutOfRange> {
        let (hi, lo) = self.apply_split(raw, temp_raw)?;
        let decay = exp_neg(t_s / self.warm_up_tau_s);
        let mut out = [0.0f32; 3];
        let mut i = 0;
        while i < 3 {
            let mut terms = self.warm_up_rate_dps[i] * decay;
            if let Some(f) = specific_force_g {
                let g = &self.g_rate_dps_per_g[i];
                terms += g[0] * f[0] + g[1] * f[1] + g[2] * f[2];
            }
            out[i] = hi[i] + (lo[i] - terms);
            i += 1;
        }
        Ok(out)
    }
}
"#;
