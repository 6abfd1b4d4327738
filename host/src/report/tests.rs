//! Figures are checked by structure: well-formed XML, the texts a reader needs, and the number
//! of drawn elements in each series' colour (so a missing or duplicated series shows up).

use super::palette::{self, hex, AFTER, BEFORE};
use super::plots::*;
use super::{Document, Verdict};
use std::f64::consts::PI;
use std::path::PathBuf;

/// Checks tag balance and that text has no raw `<` or stray `&`: enough to catch broken
/// escaping or truncated output without an XML crate. `void` lists HTML's unclosed elements.
fn assert_well_formed(doc: &str, void: &[&str]) {
    let mut stack: Vec<String> = Vec::new();
    let mut rest = doc;
    while let Some(i) = rest.find(['<', '&']) {
        let (text, tail) = rest.split_at(i);
        let _ = text;
        if tail.starts_with('&') {
            let end =
                tail.find(';').unwrap_or_else(|| panic!("unterminated entity at {:?}", &tail[..20.min(tail.len())]));
            let name = &tail[1..end];
            assert!(
                !name.is_empty() && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '#'),
                "stray & before {:?}",
                &tail[..20.min(tail.len())]
            );
            rest = &tail[end + 1..];
            continue;
        }
        if let Some(t) = tail.strip_prefix("<!--") {
            rest = &t[t.find("-->").expect("unterminated comment") + 3..];
            continue;
        }
        let end = tail.find('>').expect("unterminated tag");
        let tag = &tail[1..end];
        rest = &tail[end + 1..];
        if tag.starts_with('?') || tag.starts_with('!') || tag.ends_with('/') {
            continue;
        }
        if let Some(name) = tag.strip_prefix('/') {
            let open = stack.pop().unwrap_or_else(|| panic!("</{name}> closes nothing"));
            assert_eq!(open, name.trim(), "mismatched close tag");
            continue;
        }
        let name = tag.split_whitespace().next().expect("empty tag").to_string();
        assert!(name.chars().all(|c| c.is_ascii_alphanumeric()), "bad tag <{tag}>");
        if !void.contains(&name.as_str()) {
            stack.push(name);
        }
    }
    assert!(stack.is_empty(), "unclosed: {stack:?}");
}

fn assert_svg(svg: &str) {
    assert!(svg.starts_with("<svg"), "{}", &svg[..40.min(svg.len())]);
    assert_well_formed(svg, &[]);
}

/// Elements `<tag …>` whose attribute `attr` is `value`.
fn count(svg: &str, tag: &str, attr: &str, value: &str) -> usize {
    let needle = format!("{attr}=\"{value}\"");
    svg.split(&format!("<{tag} ")).skip(1).filter(|s| s[..s.find('>').unwrap_or(s.len())].contains(&needle)).count()
}

fn col(i: usize) -> String {
    hex(palette::series(i))
}

/// Text elements' contents (the SVG backend ends each with a newline).
fn texts(svg: &str) -> Vec<String> {
    svg.split("<text ")
        .skip(1)
        .map(|s| s[s.find('>').unwrap() + 1..s.find("</text>").unwrap()].trim().to_string())
        .collect()
}

fn has_text(svg: &str, t: &str) -> bool {
    texts(svg).iter().any(|s| s == t)
}

/// Attribute values of the elements `<tag …>` carrying `attr_filter`.
fn attr_values(svg: &str, tag: &str, filter: &str, attr: &str) -> Vec<String> {
    svg.split(&format!("<{tag} "))
        .skip(1)
        .map(|s| &s[..s.find('>').unwrap_or(s.len())])
        .filter(|s| s.contains(filter))
        .filter_map(|s| {
            let k = format!("{attr}=\"");
            let i = s.find(&k)? + k.len();
            Some(s[i..i + s[i..].find('"')?].to_string())
        })
        .collect()
}

/// The plotting-area frame drawn around the data: (x, y, width, height).
fn frame_rects(svg: &str) -> Vec<(f64, f64, f64, f64)> {
    svg.split("<rect ")
        .skip(1)
        .map(|s| format!(" {}", &s[..s.find('>').unwrap()]))
        .filter(|s| s.contains("stroke=\"#222222\""))
        .map(|s| {
            let get = |a: &str| {
                let k = format!(" {a}=\"");
                let i = s.find(&k).unwrap() + k.len();
                s[i..i + s[i..].find('"').unwrap()].parse::<f64>().unwrap()
            };
            (get("x"), get("y"), get("width"), get("height"))
        })
        .collect()
}

