//! `report.html` reads like a calibration certificate in a 1400 px window: no table hides behind
//! a horizontal scrollbar. Checked on a real report, `host calibrate` on a simulated capture with
//! four effects and its truth beside it, so that the before/after table has all seven columns
//! and Δχ² cells in the millions. Two ways:
//! - always: each table's narrowest possible width (min-content: the longest unbreakable piece
//!   of every column, by the report's own CSS: what wraps, fonts, paddings, the column width),
//!   with character widths at or above DejaVu Sans / Liberation Sans (Debian's default fonts);
//! - where Chromium is installed (Debian: `apt-get install chromium`; `.ci/run` installs it):
//!   the page laid out by headless Chromium at 1400 px, every table's scroll width against its
//!   box. Without Chromium that test is listed as ignored, with the reason.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// Viewport width the report must fit, CSS px.
const VIEWPORT_PX: f64 = 1400.0;
/// Root font size (browsers' default; the report does not change it), px per rem.
const REM_PX: f64 = 16.0;

/// The report of a simulated capture with delay, index offset, drift and speed ripple (the
/// README's example, 6 s per run), written once per test binary under the target directory.
fn report() -> &'static Path {
    static REPORT: OnceLock<PathBuf> = OnceLock::new();
    REPORT.get_or_init(|| {
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("report-layout");
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let host = |args: &[&str]| {
            let o = host_command().args(args).output().expect("host runs");
            assert!(
                o.status.code().is_some_and(|c| c == 0 || c == 3),
                "{args:?}: {}",
                String::from_utf8_lossy(&o.stderr)
            );
        };
        let cap = dir.join("bar.cap");
        let cap = cap.to_str().unwrap();
        let mut args = vec!["simulate", "--out", cap, "--seed", "1", "--duration", "6", "--rates-dps", "180,90"];
        args.extend(["--effect", "delay_ms=5", "--effect", "index_offset_deg=3", "--effect", "offset_drift"]);
        args.extend(["--effect", "speed_ripple"]);
        host(&args);
        let out = dir.join("cal");
        let db = format!("sqlite:{}", dir.join("records.sqlite").display());
        // Twice under one serial, so the certificate lists the sensor's previous calibration.
        let first = dir.join("cal-first");
        host(&["calibrate", "--replay", cap, "--out-dir", first.to_str().unwrap(), "--db", &db, "--sensor", "SN-L"]);
        host(&[
            "calibrate",
            "--replay",
            cap,
            "--out-dir",
            out.to_str().unwrap(),
            "--db",
            &db,
            "--sensor",
            "SN-L",
            "--again",
        ]);
        out.join("report.html")
    })
}

/// The declarations of the CSS rule whose selector is exactly `selector` (first match).
fn rule<'a>(css: &'a str, selector: &str) -> &'a str {
    let at = css
        .lines()
        .find(|l| l.trim_start().starts_with(&format!("{selector} {{")))
        .unwrap_or_else(|| panic!("no CSS rule for {selector}"));
    at.split_once('{').unwrap().1.trim_end().trim_end_matches('}')
}

/// The value of `property` in a rule's declarations.
fn declared<'a>(decls: &'a str, property: &str) -> Option<&'a str> {
    decls.split(';').find_map(|d| d.split_once(':').filter(|(k, _)| k.trim() == property).map(|(_, v)| v.trim()))
}

/// A length in rem (`72rem`, `.85rem`) as px.
fn rem(v: &str) -> f64 {
    v.strip_suffix("rem").and_then(|n| n.parse::<f64>().ok()).unwrap_or_else(|| panic!("{v:?} is not in rem")) * REM_PX
}

/// Advance width of a character in em, at or above DejaVu Sans and Liberation Sans (regular; the
/// bold headers get 10 % more): digits 0.636 em in DejaVu, lower case up to 0.635 except m and w.
fn char_em(c: char) -> f64 {
    match c {
        '0'..='9' => 0.64,
        ' ' | '.' | ',' | ':' | ';' | '|' | '!' | '\'' | 'i' | 'j' | 'l' | 'f' | 't' | 'r' => 0.42,
        '(' | ')' | '[' | ']' | '/' | '-' => 0.42,
        'm' | 'w' | 'M' | 'W' => 1.0,
        'a'..='z' => 0.64,
        'A'..='Z' => 0.8,
        _ => 0.85,
    }
}

