//! The library's structure, read from its sources: its modules import one way (no import
//! circle among the modules of `host/src`, and the calibration, `calib/`, reaches neither into
//! the simulator nor into the presentation, `present/` and `report/`: it returns data that they
//! show), and no function of the calibration engine runs over 100 lines. Read from the sources: every
//! `crate::a::b` and `super::a` path outside comments and test modules is an arrow from the
//! module that writes it to the module it names.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

type Graph = BTreeMap<String, BTreeSet<String>>;

/// `host/src/a/b.rs` and `host/src/a/b/mod.rs` are module `a::b`.
fn module_name(src: &Path, file: &Path) -> Option<String> {
    let rel = file.strip_prefix(src).ok()?.with_extension("");
    let mut parts: Vec<String> = rel.iter().map(|p| p.to_string_lossy().into_owned()).collect();
    if parts.last().is_some_and(|p| p == "mod") {
        parts.pop();
    }
    let name = parts.join("::");
    (!matches!(name.as_str(), "lib" | "main" | "")).then_some(name)
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap().map(Result::unwrap) {
        let path = entry.path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The code of a file without its test module and its comments.
fn code(text: &str) -> String {
    let text = text.split("#[cfg(test)]").next().unwrap_or_default();
    text.lines().map(|l| l.split("//").next().unwrap_or_default()).collect::<Vec<_>>().join("\n")
}

/// The module a path names, from the module `from`: the longest prefix of the path that is a
/// module (`super` is the parent of `from`, whether its file is `x.rs` or `x/mod.rs`).
fn target(path: &[&str], from: &str, modules: &BTreeSet<String>) -> Option<String> {
    let (root, rest): (Vec<&str>, &[&str]) = match *path.first()? {
        "crate" => (Vec::new(), &path[1..]),
        "super" => {
            let mut parent: Vec<&str> = from.split("::").collect();
            parent.pop();
            (parent, &path[1..])
        }
        _ => return None,
    };
    (1..=rest.len()).rev().find_map(|n| {
        let name = root.iter().chain(&rest[..n]).copied().collect::<Vec<_>>().join("::");
        modules.contains(&name).then_some(name)
    })
}

/// `a::{b, c::d}` written out as `a::b a::c::d`, innermost groups first.
fn expand_groups(mut text: String) -> String {
    while let Some(close) = text.find('}').filter(|_| text.contains("::{")) {
        let Some(open) = text[..close].rfind("::{") else { break };
        let start = text[..open].rfind(|c: char| !(c.is_alphanumeric() || c == '_' || c == ':')).map_or(0, |i| i + 1);
        let prefix = text[start..open].to_string();
        let items: Vec<String> = text[open + 3..close]
            .split(|c: char| c == ',' || c.is_whitespace())
            .filter(|i| !i.is_empty())
            .map(|i| format!("{prefix}::{i}"))
            .collect();
        text.replace_range(start..=close, &items.join(" "));
    }
    text
}

/// Modules declared only for tests (`#[cfg(test)] mod x;`) in a file of module `parent`.
fn test_only(parent: &str, text: &str) -> Vec<String> {
    let lines: Vec<&str> = text.lines().map(str::trim).collect();
    lines
        .windows(2)
        .filter(|w| w[0] == "#[cfg(test)]")
        .filter_map(|w| w[1].strip_prefix("mod ")?.strip_suffix(';'))
        .map(|m| if parent.is_empty() { m.to_string() } else { format!("{parent}::{m}") })
        .collect()
}

fn graph() -> Graph {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut named: Vec<(String, String)> = Vec::new();
    let mut tests_only = BTreeSet::new();
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap();
        let name = module_name(&src, &f);
        tests_only.extend(test_only(name.as_deref().unwrap_or(""), &text));
        if let Some(name) = name {
            named.push((name, text));
        }
    }
    named.retain(|(n, _)| !tests_only.iter().any(|t| n == t || n.starts_with(&format!("{t}::"))));
    let modules: BTreeSet<String> = named.iter().map(|(n, _)| n.clone()).collect();
    let mut g = Graph::new();
    for (name, text) in &named {
        let text = expand_groups(code(text));
        let arrows = g.entry(name.clone()).or_default();
        for word in text.split(|c: char| !(c.is_alphanumeric() || c == '_' || c == ':')) {
            let path: Vec<&str> = word.split("::").filter(|p| !p.is_empty()).collect();
            if let Some(to) = target(&path, name, &modules).filter(|t| t != name) {
                // A module's own children are below it, not beside it.
                if !to.starts_with(&format!("{name}::")) {
                    arrows.insert(to);
                }
            }
        }
    }
    g
}

/// The strongly connected components of more than one module (Tarjan).
fn circles(g: &Graph) -> Vec<Vec<String>> {
    struct T<'a> {
        g: &'a Graph,
        index: BTreeMap<&'a str, usize>,
        low: BTreeMap<&'a str, usize>,
        stack: Vec<&'a str>,
        out: Vec<Vec<String>>,
    }
    fn visit<'a>(t: &mut T<'a>, v: &'a str) {
        let i = t.index.len();
        t.index.insert(v, i);
        t.low.insert(v, i);
        t.stack.push(v);
        for w in t.g.get(v).into_iter().flatten() {
            let w = w.as_str();
            if !t.g.contains_key(w) {
                continue;
            }
            if !t.index.contains_key(w) {
                visit(t, w);
                t.low.insert(v, t.low[v].min(t.low[w]));
            } else if t.stack.contains(&w) {
                t.low.insert(v, t.low[v].min(t.index[w]));
            }
        }
        if t.low[v] == t.index[v] {
            let at = t.stack.iter().rposition(|&x| x == v).unwrap();
            let comp: Vec<String> = t.stack.drain(at..).map(String::from).collect();
            if comp.len() > 1 {
                t.out.push(comp);
            }
        }
    }
    let mut t = T { g, index: BTreeMap::new(), low: BTreeMap::new(), stack: Vec::new(), out: Vec::new() };
    for v in g.keys() {
        if !t.index.contains_key(v.as_str()) {
            visit(&mut t, v);
        }
    }
    t.out
}