fn wave(n: usize, f: impl Fn(f64) -> f64) -> Vec<(f64, f64)> {
    (0..n).map(|i| i as f64 / (n - 1) as f64 * 10.0).map(|x| (x, f(x))).collect()
}

fn spec() -> PlotSpec {
    PlotSpec::new("Rate <check> & more", "time [s]", "rate [°/s]")
}

#[test]
fn line_plot_draws_each_series_once_with_legend() {
    let line = Series::line("commanded", wave(50, |x| x.sin()), 0);
    let dots = Series::points("measured", wave(12, |x| x.sin() + 0.1), 1);
    let pts = wave(30, |x| 0.5 * x.cos());
    let (lo, hi) = (pts.iter().map(|p| p.1 - 0.2).collect(), pts.iter().map(|p| p.1 + 0.2).collect());
    let band = Series::with_band("mean ±1 SE", pts, lo, hi, 2);
    let svg = line_plot(&spec(), &[line, dots, band]).unwrap();
    assert_svg(&svg);
    assert!(has_text(&svg, "Rate &lt;check&gt; &amp; more"), "title escaped once: {:?}", texts(&svg));
    for t in ["time [s]", "rate [°/s]", "commanded", "measured", "mean ±1 SE"] {
        assert!(has_text(&svg, t), "missing {t}: {:?}", texts(&svg));
    }
    // Data + legend swatch for each.
    assert_eq!(count(&svg, "polyline", "stroke", &col(0)), 2);
    assert_eq!(count(&svg, "circle", "fill", &col(1)), 12 + 1);
    assert_eq!(count(&svg, "polyline", "stroke", &col(2)), 2);
    assert_eq!(count(&svg, "polygon", "fill", &col(2)), 1);
    assert_eq!(count(&svg, "polyline", "stroke", &col(3)), 0);
}

#[test]
fn line_plot_breaks_at_nan_and_clips_to_an_explicit_range() {
    // Visible near x = 0, π, 2π, 3π; the NaN at x = 3.125 splits the run near π.
    let mut pts = wave(81, |x| 3.0 * x.sin());
    pts[25].1 = f64::NAN;
    let s = spec().with_y_range(-1.0, 1.0);
    let svg = line_plot(&s, &[Series::line("", pts, 0)]).unwrap();
    assert_svg(&svg);
    // Unlabelled: no legend swatch. The gap and the clipping split the sine into many runs.
    let runs = attr_values(&svg, "polyline", &format!("stroke=\"{}\"", col(0)), "points");
    assert_eq!(runs.len(), 5);
    let (fx, fy, fw, fh) = frame_rects(&svg)[0];
    for run in &runs {
        for p in run.split_whitespace() {
            let (x, y) = p.split_once(',').unwrap();
            let (x, y): (f64, f64) = (x.parse().unwrap(), y.parse().unwrap());
            assert!(
                x >= fx - 1.0 && x <= fx + fw + 1.0 && y >= fy - 1.0 && y <= fy + fh + 1.0,
                "({x},{y}) outside frame"
            );
        }
    }
}

#[test]
fn line_plot_handles_degenerate_data() {
    let empty = Series::line("e", vec![], 0);
    let nan = Series::line("n", vec![(f64::NAN, 1.0), (2.0, f64::NAN)], 0);
    assert_eq!(line_plot(&spec(), &[]), Err(PlotError::NoFiniteData));
    assert_eq!(line_plot(&spec(), &[empty.clone(), nan]), Err(PlotError::NoFiniteData));

    let single = line_plot(&spec(), &[empty, Series::points("one", vec![(3.0, 7.0)], 1)]).unwrap();
    assert_svg(&single);
    assert_eq!(count(&single, "circle", "fill", &col(1)), 2);
    assert!(texts(&single).iter().filter(|t| t.parse::<f64>().is_ok()).count() >= 4, "ticks on both axes");

    let constant = line_plot(&spec(), &[Series::line("c", wave(10, |_| 2.5), 0)]).unwrap();
    assert_svg(&constant);
    assert!(has_text(&constant, "2.5"), "{:?}", texts(&constant));

    let log = spec().with_log_y();
    let mixed =
        line_plot(&log, &[Series::points("p", vec![(0.0, -1.0), (1.0, 0.0), (2.0, 10.0), (3.0, 100.0)], 0)]).unwrap();
    assert_eq!(count(&mixed, "circle", "fill", &col(0)), 2 + 1, "non-positive values are not drawn on a log axis");
    assert_eq!(
        line_plot(&log, &[Series::points("p", vec![(0.0, -1.0)], 0)]),
        Err(PlotError::NoFiniteData),
        "nothing positive for a log axis"
    );
}