fn text_px(s: &str, font_px: f64) -> f64 {
    s.chars().map(char_em).sum::<f64>() * font_px
}

/// One cell: its text, whether it is a header, and its class and style attributes.
struct Cell {
    text: String,
    header: bool,
    class: String,
    style: String,
}

fn attr(tag: &str, name: &str) -> String {
    tag.split_once(&format!("{name}=\"")).and_then(|(_, v)| v.split_once('"')).map_or(String::new(), |(v, _)| v.into())
}

fn unescape(s: &str) -> String {
    let mut text = String::new();
    let mut in_tag = false;
    for c in s.chars() {
        match c {
            '<' => in_tag = true,
            '>' => in_tag = false,
            c if !in_tag => text.push(c),
            _ => {}
        }
    }
    html_escape::decode_html_entities(&text).into_owned()
}

/// Every table of the page as rows of cells (the report uses no colspan).
fn tables(html: &str) -> Vec<Vec<Vec<Cell>>> {
    html.split("<table")
        .skip(1)
        .map(|t| {
            let t = t.split("</table>").next().unwrap();
            t.split("<tr")
                .skip(1)
                .map(|row| {
                    let mut cells = Vec::new();
                    let mut rest = row;
                    while let Some(at) =
                        rest.find("<t").filter(|&i| matches!(rest.as_bytes().get(i + 2), Some(b'h' | b'd')))
                    {
                        let header = rest.as_bytes()[at + 2] == b'h';
                        let (tag, after) = rest[at..].split_once('>').unwrap();
                        let (content, after) = after.split_once(if header { "</th>" } else { "</td>" }).unwrap();
                        cells.push(Cell {
                            text: unescape(content),
                            header,
                            class: attr(tag, "class"),
                            style: attr(tag, "style"),
                        });
                        rest = after;
                    }
                    cells
                })
                .filter(|r: &Vec<Cell>| !r.is_empty())
                .collect()
        })
        .collect()
}

/// The report's narrowest table width, px, by its CSS: headers bold, cells wrapping at spaces
/// unless the CSS says `nowrap` for them, `overflow-wrap: anywhere` breaking anywhere.
fn min_content_px(table: &[Vec<Cell>], css: &str) -> f64 {
    let font = rem(declared(rule(css, "table"), "font-size").unwrap());
    let pad = declared(rule(css, "th, td"), "padding").unwrap();
    let pad_x = rem(pad.split_whitespace().nth(1).unwrap_or(pad)) * 2.0;
    let th_nowrap = declared(rule(css, "th"), "white-space") == Some("nowrap");
    let td_num_nowrap = declared(rule(css, "td.num"), "white-space") == Some("nowrap");
    let cols = table.iter().map(Vec::len).max().unwrap_or(0);
    (0..cols)
        .map(|c| {
            let widest = table
                .iter()
                .filter_map(|r| r.get(c))
                .map(|cell| {
                    let (font, nowrap) = if cell.header {
                        (font * 1.1, th_nowrap)
                    } else {
                        (font, td_num_nowrap && cell.class.split(' ').any(|k| k == "num"))
                    };
                    if cell.style.replace(' ', "").contains("overflow-wrap:anywhere") {
                        cell.text.chars().map(|ch| char_em(ch) * font).fold(0.0, f64::max)
                    } else if nowrap {
                        text_px(&cell.text, font)
                    } else {
                        cell.text.split(' ').map(|w| text_px(w, font)).fold(0.0, f64::max)
                    }
                })
                .fold(0.0, f64::max);
            widest + pad_x
        })
        .sum()
}

/// The width tables get: the `main` column at `VIEWPORT_PX`, less its side padding.
fn column_px(css: &str) -> f64 {
    let main = rule(css, "main");
    let max = rem(declared(main, "max-width").unwrap());
    let pad = declared(main, "padding").unwrap().split_whitespace().collect::<Vec<_>>();
    let side = rem(pad.get(1).copied().unwrap_or(pad[0]));
    max.min(VIEWPORT_PX) - 2.0 * side
}

fn style_of(html: &str) -> &str {
    html.split_once("<style>").and_then(|(_, s)| s.split_once("</style>")).map(|(s, _)| s).expect("inline CSS")
}

