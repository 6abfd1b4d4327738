//! A report as one self-contained HTML file: inline CSS and inline SVG, no scripts, no external
//! assets, so it can be mailed, archived beside the calibration JSON and printed as is.

use super::plots::PlotError;
use std::fmt::Write as _;
use std::io;
use std::path::{Path, PathBuf};

/// Outcome shown by a verdict banner. The banner also spells it out, so it survives grey print
/// and colour-vision deficiencies.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// Passed.
    Ok,
    /// Usable, with a caveat.
    Warning,
    /// Failed.
    Error,
}

impl Verdict {
    fn class(self) -> &'static str {
        match self {
            Verdict::Ok => "ok",
            Verdict::Warning => "warning",
            Verdict::Error => "error",
        }
    }
    fn tag(self) -> &'static str {
        match self {
            Verdict::Ok => "OK",
            Verdict::Warning => "Warning",
            Verdict::Error => "Error",
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
enum Block {
    Heading(u8, String),
    Paragraph(String),
    Verdict(Verdict, String),
    Table { caption: String, headers: Vec<String>, rows: Vec<Vec<String>> },
    Figure { svg: String, caption: String },
    MissingFigure { caption: String, reason: String },
    Findings(Vec<String>),
    Preformatted(String),
}

/// An HTML report built block by block, in reading order.
#[derive(Debug, Clone, PartialEq)]
pub struct Document {
    title: String,
    blocks: Vec<Block>,
}

/// The files [`Document::write_with_svgs`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct WrittenReport {
    /// `<dir>/<stem>.html`.
    pub html: PathBuf,
    /// `<dir>/<stem>-fig<N>.svg`, N from 1 in figure order (as numbered in the HTML).
    pub svgs: Vec<PathBuf>,
}

impl Document {
    /// An empty document; `title` becomes the page title and the only `<h1>`.
    pub fn new(title: impl Into<String>) -> Self {
        Self { title: title.into(), blocks: Vec::new() }
    }

    /// A section heading. Levels are clamped to 2…6: level 1 belongs to the title.
    pub fn heading(&mut self, level: u8, text: impl Into<String>) -> &mut Self {
        self.blocks.push(Block::Heading(level.clamp(2, 6), text.into()));
        self
    }

    /// A paragraph of plain text.
    pub fn paragraph(&mut self, text: impl Into<String>) -> &mut Self {
        self.blocks.push(Block::Paragraph(text.into()));
        self
    }

    /// A coloured banner stating an outcome, e.g. whether the calibration is usable.
    pub fn verdict(&mut self, kind: Verdict, text: impl Into<String>) -> &mut Self {
        self.blocks.push(Block::Verdict(kind, text.into()));
        self
    }

    /// A table with zebra rows. Columns whose cells all start with a number (sign, ± allowed;
    /// blank, "—" and "n/a" cells ignored) are right-aligned in tabular figures so that
    /// digits line up. Short rows are padded with empty cells.
    pub fn table<S: AsRef<str>>(
        &mut self,
        caption: impl Into<String>,
        headers: &[S],
        rows: Vec<Vec<String>>,
    ) -> &mut Self {
        let headers = headers.iter().map(|h| h.as_ref().to_string()).collect();
        self.blocks.push(Block::Table { caption: caption.into(), headers, rows });
        self
    }

    /// A figure: `svg` is SVG markup (e.g. from [`super::plots`]) and is embedded verbatim,
    /// so it must come from a trusted source; the caption is escaped text.
    pub fn figure(&mut self, svg: impl Into<String>, caption: impl Into<String>) -> &mut Self {
        let svg = svg.into();
        let svg = match svg.trim_start().strip_prefix("<?xml") {
            Some(rest) => rest.split_once("?>").map_or("", |(_, s)| s).trim_start().to_string(),
            None => svg.trim_start().to_string(),
        };
        self.blocks.push(Block::Figure { svg, caption: caption.into() });
        self
    }

    /// A figure if the plot could be drawn, otherwise a note saying why, so that one
    /// degenerate run does not cost the whole report.
    pub fn figure_result(&mut self, svg: Result<String, PlotError>, caption: impl Into<String>) -> &mut Self {
        match svg {
            Ok(svg) => self.figure(svg, caption),
            Err(e) => {
                self.blocks.push(Block::MissingFigure { caption: caption.into(), reason: e.to_string() });
                self
            }
        }
    }

    /// A bulleted list of findings, one sentence each.
    pub fn findings(&mut self, items: impl IntoIterator<Item = impl Into<String>>) -> &mut Self {
        self.blocks.push(Block::Findings(items.into_iter().map(Into::into).collect()));
        self
    }

    /// Monospaced text kept as is, e.g. [`crate::calib::CalReport::summary`].
    pub fn preformatted(&mut self, text: impl Into<String>) -> &mut Self {
        self.blocks.push(Block::Preformatted(text.into()));
        self
    }