#[test]
fn line_plot_survives_extreme_values() {
    for pts in [
        vec![(0.0, -1e308), (1.0, 1e308)],
        vec![(0.0, 1e-300), (1.0, 3e-300)],
        vec![(1e15, 1e15), (1e15 + 1.0, 1e15 + 2.0)],
        vec![(f64::MIN_POSITIVE, f64::INFINITY), (1.0, 5.0), (2.0, f64::NEG_INFINITY)],
    ] {
        let svg = line_plot(&spec(), &[Series::line("l", pts.clone(), 0)]).unwrap_or_else(|e| panic!("{pts:?}: {e}"));
        assert_svg(&svg);
        assert!(!svg.contains("NaN") && !svg.contains("inf"), "{pts:?} leaked a non-finite coordinate");
    }
}

#[test]
fn line_plot_rejects_bad_input_clearly() {
    let s = [Series::line("a", wave(5, |x| x), 0)];
    let err = line_plot(&spec().with_x_range(2.0, 2.0), &s).unwrap_err();
    assert!(matches!(err, PlotError::InvalidRange { axis: "x", .. }), "{err}");
    let err = line_plot(&spec().with_y_range(0.0, 1.0).with_log_y(), &s).unwrap_err();
    assert!(err.to_string().contains("log axis"), "{err}");
    assert_eq!(line_plot(&spec().with_size(10, 10), &s), Err(PlotError::InvalidSize { width: 10, height: 10 }));
    let bad_band = Series::with_band("b", wave(5, |x| x), vec![0.0; 4], vec![0.0; 5], 0);
    let err = line_plot(&spec(), &[bad_band]).unwrap_err();
    assert_eq!(err, PlotError::LengthMismatch { series: "b".into(), what: "band lower", expected: 5, got: 4 });
}

#[test]
fn explicit_x_ticks_are_used() {
    let s = spec().with_x_range(0.0, 360.0).with_x_ticks((0..=8).map(|i| f64::from(i) * 45.0).collect());
    let svg = line_plot(&s, &[Series::line("a", vec![(0.0, 0.0), (360.0, 1.0)], 0)]).unwrap();
    for t in ["0", "45", "90", "135", "180", "225", "270", "315", "360"] {
        assert!(has_text(&svg, t), "tick {t}: {:?}", texts(&svg));
    }
}

/// Bins like those of one axis and run: before calibration a 3 % scale error, a 0.9° phase
/// error and an offset; after, noise at the floor.
pub(super) fn theta2_bins(after: bool, nbins: usize) -> Theta2Bins {
    let floor = 0.35;
    let n = 1300u64;
    let se = floor / (n as f64).sqrt();
    let theta: Vec<f64> = (0..nbins).map(|i| (i as f64 + 0.5) * 360.0 / nbins as f64).collect();
    let truth = |t: f64| 147.0 * (t.to_radians() + PI / 6.0).sin() + 103.9;
    let jitter = |i: usize| se * ((i as f64 * 12.9898).sin() * 43758.5453).fract() * 2.0;
    let measured: Vec<f64> = theta
        .iter()
        .enumerate()
        .map(|(i, &t)| {
            if after {
                truth(t) + jitter(i)
            } else {
                1.03 * (147.0 * (t.to_radians() + PI / 6.0 + 0.9f64.to_radians()).sin() + 103.9) + 2.0 + jitter(i)
            }
        })
        .collect();
    let model: Vec<f64> = theta.iter().map(|&t| truth(t)).collect();
    let residual: Vec<f64> = measured.iter().zip(&model).map(|(m, p)| m - p).collect();
    Theta2Bins {
        label: if after { "after" } else { "before" }.into(),
        colour: if after { AFTER } else { BEFORE },
        theta2_deg: theta,
        measured,
        model,
        residual,
        residual_se: vec![se; nbins],
        counts: vec![n; nbins],
        noise_floor: Some(floor),
    }
}

