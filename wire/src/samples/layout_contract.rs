//! The sample layouts are a contract between processes built at different times (and the
//! Python `ctypes` mirror). This test fails when a type's size or any field offset/type
//! changes while its layout version (the `.vN` in its type name) stays the same.
//!
//! After a deliberate layout change: bump the version in the type's `sample_struct!` name,
//! then replace that type's line in `layout_snapshot.txt` with the line this test prints.

use crate::reflect::{Field, FieldType, Reflect};
use crate::samples::*;

fn ty(t: &FieldType) -> String {
    match t {
        FieldType::Str(n) => format!("str{n}"),
        FieldType::Array(e, n) => format!("[{};{n}]", ty(e)),
        FieldType::Struct(_, fields) => format!("{{{}}}", fields_sig(fields)),
        other => format!("{other:?}").to_lowercase(),
    }
}

fn fields_sig(fields: &[Field]) -> String {
    fields
        .iter()
        .map(|f| format!("{}@{}:{}", f.name, f.offset, ty(&f.ty)))
        .collect::<Vec<_>>()
        .join(",")
}

fn signature<T: Reflect>() -> String {
    format!(
        "{} size={} align={} {}",
        T::TYPE_NAME,
        size_of::<T>(),
        align_of::<T>(),
        fields_sig(T::FIELDS)
    )
}

fn all() -> Vec<String> {
    vec![
        signature::<GnssFix>(),
        signature::<PpsEdge>(),
        signature::<ImuSample>(),
        signature::<TimeState>(),
        signature::<NavState>(),
        signature::<Health>(),
        signature::<SimTruth>(),
        signature::<GnssTimePulse>(),
        signature::<GnssEvent>(),
        signature::<GnssRaw>(),
        signature::<GnssNavData>(),
        signature::<EstimatorSettings>(),
        signature::<NetworkTime>(),
        signature::<GnssSky>(),
        signature::<EventPose>(),
    ]
}

#[test]
fn field_tables_describe_the_real_layout() {
    fn check<T: Reflect>() {
        let described = FieldType::Struct(T::TYPE_NAME, T::FIELDS);
        assert_eq!(described.size(), size_of::<T>(), "{}: table size", T::TYPE_NAME);
        assert_eq!(described.align(), align_of::<T>(), "{}: table alignment", T::TYPE_NAME);
    }
    check::<GnssFix>();
    check::<PpsEdge>();
    check::<ImuSample>();
    check::<TimeState>();
    check::<NavState>();
    check::<Health>();
    check::<SimTruth>();
    check::<GnssTimePulse>();
    check::<GnssEvent>();
    check::<RawMeasurement>();
    check::<GnssRaw>();
    check::<GnssNavData>();
    check::<EstimatorSettings>();
    check::<NetworkTime>();
    check::<GnssSky>();
    check::<EventPose>();
}

#[test]
fn layouts_match_their_versions() {
    let snapshot = include_str!("layout_snapshot.txt");
    let mut failures = Vec::new();
    for sig in all() {
        let name = sig.split(' ').next().unwrap_or_default();
        match snapshot.lines().find(|l| l.split(' ').next() == Some(name)) {
            Some(line) if line == sig => {}
            Some(_) => failures.push(format!(
                "{name} changed layout without a version bump; bump it and record:\n{sig}"
            )),
            None => failures.push(format!("{name} is not in layout_snapshot.txt; add:\n{sig}")),
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

#[test]
fn json_round_trip_is_bit_exact() {
    let mut fix = GnssFix::empty(Stamp::with_device(123_456_789, -5, 7, StampSource::Receipt));
    fix.lat_deg = 30.123_456_789_012_3;
    fix.lon_deg = -114.000_000_000_000_1;
    fix.alt_msl_m = 0.1 + 0.2;
    fix.utc_ns = i64::MAX - 3;
    fix.sentences = 0b1011;
    fix.mode = 3;
    let json = crate::json::to_json(&fix);
    assert!(json["vel_d_mps"].is_null(), "NaN must be written as null");
    let text = serde_json::to_string(&json).unwrap();
    let back: GnssFix = crate::json::from_json(&serde_json::from_str(&text).unwrap()).unwrap();
    assert_eq!(back.lat_deg.to_bits(), fix.lat_deg.to_bits());
    assert_eq!(back.alt_msl_m.to_bits(), fix.alt_msl_m.to_bits());
    assert_eq!(back.utc_ns, fix.utc_ns);
    assert_eq!(back.stamp, fix.stamp);
    assert!(back.vel_d_mps.is_nan());

    let mut h = Health::new("gps-0");
    h.counters[0].name = crate::reflect::fixed_str("bad_checksum");
    h.counters[0].value = u64::MAX;
    let back: Health = crate::json::from_json(&crate::json::to_json(&h)).unwrap();
    assert_eq!(back, h);
    assert_eq!(back.counter("bad_checksum"), Some(u64::MAX));

    let err = crate::json::from_json::<PpsEdge>(&serde_json::json!({"stamp": {}})).unwrap_err();
    assert!(err.to_string().contains("stamp.host_ns"), "{err}");
}