#[test]
fn no_import_circle_among_the_library_modules() {
    let g = graph();
    assert!(
        g.len() > 50 && g["calib::analysis::closure"].contains("calib::analysis::selection"),
        "the graph was not read: {g:?}"
    );
    assert_eq!(circles(&g), Vec::<Vec<String>>::new());
}

#[test]
fn the_calibration_imports_neither_the_simulator_nor_the_presentation() {
    let g = graph();
    let above = |t: &String| ["sim", "present", "report"].iter().any(|m| t == m || t.starts_with(&format!("{m}::")));
    let upward: Vec<(&String, &String)> = g
        .iter()
        .filter(|(from, _)| from.starts_with("calib"))
        .flat_map(|(from, to)| to.iter().filter(|t| above(t)).map(move |t| (from, t)))
        .collect();
    assert!(g.contains_key("present::html") && g["present::html"].contains("calib::analysis::closure"), "{g:?}");
    assert_eq!(upward, Vec::<(&String, &String)>::new());
}

/// The calibration's layers, lowest first (`host/src/calib/mod.rs` says what each holds). A layer
/// imports only the layers below it; nothing inside them imports the calibration's face
/// (`calib` itself, whose re-exports are for the modules outside).
const LAYERS: [&str; 5] = ["result", "data", "effects", "engine", "analysis"];

fn layer_of(module: &str) -> Option<usize> {
    let rest = module.strip_prefix("calib::")?;
    LAYERS.iter().position(|l| rest == *l || rest.starts_with(&format!("{l}::")))
}

/// The arrows of `g` that go from a calibration layer up to a higher one or to the face.
fn upward_in_calib(g: &Graph) -> Vec<(String, String)> {
    let mut out = Vec::new();
    for (from, tos) in g {
        let Some(low) = layer_of(from) else { continue };
        for to in tos {
            if to == "calib" || layer_of(to).is_some_and(|high| high > low) {
                out.push((from.clone(), to.clone()));
            }
        }
    }
    out
}

