//! Where in a profile's TOML text an error is, as a line and column.
//!
//! Owns the path into the document ([`Seg`]), a validation failure with its
//! place ([`Invalid`]) and the look-up of a path's byte offset. Never fails:
//! a path the document does not hold points as deep as it goes.

/// One step of a path into the TOML document, to find where an error is.
#[derive(Debug, Clone, Copy)]
pub(super) enum Seg {
    Key(&'static str),
    Index(usize),
}

/// A validation failure and where it is.
#[derive(Debug)]
pub(super) struct Invalid {
    pub(super) path: Vec<Seg>,
    /// Where to point instead if the document does not contain `path`.
    pub(super) alternative: Option<Vec<Seg>>,
    pub(super) message: String,
}

impl Invalid {
    pub(super) fn at(path: &[Seg], message: String) -> Self {
        Self {
            path: path.to_vec(),
            alternative: None,
            message,
        }
    }

    /// Byte offset of the failure in `text`.
    pub(super) fn offset(&self, text: &str) -> usize {
        match (locate(text, &self.path), &self.alternative) {
            ((offset, true), _) | ((offset, false), None) => offset,
            ((offset, false), Some(alt)) => match locate(text, alt) {
                (alt_offset, true) => alt_offset,
                _ => offset,
            },
        }
    }
}

/// 1-based line and column (in characters) of a byte offset.
pub(super) fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let mut offset = offset.min(text.len());
    while !text.is_char_boundary(offset) {
        offset -= 1;
    }
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    (line, before[line_start..].chars().count() + 1)
}

/// Byte offset of the value at `path`, as deep as the document goes
/// (a key left to its default points at its table), and whether the whole
/// path was found.
pub(super) fn locate(text: &str, path: &[Seg]) -> (usize, bool) {
    use toml::de::{DeTable, DeValue};
    let Ok(root) = DeTable::parse(text) else {
        return (0, false);
    };
    let mut offset = 0;
    let mut table = Some(root.get_ref());
    let mut array = None;
    for seg in path {
        let found = match (*seg, table, array) {
            (Seg::Key(k), Some(t), _) => t
                .iter()
                .find(|(key, _)| &**key.get_ref() == k)
                .map(|(key, v)| (key.span(), v)),
            (Seg::Index(i), _, Some(a)) => {
                let a: &toml::de::DeArray<'_> = a;
                // Past the end (too many entries): point at the last one.
                a.get(i).or(a.last()).map(|v| (v.span(), v))
            }
            _ => None,
        };
        let Some((key_span, v)) = found else {
            return (offset, false);
        };
        offset = match seg {
            Seg::Key(_) if !matches!(v.get_ref(), DeValue::Array(_) | DeValue::Table(_)) => {
                v.span().start
            }
            Seg::Key(_) => key_span.start,
            Seg::Index(_) => v.span().start,
        };
        table = v.get_ref().as_table();
        array = v.get_ref().as_array();
    }
    (offset, true)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_column_counts_characters() {
        let t = "a = 1\nµb = 2\n";
        assert_eq!(line_column(t, 0), (1, 1));
        assert_eq!(line_column(t, 6), (2, 1));
        assert_eq!(line_column(t, 8), (2, 2));
        assert_eq!(line_column(t, 7), (2, 1));
        assert_eq!(line_column(t, 999), (3, 1));
    }

    #[test]
    fn locate_finds_array_elements_and_nested_keys() {
        let t = "name = \"x\"\nbuttons = [0, 1, 200]\n[rc]\nheave = 30\n";
        let (l, c) = line_column(t, locate(t, &[Seg::Key("buttons"), Seg::Index(2)]).0);
        assert_eq!((l, c), (2, 18));
        let (l, c) = line_column(t, locate(t, &[Seg::Key("rc"), Seg::Key("heave")]).0);
        assert_eq!((l, c), (4, 9));
    }
}
