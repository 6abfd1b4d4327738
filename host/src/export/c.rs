//! C99 header: the correction as `float` arrays and a `static inline` function, so a firmware
//! includes one file and calls `gyrocal_apply` on each raw reading.
//!
//! Single precision because the targets this is for (Cortex-M4F, such as the rig's STM32F407)
//! have a single-precision FPU only; `double` would be emulated in software. The coefficients
//! are split ([`super::SplitRow`]): `gyrocal_apply_split` gives the rate as a float pair
//! `hi + lo` within 2^(e−19) °/s of `host apply` over the whole int16 range (2.4e-7 °/s at
//! ±2000 °/s), and `gyrocal_apply` its float, which adds only its own rounding (half an ulp).
//! `gyrocal_apply_with` also removes the offset drift and the g-sensitivity (zero terms where
//! the calibration's model has none), and the header lists what it leaves out.
//!
//! A thermal calibration's header ([`render_thermal`]) takes the OUT_TEMP reading as an input,
//! `gyrocal_apply(raw, temp_raw, rate_dps)`: the same split rows, one per reading of the
//! calibrated range ([`super::ThermalTable`]), the range in the comment and in macros, and
//! `GYROCAL_ERR_OUT_OF_RANGE` with NaN rates outside it.

use super::{f32_literal, sanitise, Export, ThermalRow, ThermalTable};
use std::fmt::Write as _;

