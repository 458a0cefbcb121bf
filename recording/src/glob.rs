//! Service-name patterns for `--services`: `*` matches within one path segment, `**` across
//! segments, `?` one character of a segment; anything else matches itself.
//! `navsync/imu/*/sample` matches every IMU, `navsync/**` every service.

/// A service-name pattern.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ServiceGlob(String);

impl ServiceGlob {
    /// A pattern.
    pub fn new(pattern: &str) -> Self {
        Self(pattern.to_string())
    }

    /// The pattern text.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// True when the pattern has no wildcard (it names one service).
    pub fn is_literal(&self) -> bool {
        !self.0.contains(['*', '?'])
    }

    /// Whether `name` matches.
    pub fn matches(&self, name: &str) -> bool {
        glob_match(self.0.as_bytes(), name.as_bytes())
    }
}

/// True when any of `globs` matches `name` (an empty list matches everything).
pub fn any_matches(globs: &[ServiceGlob], name: &str) -> bool {
    globs.is_empty() || globs.iter().any(|g| g.matches(name))
}

fn glob_match(p: &[u8], s: &[u8]) -> bool {
    match p {
        [] => s.is_empty(),
        [b'*', b'*', rest @ ..] => (0..=s.len()).any(|i| glob_match(rest, &s[i..])),
        [b'*', rest @ ..] => {
            let seg = s.iter().position(|&c| c == b'/').unwrap_or(s.len());
            (0..=seg).any(|i| glob_match(rest, &s[i..]))
        }
        [b'?', rest @ ..] => matches!(s, [c, ..] if *c != b'/') && glob_match(rest, &s[1..]),
        [c, rest @ ..] => matches!(s, [d, ..] if d == c) && glob_match(rest, &s[1..]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn patterns() {
        let g = ServiceGlob::new;
        assert!(g("navsync/imu/*/sample").matches("navsync/imu/0/sample"));
        assert!(!g("navsync/imu/*/sample").matches("navsync/imu/0/x/sample"));
        assert!(g("navsync/**").matches("navsync/imu/0/sample"));
        assert!(g("navsync/**/state").matches("navsync/nav/state"));
        assert!(g("navsync/health/*").matches("navsync/health/gps-0"));
        assert!(g("navsync/imu/?/sample").matches("navsync/imu/3/sample"));
        assert!(!g("navsync/imu/?/sample").matches("navsync/imu/12/sample"));
        assert!(g("navsync/nav/state").matches("navsync/nav/state"));
        assert!(!g("navsync/nav/state").matches("navsync/nav/states"));
        assert!(g("navsync/nav/state").is_literal());
        assert!(!g("navsync/*").is_literal());
        assert!(any_matches(&[], "x"));
        assert!(!any_matches(&[g("a")], "b"));
    }
}