    /// The SVG of each figure, in figure order.
    pub fn figures(&self) -> impl Iterator<Item = &str> {
        self.blocks.iter().filter_map(|b| match b {
            Block::Figure { svg, .. } => Some(svg.as_str()),
            _ => None,
        })
    }

    /// The whole page.
    pub fn render(&self) -> String {
        let mut o = String::with_capacity(16 * 1024 + self.figures().map(str::len).sum::<usize>());
        let t = escape(&self.title);
        let _ = write!(
            o,
            "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
             <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
             <title>{t}</title>\n<style>\n{CSS}</style>\n</head>\n<body>\n<main>\n<h1>{t}</h1>\n"
        );
        let mut fig = 0;
        for b in &self.blocks {
            match b {
                Block::Heading(l, s) => {
                    let _ = writeln!(o, "<h{l}>{}</h{l}>", escape(s));
                }
                Block::Paragraph(s) => {
                    let _ = writeln!(o, "<p>{}</p>", escape(s));
                }
                Block::Verdict(v, s) => {
                    let _ = writeln!(
                        o,
                        "<div class=\"verdict {}\" role=\"status\"><span class=\"tag\">{}</span>{}</div>",
                        v.class(),
                        v.tag(),
                        escape(s)
                    );
                }
                Block::Table { caption, headers, rows } => table(&mut o, caption, headers, rows),
                Block::Figure { svg, caption } => {
                    fig += 1;
                    let _ = writeln!(
                        o,
                        "<figure id=\"fig{fig}\">\n{svg}\n<figcaption><span class=\"num\">Figure {fig}.</span> {}</figcaption>\n</figure>",
                        escape(caption)
                    );
                }
                Block::MissingFigure { caption, reason } => {
                    let _ = writeln!(
                        o,
                        "<div class=\"missing\"><strong>Figure not drawn:</strong> {} <span class=\"why\">({})</span></div>",
                        escape(caption),
                        escape(reason)
                    );
                }
                Block::Findings(items) => {
                    o.push_str("<ul class=\"findings\">\n");
                    for s in items {
                        let _ = writeln!(o, "<li>{}</li>", escape(s));
                    }
                    o.push_str("</ul>\n");
                }
                Block::Preformatted(s) => {
                    let _ = writeln!(o, "<pre>{}</pre>", escape(s));
                }
            }
        }
        o.push_str("</main>\n</body>\n</html>\n");
        o
    }

    /// Writes `<dir>/<stem>.html` and every figure as `<dir>/<stem>-fig<N>.svg` beside it (for
    /// slides and papers), creating `dir` if needed. `stem` must be a plain file name.
    pub fn write_with_svgs(&self, dir: impl AsRef<Path>, stem: &str) -> io::Result<WrittenReport> {
        let plain = !stem.is_empty() && Path::new(stem).file_name().is_some_and(|f| f == stem);
        if !plain {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("report stem {stem:?} is not a plain file name"),
            ));
        }
        let dir = dir.as_ref();
        std::fs::create_dir_all(dir)?;
        let html = dir.join(format!("{stem}.html"));
        std::fs::write(&html, self.render())?;
        let mut svgs = Vec::new();
        for (i, svg) in self.figures().enumerate() {
            let path = dir.join(format!("{stem}-fig{}.svg", i + 1));
            std::fs::write(&path, format!("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n{svg}\n"))?;
            svgs.push(path);
        }
        Ok(WrittenReport { html, svgs })
    }
}

/// Escapes text for HTML element content and quoted attributes: `&`, `<`, `>`, `"` and `'`
/// become `&amp;`, `&lt;`, `&gt;`, `&quot;` and `&#x27;` (`html-escape`'s quoted-attribute
/// encoder, safe in both places). The one escaping function of the host: the provenance block
/// uses it too.
pub fn escape(s: &str) -> String {
    html_escape::encode_quoted_attribute(s).into_owned()
}

fn is_blank(cell: &str) -> bool {
    matches!(cell.trim(), "" | "—" | "–" | "-" | "n/a" | "NaN")
}

/// Starts with a number, allowing a sign, ±, ≈ or < in front: "−0.12", "±3 %", "1.2 ± 0.1".
fn is_numeric(cell: &str) -> bool {
    let t = cell.trim().trim_start_matches(['+', '-', '\u{2212}', '±', '≈', '~', '<', '>', '≤', '≥']).trim_start();
    let t = t.strip_prefix('.').unwrap_or(t);
    t.starts_with(|c: char| c.is_ascii_digit())
}