/// Renders the header.
pub fn render(e: &Export) -> String {
    let mut o = head(
        e,
        &[
            "rate_dps = GYROCAL_M_INV_DPS_PER_COUNT * raw - GYROCAL_OFFSET_RATE_DPS,".into(),
            "  i.e. (K S)^-1 (raw - GYROCAL_OFFSET_COUNTS), in the package frame.".into(),
        ],
    );
    let _ = writeln!(o, "\n/* (K S)^-1, deg/s per count; row i gives axis i of the rate. */");
    let _ = writeln!(o, "static const float GYROCAL_M_INV_DPS_PER_COUNT[3][3] = {{");
    for row in &e.m_inv_dps_per_count {
        let _ = writeln!(o, "    {{{}f, {}f, {}f}},", f32_literal(row[0]), f32_literal(row[1]), f32_literal(row[2]));
    }
    let _ = writeln!(o, "}};");
    let off = e.calibration.offset_counts;
    let _ = writeln!(o, "/* Offsets v_off, counts. */");
    let _ = writeln!(
        o,
        "static const float GYROCAL_OFFSET_COUNTS[3] = {{{}f, {}f, {}f}};",
        f32_literal(off[0]),
        f32_literal(off[1]),
        f32_literal(off[2])
    );
    let b = e.offset_rate_dps();
    let _ = writeln!(o, "/* (K S)^-1 v_off, deg/s: the offsets as a rate, subtracted after the product. */");
    let _ = writeln!(
        o,
        "static const float GYROCAL_OFFSET_RATE_DPS[3] = {{{}f, {}f, {}f}};",
        f32_literal(b[0]),
        f32_literal(b[1]),
        f32_literal(b[2])
    );
    let sp = e.split();
    let rows = |f: &dyn Fn(&super::SplitRow) -> [f64; 3]| -> String {
        sp.rows
            .iter()
            .map(|r| {
                let v = f(r);
                format!("    {{{}f, {}f, {}f}},\n", f32_literal(v[0]), f32_literal(v[1]), f32_literal(v[2]))
            })
            .collect()
    };
    let vector = |f: &dyn Fn(&super::SplitRow) -> f64| -> String {
        format!(
            "{{{}f, {}f, {}f}}",
            f32_literal(f(&sp.rows[0])),
            f32_literal(f(&sp.rows[1])),
            f32_literal(f(&sp.rows[2]))
        )
    };
    let bound = sp.rows.iter().map(super::SplitRow::bound_dps).fold(0.0, f64::max);
    let _ = write!(
        o,
        r#"
/* The same correction split in three per row (host/src/export/mod.rs, SplitRow): HI on a grid of
 * 2^(e-7) and MID on 2^(e-14), each with at most 7 significant bits, so that every product with a
 * raw count and every partial sum is exact in float; LO the remainder, the only part that rounds. */
static const float GYROCAL_M_INV_HI[3][3] = {{
{mh}}};
static const float GYROCAL_M_INV_MID[3][3] = {{
{mm}}};
static const float GYROCAL_M_INV_LO[3][3] = {{
{ml}}};
static const float GYROCAL_OFFSET_RATE_HI[3] = {bh};
static const float GYROCAL_OFFSET_RATE_MID[3] = {bm};
static const float GYROCAL_OFFSET_RATE_LO[3] = {bl};
/* Proven bound on |hi + lo - (K S)^-1 (raw - v_off)| of gyrocal_apply_split, deg/s, for every
 * int16 reading (2^(e-19), 2^e >= the largest coefficient of a row). */
#define GYROCAL_SPLIT_BOUND_DPS {bound:e}

{FLOAT_GUARD}
/* The rate vector in the package frame, deg/s, from one raw reading (counts), as the unevaluated
 * sum hi[i] + lo[i] of two floats (|lo| <= half an ulp of hi): this is what agrees with
 * `host apply` (double precision) to GYROCAL_SPLIT_BOUND_DPS over the whole int16 range, which
 * a single float cannot above 256 deg/s (half its ulp is 1.5e-5 deg/s there). Float operations
 * only: per axis 9 multiplications and 22 additions. */
static inline void gyrocal_apply_split(const int16_t raw[3], float hi[3], float lo[3])
{{
    const float x = (float)raw[0], y = (float)raw[1], z = (float)raw[2];
    int i;
    for (i = 0; i < 3; i++) {{
        const float *h = GYROCAL_M_INV_HI[i], *m = GYROCAL_M_INV_MID[i], *l = GYROCAL_M_INV_LO[i];
        /* Exact (multiples of the row's grid below 2^24 steps), in any order, with or without FMA. */
        const float a = h[0] * x + h[1] * y + h[2] * z - GYROCAL_OFFSET_RATE_HI[i];
        const float b = m[0] * x + m[1] * y + m[2] * z - GYROCAL_OFFSET_RATE_MID[i];
        /* The one sum that rounds: its terms are below 2^e. */
        const float c = l[0] * x + l[1] * y + l[2] * z - GYROCAL_OFFSET_RATE_LO[i];
        /* TwoSum (Knuth): s + t == a + b exactly; then once more to normalise hi + lo. */
        float s = a + b, bv = s - a;
        const float t = (a - (s - bv)) + (b - bv);
        const float u = t + c;
        hi[i] = s + u;
        bv = hi[i] - s;
        lo[i] = (s - (hi[i] - bv)) + (u - bv);
    }}
}}

/* The rate vector as floats, deg/s: hi of gyrocal_apply_split, i.e. its sum rounded once. Within
 * half a float ulp of the rate plus GYROCAL_SPLIT_BOUND_DPS of `host apply`: half an ulp is
 * 7.6e-6 deg/s below 256 deg/s, 6.1e-5 below 2048 deg/s, 1.2e-4 above. */
static inline void gyrocal_apply(const int16_t raw[3], float rate_dps[3])
{{
    float lo[3];
    gyrocal_apply_split(raw, rate_dps, lo);
}}

{with}
#endif /* GYROCAL_H */
"#,
        mh = rows(&|r| r.m_hi),
        mm = rows(&|r| r.m_mid),
        ml = rows(&|r| r.m_lo),
        bh = vector(&|r| r.b_hi),
        bm = vector(&|r| r.b_mid),
        bl = vector(&|r| r.b_lo),
        with = with_terms(e),
    );
    o
}

/// The header's comment (identity, model, `formula` lines, provenance, what it leaves out), its
/// include guard and its identity and gyro-setting macros.
fn head(e: &Export, formula: &[String]) -> String {
    let mut o = super::header_comment(e, "c", formula, ("/* ", " * "));
    let (serial, date) = (sanitise(e.serial()), sanitise(e.date()));
    let _ = writeln!(o, " * Valid only for raw readings taken at the gyro configuration below. */");
    let _ = writeln!(o, "#ifndef GYROCAL_H\n#define GYROCAL_H\n\n#include <stdint.h>\n");
    let _ = writeln!(o, "#define GYROCAL_SENSOR_SERIAL \"{serial}\"");
    let _ = writeln!(o, "#define GYROCAL_DATE_UTC \"{date}\"");
    let _ = writeln!(o, "#define GYROCAL_FULL_SCALE_DPS {}", e.calibration.full_scale.range_dps());
    if let Some(g) = e.gyro {
        let _ = writeln!(o, "#define GYROCAL_ODR_HZ {}", g.odr.hz());
        let _ = writeln!(
            o,
            "/* CTRL_REG1 BW[1:0]; low-pass cut-off {:.1} Hz */",
            f64::from(g.bandwidth.cutoff_dhz(g.odr)) / 10.0
        );
        let _ = writeln!(o, "#define GYROCAL_BANDWIDTH_BITS {}", g.bandwidth.bw_bits());
    }
    o
}

