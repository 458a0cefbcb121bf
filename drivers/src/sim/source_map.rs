//! Where each field of a scenario file is: dotted field paths mapped to 1-based lines, so
//! that type errors and semantic errors can name the file, the line and the field.

use toml::de::{DeTable, DeValue};

/// One key/value pair of the document: its dotted path and byte spans.
#[derive(Debug, Clone)]
struct Entry {
    path: String,
    key_start: usize,
    value_span: std::ops::Range<usize>,
}

/// The field locations of one scenario text.
#[derive(Debug, Clone, Default)]
pub struct SourceMap {
    /// Where the text came from (file path or a label such as `<embedded default_drive.toml>`).
    pub origin: String,
    /// Byte offset of the start of each line.
    line_starts: Vec<usize>,
    entries: Vec<Entry>,
}

impl SourceMap {
    /// Maps the fields of `text`; without field entries when the text is not syntactically
    /// valid TOML (the syntax error is then reported by the deserializer with its position).
    pub fn build(text: &str, origin: &str) -> Self {
        let mut map = Self {
            origin: origin.to_owned(),
            line_starts: line_starts(text),
            entries: Vec::new(),
        };
        if let Ok(doc) = DeTable::parse(text) {
            map.walk_table(doc.get_ref(), "");
        }
        map
    }

    /// A map without any field locations (text not available).
    pub fn unknown(origin: &str) -> Self {
        Self {
            origin: origin.to_owned(),
            ..Self::default()
        }
    }

    fn walk_table(&mut self, table: &DeTable<'_>, prefix: &str) {
        for (key, value) in table.iter() {
            let path = join(prefix, key.get_ref());
            self.entries.push(Entry {
                path: path.clone(),
                key_start: key.span().start,
                value_span: value.span(),
            });
            self.walk_value(value.get_ref(), &path);
        }
    }

    fn walk_value(&mut self, value: &DeValue<'_>, path: &str) {
        match value {
            DeValue::Table(t) => self.walk_table(t, path),
            DeValue::Array(items) => {
                for (i, item) in items.iter().enumerate() {
                    let p = format!("{path}[{i}]");
                    if let DeValue::Table(_) = item.get_ref() {
                        let span = item.span();
                        self.entries.push(Entry {
                            path: p.clone(),
                            key_start: span.start,
                            value_span: span,
                        });
                    }
                    self.walk_value(item.get_ref(), &p);
                }
            }
            _ => {}
        }
    }

    /// 1-based line and column of byte offset `pos`.
    pub fn line_col(&self, pos: usize) -> (usize, usize) {
        let line = self.line_starts.partition_point(|&s| s <= pos).max(1);
        let start = self.line_starts.get(line - 1).copied().unwrap_or(0);
        (line, pos.saturating_sub(start) + 1)
    }

    /// 1-based line of the field `path` (e.g. `trajectory.segment[2].duration_s`); falls back
    /// to the nearest enclosing table or array element that appears in the text.
    pub fn line_of(&self, path: &str) -> Option<usize> {
        let mut p = path;
        loop {
            if let Some(e) = self.entries.iter().find(|e| e.path == p) {
                return Some(self.line_col(e.key_start).0);
            }
            p = parent(p)?;
        }
    }

    /// Dotted path of the innermost field whose key or value covers byte offset `pos`.
    pub fn field_at(&self, pos: usize) -> Option<&str> {
        self.entries
            .iter()
            .filter(|e| e.key_start <= pos && pos < e.value_span.end.max(e.key_start + 1))
            .max_by_key(|e| e.key_start)
            .map(|e| e.path.as_str())
    }
}

fn join(prefix: &str, key: &str) -> String {
    if prefix.is_empty() {
        key.to_owned()
    } else {
        format!("{prefix}.{key}")
    }
}

/// The enclosing path: `a.b[2].c` → `a.b[2]` → `a.b` → `a` → none.
fn parent(path: &str) -> Option<&str> {
    let cut = path.rfind(['.', '['])?;
    Some(&path[..cut])
}

fn line_starts(text: &str) -> Vec<usize> {
    std::iter::once(0)
        .chain(text.match_indices('\n').map(|(i, _)| i + 1))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    const DOC: &str = "seed = 3\n\n[trajectory.start]\nlat_deg = 1.0\n\n[[trajectory.segment]]\nkind = \"static\"\nduration_s = 5.0\n\n[[trajectory.segment]]\nkind = \"cruise\"\nduration_s = 7.0\n";

    #[test]
    fn lines_of_fields_and_array_elements() {
        let m = SourceMap::build(DOC, "t.toml");
        assert_eq!(m.line_of("seed"), Some(1));
        assert_eq!(m.line_of("trajectory.start.lat_deg"), Some(4));
        assert_eq!(m.line_of("trajectory.segment[1].duration_s"), Some(12));
        assert_eq!(m.line_of("trajectory.segment[0].kind"), Some(7));
        // A field that is absent falls back to its table.
        let seg1 = m.line_of("trajectory.segment[1].to_speed_mps").expect("segment line");
        assert!((10..=12).contains(&seg1), "segment 1 at line {seg1}");
    }

    #[test]
    fn field_at_offset() {
        let m = SourceMap::build(DOC, "t.toml");
        let pos = DOC.find("7.0").expect("present");
        assert_eq!(m.field_at(pos), Some("trajectory.segment[1].duration_s"));
        assert_eq!(m.line_col(pos).0, 12);
    }
}