#[test]
fn the_calibrations_layers_import_one_way() {
    let g = graph();
    assert!(LAYERS.iter().all(|l| g.contains_key(&format!("calib::{l}"))), "a layer is missing: {g:?}");
    assert!(g["calib::engine::loop_data"].contains("calib::data::kinematics"), "the graph was not read: {g:?}");
    assert_eq!(upward_in_calib(&g), Vec::<(String, String)>::new());
}

#[test]
fn an_upward_arrow_is_found() {
    let mut g = Graph::new();
    for (a, b) in [
        ("calib::data::x", "calib::result::y"),
        ("calib::result::y", "calib::engine::z"),
        ("calib::effects::e", "calib"),
    ] {
        g.entry(a.into()).or_default().insert(b.into());
    }
    let expected = [("calib::effects::e", "calib"), ("calib::result::y", "calib::engine::z")];
    assert_eq!(upward_in_calib(&g), expected.map(|(a, b)| (a.to_string(), b.to_string())).to_vec());
}

/// The reader itself: a circle written into a graph is found, and only it.
#[test]
fn use_groups_are_written_out() {
    assert_eq!(expand_groups("use super::{a::{B, C}, d};".into()), "use super::a::B super::a::C super::d;");
}

#[test]
fn a_circle_is_found() {
    let mut g = Graph::new();
    for (a, b) in [("a", "b"), ("b", "c"), ("c", "a"), ("c", "d")] {
        g.entry(a.into()).or_default().insert(b.into());
        g.entry(b.into()).or_default();
    }
    let found = circles(&g);
    assert_eq!(found.len(), 1);
    assert_eq!(found[0].iter().cloned().collect::<BTreeSet<_>>(), ["a", "b", "c"].map(String::from).into());
}

// No function of the calibration engine (`host/src/calib/`) runs over 100 lines, its body's
// closing brace included: a longer one holds more than one step of the method and is split
// into the steps (the project's code standard). A function starts at a line `fn name(` (any
// visibility) and ends at the first later line that is its indentation followed by `}`, which
// rustfmt guarantees.

const MAX_LINES: usize = 100;

/// The name of the function a line opens, and the line's indentation.
fn opens_fn(line: &str) -> Option<(&str, usize)> {
    let indent = line.len() - line.trim_start().len();
    let mut words = line.split_whitespace();
    let mut word = words.next()?;
    while matches!(word, "pub" | "const" | "async" | "unsafe" | "extern") || word.starts_with("pub(") {
        word = words.next()?;
    }
    if word != "fn" || line.trim_end().ends_with(';') {
        return None;
    }
    let name = words.next()?.split(['(', '<']).next()?;
    Some((name, indent))
}

/// (name, lines) of every function of `text` longer than [`MAX_LINES`].
fn long_functions(text: &str) -> Vec<(String, usize)> {
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        if let Some((name, indent)) = opens_fn(lines[i]) {
            let close = format!("{}}}", " ".repeat(indent));
            let end = (i + 1..lines.len()).find(|&j| lines[j].starts_with(&close)).unwrap_or(lines.len() - 1);
            let n = end - i + 1;
            if n > MAX_LINES {
                out.push((name.to_string(), n));
            }
            // Nested functions are inside this one's count: go on after it.
            i = end;
        }
        i += 1;
    }
    out
}

#[test]
fn no_function_of_the_calibration_engine_runs_over_100_lines() {
    let calib = Path::new(env!("CARGO_MANIFEST_DIR")).join("src/calib");
    let mut files = Vec::new();
    rust_files(&calib, &mut files);
    assert!(files.len() > 20, "{files:?}");
    let long: Vec<String> = files
        .iter()
        .flat_map(|f| {
            let text = std::fs::read_to_string(f).unwrap();
            long_functions(&text).into_iter().map(move |(name, n)| format!("{}: {name}, {n} lines", f.display()))
        })
        .collect();
    assert_eq!(long, Vec::<String>::new());
}

/// The reader itself: a 101-line function is found, a 100-line one and a declaration are not.
#[test]
fn a_long_function_is_found() {
    let body =
        |name: &str, n: usize| format!("    pub(crate) fn {name}() {{\n{}    }}\n", "        x();\n".repeat(n - 2));
    let text = format!("{}{}    fn f();\n", body("long", 101), body("short", 100));
    assert_eq!(long_functions(&text), vec![("long".to_string(), 101)]);
}