/// What the error-free sums need of the compiler, checked when the header is compiled.
const FLOAT_GUARD: &str = r#"/* The error-free sum below needs float arithmetic evaluated in float, in program order. */
#include <float.h>
#if !defined(FLT_EVAL_METHOD) || FLT_EVAL_METHOD != 0
#error "gyrocal.h needs FLT_EVAL_METHOD == 0 (float evaluated in float, e.g. Cortex-M4F, x86-64 SSE)"
#endif
#ifdef __FAST_MATH__
#error "gyrocal.h: -ffast-math reassociates the error-free sum; compile this file without it"
#endif
"#;

/// The drift and g-sensitivity terms and `gyrocal_apply_with`.
fn with_terms(e: &Export) -> String {
    let t = e.rate_terms();
    let v = |x: [f64; 3]| format!("{{{}f, {}f, {}f}}", f32_literal(x[0]), f32_literal(x[1]), f32_literal(x[2]));
    let g = t.g_dps_per_g;
    format!(
        r#"
/* Offset drift and g-sensitivity in the rate, deg/s, package frame (zero where the model has
 * none; see "Left out" above). Warm-up: (K S)^-1 c at power-up, decaying as exp(-t/T). */
static const float GYROCAL_WARMUP_RATE_DPS[3] = {wu};
#define GYROCAL_WARMUP_TAU_S {tau}f
/* Die temperature: (K S)^-1 beta, deg/s per deg C, from the OUT_TEMP reading below (OUT_TEMP
 * falls 1 LSB per deg C, L3G4200D datasheet Table 5). */
static const float GYROCAL_TEMP_RATE_DPS_PER_C[3] = {tc};
#define GYROCAL_TEMP_REFERENCE_LSB {tref}f
/* g-sensitivity: (K S)^-1 diag(k) G, deg/s per g of specific force along package x, y, z. */
static const float GYROCAL_G_RATE_DPS_PER_G[3][3] = {{
    {g0},
    {g1},
    {g2},
}};

#include <math.h>

/* gyrocal_apply with the drift and the g-sensitivity removed. t_s: seconds since power-up (the
 * calibration takes its session's first sample as power-up). out_temp_lsb: the die temperature
 * as OUT_TEMP (the calibration averaged it over 20 s). specific_force_g: what an accelerometer
 * on the same package reads, g (+1 g up at rest), or NULL without one (no g-sensitivity applied).
 * Within half a float ulp of the rate plus GYROCAL_SPLIT_BOUND_DPS plus the float rounding of the
 * terms (about 1e-7 of their size) of the double-precision reference (host/src/export/mod.rs,
 * Export::apply_with). Needs expf (link with -lm where the C library asks for it). */
static inline void gyrocal_apply_with(const int16_t raw[3], float t_s, float out_temp_lsb,
                                      const float *specific_force_g, float rate_dps[3])
{{
    float hi[3], lo[3];
    const float decay = expf(-t_s / GYROCAL_WARMUP_TAU_S);
    const float dtemp_c = -(out_temp_lsb - GYROCAL_TEMP_REFERENCE_LSB);
    int i;
    gyrocal_apply_split(raw, hi, lo);
    for (i = 0; i < 3; i++) {{
        float terms = GYROCAL_WARMUP_RATE_DPS[i] * decay + GYROCAL_TEMP_RATE_DPS_PER_C[i] * dtemp_c;
        if (specific_force_g) {{
            const float *g = GYROCAL_G_RATE_DPS_PER_G[i];
            terms += g[0] * specific_force_g[0] + g[1] * specific_force_g[1] + g[2] * specific_force_g[2];
        }}
        rate_dps[i] = hi[i] + (lo[i] - terms);
    }}
}}
"#,
        wu = v(t.warm_up_dps),
        tau = f32_literal(t.warm_up_tau_s),
        tc = v(t.temperature_dps_per_c),
        tref = f32_literal(t.reference_out_temp_lsb),
        g0 = v(g[0]),
        g1 = v(g[1]),
        g2 = v(g[2]),
    )
}