#[test]
fn theta2_panel_overlays_before_and_after_in_two_panels() {
    let spec = Theta2Spec::new("Axis x, run 1 (pose 1, +180 °/s)", "°/s");
    let svg = theta2_panel(&spec, &[theta2_bins(false, 36), theta2_bins(true, 36)]).unwrap();
    assert_svg(&svg);
    for t in [
        "Axis x, run 1 (pose 1, +180 °/s)",
        "θ2 [°]",
        "output [°/s]",
        "residual [°/s]",
        "before:",
        "after:",
        "measured (bin mean)",
        "residual ±1 SE",
        "±floor/√n",
        "45",
        "315",
    ] {
        assert!(has_text(&svg, t), "missing {t}: {:?}", texts(&svg));
    }
    assert_eq!(frame_rects(&svg).len(), 2, "two stacked panels");
    for c in [BEFORE, AFTER] {
        assert_eq!(count(&svg, "circle", "fill", &col(c)), 36 + 1, "bin means + legend");
        // Model and residual lines, plus the model and band legend swatches.
        let solid = svg
            .split("<polyline ")
            .filter(|s| s.contains(&format!("stroke=\"{}\"", col(c))) && s.contains("stroke-width=\"2\""))
            .count();
        assert_eq!(solid, 4, "colour {c}");
        assert_eq!(count(&svg, "polygon", "fill", &col(c)), 1, "one SE band");
    }
    // The two panels share the x axis pixel span.
    let f = frame_rects(&svg);
    assert_eq!((f[0].0, f[0].2), (f[1].0, f[1].2));
}

#[test]
fn theta2_panel_handles_degenerate_bins() {
    let spec = Theta2Spec::new("t", "counts");
    assert_eq!(theta2_panel(&spec, &[]), Err(PlotError::NoFiniteData));
    let mut empty = theta2_bins(true, 8);
    for v in empty.measured.iter_mut().chain(&mut empty.model).chain(&mut empty.residual) {
        *v = f64::NAN;
    }
    empty.noise_floor = None;
    assert_eq!(theta2_panel(&spec, &[empty]), Err(PlotError::NoFiniteData));

    let single = theta2_panel(&spec, &[theta2_bins(true, 1)]).unwrap();
    assert_svg(&single);
    assert_eq!(count(&single, "circle", "fill", &col(AFTER)), 2);

    let mut gap = theta2_bins(false, 12);
    gap.measured[5] = f64::NAN;
    gap.residual[5] = f64::NAN;
    gap.counts[5] = 0;
    let svg = theta2_panel(&spec, &[gap]).unwrap();
    assert_svg(&svg);
    assert_eq!(count(&svg, "circle", "fill", &col(BEFORE)), 11 + 1, "the empty bin has no dot");
    assert_eq!(count(&svg, "polygon", "fill", &col(BEFORE)), 2, "the band breaks at the empty bin");

    let mut short = theta2_bins(true, 6);
    short.counts.pop();
    assert_eq!(
        theta2_panel(&spec, &[short]),
        Err(PlotError::LengthMismatch { series: "after".into(), what: "counts", expected: 6, got: 5 })
    );
}

/// A residual spectrum: white floor (`base`), lines at the first three table-rate harmonics.
fn spectrum(label: &str, colour: usize, base: f64, peak: f64) -> Spectrum {
    let freqs: Vec<f64> = (0..=200).map(|i| f64::from(i) * 0.05).collect();
    let amp = freqs
        .iter()
        .map(|&f| {
            let line = |f0: f64, a: f64| a * (-((f - f0) / 0.03).powi(2)).exp();
            base * (1.0 + 0.3 * (f * 7.3 + peak).sin())
                + line(0.5, peak)
                + line(1.0, peak / 15.0)
                + line(1.5, peak / 40.0)
        })
        .collect();
    Spectrum { label: label.into(), freqs_hz: freqs, amp_dps: amp, colour }
}