fn table(o: &mut String, caption: &str, headers: &[String], rows: &[Vec<String>]) {
    let cols = rows.iter().map(Vec::len).chain([headers.len()]).max().unwrap_or(0);
    fn cell(r: &[String], c: usize) -> &str {
        r.get(c).map_or("", String::as_str)
    }
    let numeric: Vec<bool> = (0..cols)
        .map(|c| {
            let mut cells = rows.iter().map(|r| cell(r, c)).filter(|s| !is_blank(s)).peekable();
            cells.peek().is_some() && cells.all(is_numeric)
        })
        .collect();
    let class = |c: usize| if numeric[c] { " class=\"num\"" } else { "" };
    o.push_str("<div class=\"table-wrap\"><table>\n");
    if !caption.is_empty() {
        let _ = writeln!(o, "<caption>{}</caption>", escape(caption));
    }
    if !headers.is_empty() {
        o.push_str("<thead><tr>");
        for c in 0..cols {
            let _ =
                write!(o, "<th scope=\"col\"{}>{}</th>", class(c), escape(headers.get(c).map_or("", String::as_str)));
        }
        o.push_str("</tr></thead>\n");
    }
    o.push_str("<tbody>\n");
    for r in rows {
        o.push_str("<tr>");
        for c in 0..cols {
            let _ = write!(o, "<td{}>{}</td>", class(c), escape(cell(r, c)));
        }
        o.push_str("</tr>\n");
    }
    o.push_str("</tbody></table></div>\n");
}

/// Screen: a 72rem column (1152 px), wide enough for a seven-column table such as the loop's
/// before/after table at a 1400 px window, while paragraphs, findings and captions keep 46rem
/// lines; figures at their native width (shrunk to fit). Headers and text cells wrap at spaces,
/// numbers never (`host/tests/report_layout.rs` checks every table of a real report fits).
/// Print: full width, figures and tables kept whole, banner and zebra colours kept.
const CSS: &str = r#":root { --ink: #222; --muted: #555; --rule: #d5d9de; --zebra: #f2f4f7; }
* { box-sizing: border-box; }
html { background: #fff; }
body { margin: 0; color: var(--ink); font: 15px/1.5 system-ui, -apple-system, "Segoe UI", Roboto, "Helvetica Neue", Arial, sans-serif; }
main { max-width: 72rem; margin: 0 auto; padding: 2rem 1.5rem 4rem; }
h1 { font-size: 1.75rem; line-height: 1.2; margin: 0 0 1.2rem; }
h2 { font-size: 1.3rem; margin: 2.4rem 0 .7rem; padding-bottom: .25rem; border-bottom: 1px solid var(--rule); }
h3 { font-size: 1.1rem; margin: 1.8rem 0 .5rem; }
h4, h5, h6 { font-size: 1rem; margin: 1.3rem 0 .4rem; }
p { margin: .5rem 0 1rem; max-width: 46rem; }
.verdict { margin: 1rem 0 1.4rem; padding: .75rem 1rem; border-left: 6px solid; border-radius: 4px; font-size: 1.02rem; }
.verdict .tag { font-weight: 700; text-transform: uppercase; letter-spacing: .05em; margin-right: .75rem; }
.verdict.ok { background: #e2f3ec; border-color: #009E73; }
.verdict.warning { background: #fcf0d4; border-color: #E69F00; }
.verdict.error { background: #fbe1d3; border-color: #D55E00; }
.table-wrap { overflow-x: auto; margin: 1rem 0 1.6rem; }
table { border-collapse: collapse; font-size: .92rem; font-variant-numeric: tabular-nums; }
caption { caption-side: top; text-align: left; font-weight: 600; padding: 0 0 .45rem; }
th, td { padding: .35rem .85rem; text-align: left; vertical-align: top; border-bottom: 1px solid var(--rule); }
th { font-weight: 600; border-bottom: 2px solid var(--ink); }
th.num, td.num { text-align: right; }
td.num { white-space: nowrap; }
tbody tr:nth-child(even) { background: var(--zebra); }
figure { margin: 1.8rem 0; }
figure svg { display: block; max-width: 100%; height: auto; margin: 0 auto; }
figcaption { font-size: .9rem; color: var(--muted); margin: .5rem auto 0; max-width: 46rem; }
figcaption .num { font-weight: 600; color: var(--ink); }
.missing { margin: 1.2rem 0; padding: .7rem 1rem; border: 1px dashed var(--muted); color: var(--muted); }
ul.findings { padding-left: 1.3rem; max-width: 46rem; }
ul.findings li { margin: .35rem 0; }
pre { background: #f6f8fa; border: 1px solid var(--rule); border-radius: 4px; padding: .8rem 1rem; overflow-x: auto; font: .8rem/1.45 ui-monospace, SFMono-Regular, Menlo, Consolas, "DejaVu Sans Mono", monospace; }
@page { margin: 14mm; }
@media print {
  body { font-size: 10pt; }
  main { max-width: none; padding: 0; }
  h2, h3, h4 { break-after: avoid; }
  figure, .verdict, pre, tr { break-inside: avoid; }
  .verdict, tbody tr:nth-child(even) { print-color-adjust: exact; -webkit-print-color-adjust: exact; }
  .table-wrap { overflow: visible; }
  pre { white-space: pre-wrap; }
}
"#;