/// Renders the header of a thermal calibration: the correction at each OUT_TEMP reading of the
/// calibrated range ([`ThermalTable`]), `gyrocal_apply(raw, temp_raw, rate_dps)` and its split
/// and drift forms, each returning `GYROCAL_ERR_OUT_OF_RANGE` (and NaN rates) outside the range.
pub fn render_thermal(e: &Export, t: &ThermalTable) -> String {
    let [min_lsb, max_lsb] = t.out_temp_range_lsb();
    let mut o = head(e, &super::temperature::header_lines(t));
    let rows: String = t.rows.iter().map(c_row).collect();
    let terms = e.rate_terms();
    let v = |x: [f64; 3]| format!("{{{}f, {}f, {}f}}", f32_literal(x[0]), f32_literal(x[1]), f32_literal(x[2]));
    let g = terms.g_dps_per_g;
    let _ = write!(
        o,
        r#"
#include <math.h>

#define GYROCAL_OK 0
/* The OUT_TEMP reading is outside the calibrated range: the rates are NaN. */
#define GYROCAL_ERR_OUT_OF_RANGE 1
/* OUT_TEMP readings the calibration holds for, LSB (die temperature = GYROCAL_OUT_TEMP_AT_0C - reading). */
#define GYROCAL_OUT_TEMP_MIN_LSB ({min_lsb})
#define GYROCAL_OUT_TEMP_MAX_LSB ({max_lsb})
#define GYROCAL_OUT_TEMP_AT_0C {c0}f
#define GYROCAL_TEMP_MIN_C {cold}f
#define GYROCAL_TEMP_MAX_C {warm}f

/* The correction at one OUT_TEMP reading, each row of (K S)^-1 and of (K S)^-1 v_off split in
 * three (host/src/export/mod.rs, SplitRow): HI on a grid of 2^(e-7) and MID on 2^(e-14), each
 * with at most 7 significant bits, so that every product with a raw count and every partial sum
 * is exact in float; LO the remainder, the only part that rounds. */
typedef struct {{
    float m_inv_hi[3][3], m_inv_mid[3][3], m_inv_lo[3][3];
    float offset_rate_hi[3], offset_rate_mid[3], offset_rate_lo[3];
}} gyrocal_row;

/* The thermal model's calibration at each OUT_TEMP reading, GYROCAL_OUT_TEMP_MIN_LSB first. */
static const gyrocal_row GYROCAL_ROWS[GYROCAL_OUT_TEMP_MAX_LSB - GYROCAL_OUT_TEMP_MIN_LSB + 1] = {{
{rows}}};
/* Proven bound on |hi + lo - (K S)^-1 (raw - v_off)| of gyrocal_apply_split at every reading of
 * the range, deg/s, for every int16 reading (2^(e-19), 2^e >= the largest coefficient of a row). */
#define GYROCAL_SPLIT_BOUND_DPS {bound:e}

/* Warm-up and g-sensitivity in the rate, deg/s, package frame, of the base calibration (zero
 * where its model has none; see "Left out" above). Warm-up: (K S)^-1 c at power-up, decaying as
 * exp(-t/T). g-sensitivity: (K S)^-1 diag(k) G, deg/s per g along package x, y, z. */
static const float GYROCAL_WARMUP_RATE_DPS[3] = {wu};
#define GYROCAL_WARMUP_TAU_S {tau}f
static const float GYROCAL_G_RATE_DPS_PER_G[3][3] = {{
    {g0},
    {g1},
    {g2},
}};

{FLOAT_GUARD}
{THERMAL_C_FUNCTIONS}"#,
        c0 = f32_literal(t.model.out_temp_at_0c),
        cold = f32_literal(t.temp_range_c()[0]),
        warm = f32_literal(t.temp_range_c()[1]),
        bound = t.bound_dps(),
        wu = v(terms.warm_up_dps),
        tau = f32_literal(terms.warm_up_tau_s),
        g0 = v(g[0]),
        g1 = v(g[1]),
        g2 = v(g[2]),
    );
    o
}

/// The thermal header's functions (everything but the numbers, which precede them).
const THERMAL_C_FUNCTIONS: &str = r#"/* The rate vector in the package frame, deg/s, from one raw reading (counts) at the OUT_TEMP
 * reading temp_raw, as the unevaluated sum hi[i] + lo[i] of two floats (|lo| <= half an ulp of
 * hi): within GYROCAL_SPLIT_BOUND_DPS of `host apply --temp-c` at that reading's die temperature
 * over the whole int16 range. Returns GYROCAL_OK, or GYROCAL_ERR_OUT_OF_RANGE with NaN in hi and
 * lo when temp_raw is outside GYROCAL_OUT_TEMP_MIN_LSB..GYROCAL_OUT_TEMP_MAX_LSB. */