fn markers() -> Vec<Marker> {
    ["1×", "2×", "3×"]
        .iter()
        .enumerate()
        .map(|(i, l)| Marker { freq_hz: 0.5 * (i + 1) as f64, label: (*l).into() })
        .collect()
}

#[test]
fn spectrum_plot_marks_harmonics_and_floor_on_a_log_axis() {
    let s = spectrum("", AFTER, 0.004, 4.0);
    let spec = PlotSpec::new("Residual spectrum, axis x", "frequency [Hz]", "amplitude [°/s]");
    let svg = spectrum_plot(&spec, &s.freqs_hz, &s.amp_dps, &markers(), Some(0.004)).unwrap();
    assert_svg(&svg);
    for t in
        ["Residual spectrum, axis x", "frequency [Hz]", "amplitude [°/s]", "1×", "2×", "3×", "noise floor", "0.01", "1"]
    {
        assert!(has_text(&svg, t), "missing {t}: {:?}", texts(&svg));
    }
    // The spectrum is one unbroken 1 px line; legend swatches are 2 px.
    let one = svg.split("<polyline ").filter(|p| p.contains(&format!("stroke=\"{}\"", col(AFTER)))).count();
    assert_eq!(one, 1);
    // DC bin (0.004 ≈ floor) and everything else drawn; the markers and floor are dashed in grey.
    assert!(count(&svg, "polyline", "stroke", &hex(palette::REFERENCE)) > 20);
}

#[test]
fn spectra_plot_overlays_and_keeps_close_marker_labels_apart() {
    let spec = PlotSpec::new("Residual spectrum", "frequency [Hz]", "amplitude [°/s]").with_size(500, 320);
    let mut mk = markers();
    mk.push(Marker { freq_hz: 0.52, label: "table".into() });
    mk.push(Marker { freq_hz: 99.0, label: "out of range".into() });
    let svg = spectra_plot(
        &spec,
        &[spectrum("before", BEFORE, 0.004, 4.0), spectrum("after", AFTER, 0.004, 0.01)],
        &mk,
        None,
    )
    .unwrap();
    assert_svg(&svg);
    assert!(has_text(&svg, "before") && has_text(&svg, "after"));
    assert!(!has_text(&svg, "noise floor"));
    assert!(!has_text(&svg, "out of range"), "markers outside the x range are not drawn");
    for c in [BEFORE, AFTER] {
        assert_eq!(count(&svg, "polyline", "stroke", &col(c)), 2, "line + legend swatch");
    }
    let y_of = |label: &str| {
        let i = svg.find(&format!("\n{label}\n</text>")).unwrap();
        let tag = &svg[svg[..i].rfind("<text ").unwrap()..i];
        let k = tag.find(" y=\"").unwrap() + 4;
        tag[k..k + tag[k..].find('"').unwrap()].parse::<i32>().unwrap()
    };
    assert_ne!(y_of("1×"), y_of("table"), "overlapping labels are staggered");
}

#[test]
fn spectrum_plot_rejects_what_cannot_be_drawn() {
    let spec = PlotSpec::new("s", "frequency [Hz]", "amplitude [°/s]");
    assert_eq!(spectrum_plot(&spec, &[0.0, 1.0], &[0.0, 0.0], &[], Some(1.0)), Err(PlotError::NoFiniteData));
    assert_eq!(spectrum_plot(&spec, &[], &[], &markers(), None), Err(PlotError::NoFiniteData));
    assert!(matches!(spectrum_plot(&spec, &[0.0, 1.0], &[1.0], &[], None), Err(PlotError::LengthMismatch { .. })));
    let single = spectrum_plot(&spec, &[0.5], &[2.0], &markers(), Some(0.1)).unwrap();
    assert_svg(&single);
    assert!(has_text(&single, "1×"), "a single bin still gets an axis around it");
}

fn axes() -> Vec<String> {
    ["x", "y", "z"].map(String::from).to_vec()
}