#[test]
fn every_table_fits_a_1400_px_window_by_its_min_content_width() {
    let html = std::fs::read_to_string(report()).unwrap();
    let css = style_of(&html);
    let column = column_px(css);
    let tables = tables(&html);
    let before_after = tables.iter().find(|t| t[0].iter().any(|c| c.text == "sensitivity error [ppm]"));
    let before_after = before_after.expect("the before/after table with its truth columns");
    assert_eq!(before_after[0].len(), 7);
    assert!(before_after.len() >= 3, "the linear model and at least two effects: {}", before_after.len());
    let history = tables.iter().find(|t| t[0].iter().any(|c| c.text == "Δk/σ"));
    assert_eq!(history.expect("the certificate's table of the previous calibration").len(), 4, "header and 3 axes");
    for (i, t) in tables.iter().enumerate() {
        let need = min_content_px(t, css);
        let first: Vec<&str> = t[0].iter().map(|c| c.text.as_str()).collect();
        eprintln!("table {i} {first:?}: min-content {need:.0} px of {column:.0} px");
        assert!(
            need <= column,
            "table {i} {first:?} needs {need:.0} px, the column at {VIEWPORT_PX} px gives {column:.0}"
        );
    }
    // The check has teeth: headers that do not wrap, as before, make the before/after table
    // overflow even the wider column.
    let old = css.replace("th { font-weight: 600;", "th { white-space: nowrap; font-weight: 600;");
    assert!(min_content_px(before_after, &old) > column_px(&old));
}

#[test]
#[cfg_attr(not(has_chromium), ignore = "no chromium: apt-get install chromium (.ci/run does)")]
fn every_table_fits_a_1400_px_window_in_chromium() {
    let html = std::fs::read_to_string(report()).unwrap();
    // The report has no scripts; this copy gets one that writes the window's width, the page's
    // and each table box's scroll and client widths into the DOM that --dump-dom prints.
    let probe = r#"<script>document.body.setAttribute("data-layout", [innerWidth, document.documentElement.scrollWidth + ":" + document.documentElement.clientWidth].concat([...document.querySelectorAll("table")].map(t => { const b = t.closest(".table-wrap") || t; return b.scrollWidth + ":" + b.clientWidth; })).join(" "));</script></body>"#;
    let dir = tempfile::tempdir().unwrap();
    let page = dir.path().join("probe.html");
    std::fs::write(&page, html.replace("</body>", probe)).unwrap();
    let profile = dir.path().join("profile");
    let o = Command::new("chromium")
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            &format!("--window-size={VIEWPORT_PX},1000"),
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg("--dump-dom")
        .arg(format!("file://{}", page.display()))
        .output()
        .expect("chromium runs");
    let dom = String::from_utf8_lossy(&o.stdout);
    let layout = dom
        .split_once("data-layout=\"")
        .and_then(|(_, v)| v.split_once('"'))
        .map(|(v, _)| v)
        .unwrap_or_else(|| panic!("no layout in chromium's DOM: {}", String::from_utf8_lossy(&o.stderr)));
    let (window, boxes) = layout.split_once(' ').unwrap();
    assert_eq!(window, format!("{VIEWPORT_PX}"), "the window was not {VIEWPORT_PX} px wide");
    let boxes: Vec<(u32, u32)> = boxes
        .split(' ')
        .map(|p| {
            let (s, c) = p.split_once(':').unwrap();
            (s.parse().unwrap(), c.parse().unwrap())
        })
        .collect();
    eprintln!("chromium: window, then page and tables as scroll:client widths, px: {layout}");
    assert!(boxes.len() >= 4, "the page and at least the certificate, before/after and per-axis tables: {layout}");
    for (i, (scroll, client)) in boxes.iter().enumerate() {
        assert!(scroll <= client, "box {i} scrolls sideways: {scroll} px of content in {client} px ({layout})");
    }
}

/// `host`, with the records database's default kept out of the user's data folder: a run
/// without `--db` records under the temporary directory, never in ~/.local/share.
fn host_command() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_host"));
    c.env_remove("GYROCAL_DB").env("XDG_DATA_HOME", std::env::temp_dir().join("gyrocal-tests-data"));
    c
}
