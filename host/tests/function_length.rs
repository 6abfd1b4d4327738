//! No function of the calibration engine (`host/src/calib/`) runs over 100 lines, its body's
//! closing brace included: a longer one holds more than one step of the method and is split
//! into the steps (the project's code standard). Read from the sources: a function starts at a
//! line `fn name(` (any visibility) and ends at the first later line that is its indentation
//! followed by `}`, which rustfmt guarantees.

use std::path::{Path, PathBuf};

const MAX_LINES: usize = 100;

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