#[test]
fn bar_chart_groups_bars_and_labels_values() {
    let spec = PlotSpec::new("Residual RMS / noise floor", "axis", "RMS / floor").with_log_y();
    let series = [
        BarSeries { label: "before".into(), values: vec![12.6, 9.81, 15.1], colour: BEFORE },
        BarSeries { label: "after".into(), values: vec![1.02, 0.99, f64::NAN], colour: AFTER },
    ];
    let reference = RefLine { value: 1.0, label: "noise floor".into() };
    let svg = bar_chart(&spec, &axes(), &series, Some(&reference)).unwrap();
    assert_svg(&svg);
    for t in [
        "Residual RMS / noise floor",
        "axis",
        "RMS / floor",
        "x",
        "y",
        "z",
        "before",
        "after",
        "noise floor",
        "12.6",
        "0.99",
        "n/a",
    ] {
        assert!(has_text(&svg, t), "missing {t}: {:?}", texts(&svg));
    }
    assert_eq!(count(&svg, "rect", "fill", &col(BEFORE)), 3 + 1);
    assert_eq!(count(&svg, "rect", "fill", &col(AFTER)), 2 + 1, "NaN draws no bar");

    let linear = bar_chart(&spec.clone().with_size(400, 300), &axes(), &series[..1], None).unwrap();
    assert_svg(&linear);
    let negative = PlotSpec::new("Offset", "axis", "offset [counts]");
    let svg = bar_chart(
        &negative,
        &axes(),
        &[BarSeries { label: "o".into(), values: vec![-3.0, 0.0, 2.0], colour: 2 }],
        None,
    )
    .unwrap();
    assert_eq!(count(&svg, "rect", "fill", &col(2)), 3 + 1);
    assert!(has_text(&svg, "\u{2212}3"));
}

#[test]
fn bar_chart_rejects_what_cannot_be_drawn() {
    let spec = PlotSpec::new("b", "axis", "v");
    let nan = BarSeries { label: "n".into(), values: vec![f64::NAN; 3], colour: 0 };
    assert_eq!(bar_chart(&spec, &axes(), &[nan], None), Err(PlotError::NoFiniteData));
    assert_eq!(bar_chart(&spec, &[], &[], None), Err(PlotError::NoFiniteData));
    let short = BarSeries { label: "s".into(), values: vec![1.0], colour: 0 };
    assert_eq!(
        bar_chart(&spec, &axes(), &[short], None),
        Err(PlotError::LengthMismatch { series: "s".into(), what: "values", expected: 3, got: 1 })
    );
}

const HTML_VOID: &[&str] = &["meta", "br", "hr", "img", "link", "input"];

#[test]
fn html_escapes_all_text() {
    let evil = "<script>alert('x')</script> & \"q\"";
    let mut d = Document::new(evil);
    d.heading(2, evil)
        .paragraph(evil)
        .verdict(Verdict::Error, evil)
        .table(evil, &[evil], vec![vec![evil.to_string()]])
        .findings([evil])
        .preformatted(evil)
        .figure_result(Err(PlotError::NoFiniteData), evil);
    let html = d.render();
    assert_well_formed(&html, HTML_VOID);
    assert!(!html.contains("<script"), "raw script tag in output");
    assert!(!html.contains("& \""), "raw ampersand in output");
    // `'` as `&#x27;` (html-escape's form; the hand-written escaper wrote the decimal `&#39;`, the
    // same character reference).
    let escaped = "&lt;script&gt;alert(&#x27;x&#x27;)&lt;/script&gt; &amp; &quot;q&quot;";
    // Title (twice), heading, paragraph, verdict, caption, header, cell, finding, pre, note.
    assert_eq!(html.matches(escaped).count(), 11);
}

