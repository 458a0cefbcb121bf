//! The configuration loader: TOML text → `Loaded::parse` (TOML, serde into the roles' typed
//! values — the drivers' parsers run during deserialisation —, the source map that locates
//! errors, the semantic checks), then what the roles do with an accepted file.
//!
//! Checks: no panic; an error's line/column lies inside the text; an accepted file satisfies
//! every rule `Loaded::check` documents (ids, rates, ranges, finite lever arms and angles,
//! 1..=8 estimator IMUs), and its mounting rotations are finite orthonormal matrices.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use navsync::config::estimator::EstimatorFlags;
use navsync::config::{ConfigError, Loaded, valid_id};
use navsync_shared::source_map::SourceMap;

fn check_location(e: &ConfigError, text: &str) {
    let lines = text.split('\n').count();
    if let Some((l, c)) = e.line {
        assert!(l >= 1 && l <= lines, "line {l} of {lines}: {e}");
        assert!(c >= 1 && c <= text.len() + 1, "column {c}: {e}");
    }
    assert!(!e.to_string().is_empty());
}

fn check_accepted(l: &Loaded, text: &str) {
    let c = &l.config;
    for id in c.gnss.keys().chain(c.pps.keys()).chain(c.imu.keys()) {
        assert!(valid_id(id), "{id:?}");
    }
    for g in c.gnss.values() {
        assert!(!g.port.is_empty());
        assert!(g.lever_arm_m.iter().all(|x| x.is_finite()));
    }
    for i in c.imu.values() {
        if let Some(r) = i.rate_hz {
            assert!(r.is_finite() && r > 1.0 && r <= 100_000.0, "rate {r}");
        }
        for r in [i.gyro_range_dps, i.accel_range_g].into_iter().flatten() {
            assert!(r.is_finite() && r > 0.0, "range {r}");
        }
        assert_ne!(i.buffer_length, Some(0));
        assert!(i.mounting.rotation_deg.iter().all(|x| x.is_finite()));
        assert!(i.mounting.lever_arm_m.iter().all(|x| x.is_finite()));
        let m = i.mounting.c_b_s();
        for (r, row) in m.iter().enumerate() {
            let norm: f64 = row.iter().map(|x| x * x).sum();
            assert!((norm - 1.0).abs() < 1e-9, "row {r} of {m:?}");
        }
        // The typed values print back as text the parsers take again.
        assert_eq!(i.source.to_string().parse().ok(), Some(i.source.clone()));
        if let Some(a) = i.axes {
            assert_eq!(a.to_string().parse().ok(), Some(a));
        }
    }
    // What `navsync estimator` and the offline tools build from an accepted file.
    // An accepted file gives settings that pass their checks (the loader ran them).
    let s = EstimatorFlags::default()
        .settings(l)
        .expect("an accepted file gives the estimator's settings");
    assert!(s.check().is_ok());
    assert!((1..=8).contains(&s.inputs.imus.len()));
    for ids in [&s.inputs.gnss, &s.inputs.pps, &s.inputs.imus] {
        assert!(ids.iter().all(|id| valid_id(id)), "{ids:?}");
    }
    let _ = s.pipeline_config();
    for p in [
        "logging.level",
        "imu",
        "imu.0.mounting.lever_arm_m[2]",
        "estimator.imus[9]",
        "",
        ".",
    ] {
        check_location(&l.error_at(p, "x"), text);
    }
}

fuzz_target!(|data: &[u8]| {
    let Ok(text) = core::str::from_utf8(data) else {
        return;
    };
    match Loaded::parse(text, Path::new("fuzz.toml")) {
        Ok(l) => check_accepted(&l, text),
        Err(e) => check_location(&e, text),
    }
    // The source map on its own, at a few offsets.
    let map = SourceMap::build(text);
    for pos in [0, text.len() / 2, text.len(), text.len() + 1] {
        let (line, col) = map.line_col(pos);
        assert!(line >= 1 && col >= 1);
        let _ = map.field_at(pos);
    }
});
