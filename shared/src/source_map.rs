//! Where each field of a configuration file is: dotted field paths mapped to byte offsets, so
//! that syntax, type and semantic errors can name the file, the line and the field.

use toml::de::{DeTable, DeValue};

#[derive(Debug, Clone)]
struct Entry {
    path: String,
    key_start: usize,
    value_span: std::ops::Range<usize>,
}

/// The field locations of one configuration text.
#[derive(Debug, Clone, Default)]
pub struct SourceMap {
    line_starts: Vec<usize>,
    entries: Vec<Entry>,
}

impl SourceMap {
    /// Maps the fields of `text` (none when the text is not valid TOML: the parser's error
    /// then carries the position).
    pub fn build(text: &str) -> Self {
        let mut map = Self {
            line_starts: std::iter::once(0)
                .chain(text.match_indices('\n').map(|(i, _)| i + 1))
                .collect(),
            entries: Vec::new(),
        };
        if let Ok(doc) = DeTable::parse(text) {
            map.walk_table(doc.get_ref(), "");
        }
        map
    }

    fn walk_table(&mut self, table: &DeTable<'_>, prefix: &str) {
        for (key, value) in table.iter() {
            let path = if prefix.is_empty() {
                key.get_ref().to_string()
            } else {
                format!("{prefix}.{}", key.get_ref())
            };
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
                    let span = item.span();
                    self.entries.push(Entry {
                        path: p.clone(),
                        key_start: span.start,
                        value_span: span,
                    });
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

    /// Line and column of the value of field `path` (e.g. `imu.0.rate_hz`), else of the
    /// nearest enclosing field that appears in the text.
    pub fn locate(&self, path: &str) -> Option<(usize, usize)> {
        let mut p = path;
        loop {
            if let Some(e) = self.entries.iter().find(|e| e.path == p) {
                let at = if p == path { e.value_span.start } else { e.key_start };
                return Some(self.line_col(at));
            }
            p = &p[..p.rfind(['.', '['])?];
        }
    }

    /// Dotted path of the innermost field whose key or value covers byte offset `pos`.
    pub fn field_at(&self, pos: usize) -> Option<&str> {
        self.entries
            .iter()
            .filter(|e| e.key_start <= pos && pos < e.value_span.end.max(e.key_start + 1))
            .max_by_key(|e| (e.key_start, e.path.len()))
            .map(|e| e.path.as_str())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_and_positions() {
        let doc = "[imu.0]\nsource = \"sim\"\nrate_hz = 200\n\n[estimator]\nimus = [\"0\", \"1\"]\n";
        let m = SourceMap::build(doc);
        assert_eq!(m.locate("imu.0.rate_hz"), Some((3, 11)));
        assert_eq!(m.locate("estimator.imus[1]"), Some((6, 14)));
        assert_eq!(m.locate("imu.0.axes"), Some((1, 6)), "absent: its table");
        let pos = doc.find("200").unwrap();
        assert_eq!(m.field_at(pos), Some("imu.0.rate_hz"));
    }

    #[test]
    fn array_of_tables_elements_and_absent_fields() {
        let doc = "seed = 3\n\n[trajectory.start]\nlat_deg = 1.0\n\n[[trajectory.segment]]\nkind = \"static\"\nduration_s = 5.0\n\n[[trajectory.segment]]\nkind = \"cruise\"\nduration_s = 7.0\n";
        let m = SourceMap::build(doc);
        let line = |p: &str| m.locate(p).map(|(l, _)| l);
        assert_eq!(line("seed"), Some(1));
        assert_eq!(line("trajectory.start.lat_deg"), Some(4));
        assert_eq!(line("trajectory.segment[1].duration_s"), Some(12));
        assert_eq!(line("trajectory.segment[0].kind"), Some(7));
        // A field that is absent falls back to its array element.
        let seg1 = line("trajectory.segment[1].to_speed_mps").expect("segment line");
        assert!((10..=12).contains(&seg1), "segment 1 at line {seg1}");
        let pos = doc.find("7.0").expect("present");
        assert_eq!(m.field_at(pos), Some("trajectory.segment[1].duration_s"));
        assert_eq!(m.line_col(pos).0, 12);
    }
}