#[test]
fn html_embeds_figures_numbered_and_aligns_numbers() {
    let svg = line_plot(&spec(), &[Series::line("a", wave(5, |x| x), 0)]).unwrap();
    let mut d = Document::new("Report");
    d.heading(1, "Results")
        .verdict(Verdict::Ok, "fine")
        .figure(svg.clone(), "First.")
        .figure_result(Err(PlotError::NoFiniteData), "Skipped.")
        .figure(format!("<?xml version=\"1.0\"?>\n{svg}"), "Second.")
        .table(
            "Estimates",
            &["axis", "k [counts/(°/s)]", "tilt [°]", "note"],
            vec![
                vec!["x".into(), "57.12 ± 0.01".into(), "−0.12".into(), "ok".into()],
                vec!["y".into(), "n/a".into(), "+0.3".into(), "2 clipped".into()],
                vec!["z".into(), "56.9".into()],
            ],
        );
    let html = d.render();
    assert_well_formed(&html, HTML_VOID);
    assert_eq!(html.matches("<svg ").count(), 2);
    assert!(!html.contains("<?xml"), "prolog stripped for inline use");
    assert!(html.contains("Figure 1.</span> First.") && html.contains("Figure 2.</span> Second."));
    assert!(html.contains("Figure not drawn:</strong> Skipped."));
    assert!(html.contains("<h2>Results</h2>"), "level 1 is the title's");
    assert!(html.contains("class=\"verdict ok\"") && html.contains("<span class=\"tag\">OK</span>"));
    assert!(html.contains("<td>x</td><td class=\"num\">57.12 ± 0.01</td><td class=\"num\">−0.12</td><td>ok</td>"));
    assert!(html.contains("<td class=\"num\">n/a</td><td class=\"num\">+0.3</td><td>2 clipped</td>"));
    assert!(
        html.contains("<td>z</td><td class=\"num\">56.9</td><td class=\"num\"></td><td></td>"),
        "short rows padded"
    );
    for external in ["<script", "<link", "src=", "href=", "url("] {
        assert!(!html.contains(external), "self-contained: found {external}");
    }
}

/// A scratch directory, removed on drop.
struct Scratch(PathBuf);