static inline int gyrocal_apply_split(const int16_t raw[3], int8_t temp_raw, float hi[3], float lo[3])
{
    const float x = (float)raw[0], y = (float)raw[1], z = (float)raw[2];
    const int reading = temp_raw;
    const gyrocal_row *r;
    int i;
    if (reading < GYROCAL_OUT_TEMP_MIN_LSB || reading > GYROCAL_OUT_TEMP_MAX_LSB) {
        for (i = 0; i < 3; i++) hi[i] = lo[i] = NAN;
        return GYROCAL_ERR_OUT_OF_RANGE;
    }
    r = &GYROCAL_ROWS[reading - GYROCAL_OUT_TEMP_MIN_LSB];
    for (i = 0; i < 3; i++) {
        const float *h = r->m_inv_hi[i], *m = r->m_inv_mid[i], *l = r->m_inv_lo[i];
        /* Exact (multiples of the row's grid below 2^24 steps), in any order, with or without FMA. */
        const float a = h[0] * x + h[1] * y + h[2] * z - r->offset_rate_hi[i];
        const float b = m[0] * x + m[1] * y + m[2] * z - r->offset_rate_mid[i];
        /* The one sum that rounds: its terms are below 2^e. */
        const float c = l[0] * x + l[1] * y + l[2] * z - r->offset_rate_lo[i];
        /* TwoSum (Knuth): s + t == a + b exactly; then once more to normalise hi + lo. */
        float s = a + b, bv = s - a;
        const float t = (a - (s - bv)) + (b - bv);
        const float u = t + c;
        hi[i] = s + u;
        bv = hi[i] - s;
        lo[i] = (s - (hi[i] - bv)) + (u - bv);
    }
    return GYROCAL_OK;
}

/* The rate vector as floats, deg/s: hi of gyrocal_apply_split, its sum rounded once (half a float
 * ulp: 7.6e-6 deg/s below 256 deg/s, 6.1e-5 below 2048 deg/s). Returns as gyrocal_apply_split. */
static inline int gyrocal_apply(const int16_t raw[3], int8_t temp_raw, float rate_dps[3])
{
    float lo[3];
    return gyrocal_apply_split(raw, temp_raw, rate_dps, lo);
}

/* gyrocal_apply with the warm-up and the g-sensitivity removed (the thermal model is the
 * temperature dependence). t_s: seconds since power-up. specific_force_g: what an accelerometer
 * on the same package reads, g (+1 g up at rest), or NULL without one. Within half a float ulp
 * plus GYROCAL_SPLIT_BOUND_DPS plus the terms' float rounding of host/src/export/mod.rs,
 * Export::apply_thermal_with. Returns as gyrocal_apply_split (NaN rates outside the range). */
static inline int gyrocal_apply_with(const int16_t raw[3], int8_t temp_raw, float t_s,
                                     const float *specific_force_g, float rate_dps[3])
{
    float hi[3], lo[3];
    const float decay = expf(-t_s / GYROCAL_WARMUP_TAU_S);
    const int status = gyrocal_apply_split(raw, temp_raw, hi, lo);
    int i;
    for (i = 0; i < 3; i++) {
        float terms = GYROCAL_WARMUP_RATE_DPS[i] * decay;
        if (specific_force_g) {
            const float *g = GYROCAL_G_RATE_DPS_PER_G[i];
            terms += g[0] * specific_force_g[0] + g[1] * specific_force_g[1] + g[2] * specific_force_g[2];
        }
        rate_dps[i] = hi[i] + (lo[i] - terms);
    }
    return status;
}

#endif /* GYROCAL_H */
"#;

/// One row of the C table, with its reading and die temperature as a comment.
fn c_row(r: &ThermalRow) -> String {
    let v = |x: [f64; 3]| format!("{{{}f, {}f, {}f}}", f32_literal(x[0]), f32_literal(x[1]), f32_literal(x[2]));
    let m = |f: &dyn Fn(&super::SplitRow) -> [f64; 3]| {
        format!("{{{}, {}, {}}}", v(f(&r.split.rows[0])), v(f(&r.split.rows[1])), v(f(&r.split.rows[2])))
    };
    let b = |f: &dyn Fn(&super::SplitRow) -> f64| v(r.split.rows.map(|row| f(&row)));
    format!(
        "    /* OUT_TEMP {}: die {:.2} deg C */\n    {{{}, {}, {}, {}, {}, {}}},\n",
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
