//! Plain text for a terminal: long lines wrapped at word boundaries.

/// Width the summaries are wrapped to, characters: 100 reads on a terminal and in an e-mail.
pub const TEXT_WIDTH: usize = 100;

/// Wraps every line of `text` longer than `width` characters at spaces. Continuation lines keep
/// the line's indent, plus two characters under a list item (`- `) so that the item stays one
/// block. A word longer than the width (a path, a digest) stays whole on its own line.
pub fn wrap(text: &str, width: usize) -> String {
    let mut out = String::with_capacity(text.len() + text.len() / width);
    for line in text.split_inclusive('\n') {
        let (body, newline) = line.strip_suffix('\n').map_or((line, ""), |b| (b, "\n"));
        if body.chars().count() <= width {
            out.push_str(line);
            continue;
        }
        let indent = body.len() - body.trim_start().len();
        let hang = indent + if body.trim_start().starts_with("- ") { 2 } else { 0 };
        let mut current = body[..indent].to_string();
        let mut current_len = indent;
        let mut first_word = true;
        for word in body[indent..].split(' ') {
            let len = word.chars().count();
            if !first_word && current_len + 1 + len > width {
                out.push_str(current.trim_end());
                out.push('\n');
                current = " ".repeat(hang);
                current_len = hang;
                first_word = true;
            }
            if !first_word {
                current.push(' ');
                current_len += 1;
            }
            current.push_str(word);
            current_len += len;
            first_word = false;
        }
        out.push_str(current.trim_end());
        out.push_str(newline);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn long_lines_wrap_with_their_indent_and_short_ones_stay() {
        let text = "short line\n  - a list item that goes on and on past the width\nlast";
        assert_eq!(wrap(text, 20), "short line\n  - a list item that\n    goes on and on\n    past the width\nlast");
        let digest = "x".repeat(30);
        assert_eq!(wrap(&format!("sha {digest} end\n"), 20), format!("sha\n{digest}\nend\n"));
    }
}