impl Scratch {
    fn new(name: &str) -> Self {
        let p = std::env::temp_dir().join(format!("host-report-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&p);
        Self(p)
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

#[test]
fn write_with_svgs_writes_html_and_numbered_svgs() {
    let dir = Scratch::new("write");
    let svg = line_plot(&spec(), &[Series::line("a", wave(5, |x| x), 0)]).unwrap();
    let mut d = Document::new("R");
    d.figure(svg.clone(), "a").figure(svg, "b");
    let out = d.write_with_svgs(dir.0.join("nested"), "cal").unwrap();
    assert_eq!(out.html, dir.0.join("nested/cal.html"));
    assert_eq!(out.svgs, [dir.0.join("nested/cal-fig1.svg"), dir.0.join("nested/cal-fig2.svg")]);
    assert_eq!(std::fs::read_to_string(&out.html).unwrap(), d.render());
    for p in &out.svgs {
        let text = std::fs::read_to_string(p).unwrap();
        assert!(text.starts_with("<?xml") && text.contains("xmlns=\"http://www.w3.org/2000/svg\""));
        assert_well_formed(&text, &[]);
    }
    let err = d.write_with_svgs(&dir.0, "../escape").unwrap_err();
    assert_eq!(err.kind(), std::io::ErrorKind::InvalidInput);
}

/// A report of every kind of block and figure, on synthetic calibration numbers.
fn sample_report() -> Document {
    let mut d = Document::new("Gyro calibration — L3G4200D s/n 0042");
    d.verdict(Verdict::Ok, "Calibration usable: residuals at the noise floor on all three axes (RMS/floor 0.99–1.04).")
        .paragraph(
            "Two poses, four runs at ±180 °/s, 800 Hz, ±500 °/s full scale. 1 530 112 samples used, 8 211 excluded \
             (spin-up, stop and window edges); no clipped samples.",
        )
        .findings([
            "Sensitivities are 2.1–3.4 % above nominal; the largest tilt is 0.93 ± 0.01° (axis z towards x).",
            "Before calibration the residual is dominated by the 1× table rate line; after, no line stands above the floor.",
            "Gear ratio 1.00002 ± 0.00001, consistent with the 1:1 magnetic gears.",
        ]);
    d.heading(2, "Estimates").table(
        "Per-axis estimates (±1σ, inflated for residual autocorrelation)",
        &["axis", "k [counts/(°/s)]", "vs nominal", "offset [counts]", "tilt [°]"],
        vec![
            vec!["x".into(), "58.962 ± 0.004".into(), "+3.18 %".into(), "+12.4 ± 0.2".into(), "0.412 ± 0.008".into()],
            vec!["y".into(), "58.335 ± 0.004".into(), "+2.09 %".into(), "−31.9 ± 0.2".into(), "0.655 ± 0.008".into()],
            vec!["z".into(), "59.081 ± 0.005".into(), "+3.39 %".into(), "+4.1 ± 0.3".into(), "0.931 ± 0.010".into()],
        ],
    );
    let bars = bar_chart(
        &PlotSpec::new("Residual RMS relative to the noise floor", "axis", "RMS / noise floor").with_log_y(),
        &axes(),
        &[
            BarSeries { label: "before".into(), values: vec![12.6, 9.81, 15.1], colour: BEFORE },
            BarSeries { label: "after".into(), values: vec![1.02, 0.99, 1.04], colour: AFTER },
        ],
        Some(&RefLine { value: 1.0, label: "noise floor".into() }),
    );
    d.figure_result(bars, "Residual RMS over noise floor per axis; 1 means the model leaves nothing but noise.");
    d.heading(2, "Fit against θ2");
    let t2 = theta2_panel(
        &Theta2Spec::new("Axis x, run 1 (pose 1, +180 °/s)", "°/s"),
        &[theta2_bins(false, 36), theta2_bins(true, 36)],
    );
    d.figure_result(t2, "Bin means over θ2 with the model (top) and residual bin means ±1 SE (bottom).");
    let t2_after =
        theta2_panel(&Theta2Spec::new("Axis x, run 1: after calibration only", "°/s"), &[theta2_bins(true, 36)]);
    d.figure_result(t2_after, "The same residual after calibration on its own scale: within ±floor/√n.");
    d.heading(2, "Residual spectrum");
    let spectra = spectra_plot(
        &PlotSpec::new("Residual amplitude spectrum, axis x", "frequency [Hz]", "amplitude [°/s]"),
        &[spectrum("before", BEFORE, 0.009, 4.0), spectrum("after", AFTER, 0.004, 0.006)],
        &markers(),
        Some(0.004),
    );
    d.figure_result(spectra, "Residual spectra; dashed lines at multiples of the table rate and at the noise floor.");
    let rate: Vec<(f64, f64)> =
        (0..60).map(|i| (f64::from(i) * 2.0, 180.0 + 0.4 * (f64::from(i) * 0.37).sin())).collect();
    let (lo, hi) = (rate.iter().map(|p| p.1 - 0.15).collect(), rate.iter().map(|p| p.1 + 0.15).collect());
    let steady = line_plot(
        &PlotSpec::new("Base-table rate per revolution, run 1", "time [s]", "θ1' [°/s]").with_size(800, 340),
        &[
            Series::with_band("measured ±1σ", rate, lo, hi, AFTER),
            Series::dashed("commanded", vec![(0.0, 180.0), (118.0, 180.0)], 6),
        ],
    );
    d.figure_result(steady, "Table rate from the encoder, one value per revolution.");
    d.figure_result(
        line_plot(&PlotSpec::new("Empty run", "time [s]", "rate [°/s]"), &[]),
        "A run without usable samples shows as a note, not a blank figure.",
    );
    d.heading(2, "Summary as text")
        .preformatted("Axis  k [counts/(°/s)]\n  x   58.96200 ± 0.00400\n  y   58.33500 ± 0.00400");
    d
}

/// Renders the sample report to files; set REPORT_DEMO_DIR to keep them for a look in a
/// browser (e.g. /tmp/report-demo), otherwise they go to a scratch directory.
#[test]
fn demo_report_renders_to_files() {
    let d = sample_report();
    let scratch = Scratch::new("demo");
    let dir = std::env::var_os("REPORT_DEMO_DIR").map_or_else(|| scratch.0.clone(), PathBuf::from);
    let out = d.write_with_svgs(&dir, "report").unwrap();
    assert!(out.html.is_file());
    assert_eq!(out.svgs.len(), 5, "five figures drawn, one noted as missing");
    let html = std::fs::read_to_string(&out.html).unwrap();
    assert_well_formed(&html, HTML_VOID);
    assert_eq!(html.matches("<svg ").count(), 5);
    assert!(html.contains("Figure not drawn:"));
}
