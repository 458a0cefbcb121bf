//! Axis maps: how a device's x, y, z become the published forward-right-down axes.
//!
//! Written as three signed device axes, one per published axis: `x,-y,-z` means published
//! x = device x, published y = −device y, published z = −device z, which turns a z-up device
//! frame (Xsens' sensor frame S, and most MEMS chips lying flat with their top up) into
//! forward-right-down. Only signed permutations are accepted (a proper or improper rotation
//! by multiples of 90°); a mounting at another angle belongs in the estimator's
//! configuration, not here.

use std::str::FromStr;

/// A signed permutation of the three axes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AxisMap {
    /// For each published axis: (device axis index, sign).
    pub from: [(usize, i8); 3],
}

impl AxisMap {
    /// The identity map `x,y,z`.
    pub const IDENTITY: Self = Self {
        from: [(0, 1), (1, 1), (2, 1)],
    };
    /// `x,-y,-z`: a z-up device frame (x forward, y left, z up) to forward-right-down.
    pub const Z_UP_TO_FRD: Self = Self {
        from: [(0, 1), (1, -1), (2, -1)],
    };

    /// Maps a device vector to the published axes.
    pub fn apply(&self, v: [f64; 3]) -> [f64; 3] {
        self.from.map(|(i, s)| f64::from(s) * v[i])
    }

    /// Maps a published vector back to the device axes (for simulators and tests).
    pub fn invert(&self, p: [f64; 3]) -> [f64; 3] {
        let mut v = [0.0; 3];
        for (k, (i, s)) in self.from.iter().enumerate() {
            v[*i] = f64::from(*s) * p[k];
        }
        v
    }
}

impl std::fmt::Display for AxisMap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let parts = self
            .from
            .map(|(i, s)| format!("{}{}", if s < 0 { "-" } else { "" }, ["x", "y", "z"][i]));
        write!(f, "{}", parts.join(","))
    }
}

deserialize_from_str!(AxisMap);

impl FromStr for AxisMap {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let bad = || format!("`{s}` is not an axis map: expected three signed device axes, each once, e.g. `x,-y,-z`");
        let parts: Vec<&str> = s.split(',').map(str::trim).collect();
        if parts.len() != 3 {
            return Err(bad());
        }
        let mut from = [(0usize, 1i8); 3];
        let mut seen = [false; 3];
        for (slot, p) in from.iter_mut().zip(&parts) {
            let (sign, axis) = match p.strip_prefix('-') {
                Some(a) => (-1, a),
                None => (1, p.strip_prefix('+').unwrap_or(p)),
            };
            let i = match axis {
                "x" => 0,
                "y" => 1,
                "z" => 2,
                _ => return Err(bad()),
            };
            if std::mem::replace(&mut seen[i], true) {
                return Err(bad());
            }
            *slot = (i, sign);
        }
        Ok(Self { from })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_apply_invert() {
        let m: AxisMap = "y, x, -z".parse().unwrap();
        assert_eq!(m.apply([1.0, 2.0, 3.0]), [2.0, 1.0, -3.0]);
        assert_eq!(m.invert(m.apply([1.0, 2.0, 3.0])), [1.0, 2.0, 3.0]);
        assert_eq!("x,-y,-z".parse::<AxisMap>().unwrap(), AxisMap::Z_UP_TO_FRD);
        assert_eq!(AxisMap::Z_UP_TO_FRD.to_string(), "x,-y,-z");
        assert_eq!("+x,+y,+z".parse::<AxisMap>().unwrap(), AxisMap::IDENTITY);
        for bad in ["x,y", "x,x,z", "x,y,w", "x,y,z,x", ""] {
            let e = bad.parse::<AxisMap>().unwrap_err();
            assert!(e.contains("e.g. `x,-y,-z`"), "{e}");
        }
    }
}
