//! `shared/python/navsync_types.py` is what `navsync python-types` generates from the Rust field
//! tables, and Python's `ctypes` lays every class out exactly as Rust does: the same size,
//! alignment and offset of every field (nested structs and arrays included), and the same
//! iceoryx2 type names. Needs only `python3` (ctypes is in its standard library).

use std::collections::BTreeMap;
use std::process::Command;

use crate::clients_common::repo_root;
use navsync_shared::reflect::{Field, FieldType, Reflect};
use navsync_shared::samples::*;
use navsync_tests::TestEnv;
use serde_json::Value;

/// (class, type name, size, align, offsets of every field including nested ones as dotted paths)
type Layout = (String, String, usize, usize, BTreeMap<String, usize>);

fn nested(prefix: &str, base: usize, fields: &[Field], out: &mut BTreeMap<String, usize>) {
    for f in fields {
        let path = format!("{prefix}{}", f.name);
        out.insert(path.clone(), base + f.offset);
        if let FieldType::Struct(_, inner) = f.ty {
            nested(&format!("{path}."), base + f.offset, inner, out);
        }
        if let FieldType::Array(t, n) = f.ty
            && let FieldType::Struct(_, inner) = *t
        {
            for i in 0..n {
                let at = base + f.offset + i * t.size();
                nested(&format!("{path}[{i}]."), at, inner, out);
            }
        }
    }
}

fn rust<T: Reflect>() -> Layout {
    let mut offsets = BTreeMap::new();
    nested("", 0, T::FIELDS, &mut offsets);
    (
        T::TYPE_NAME.split('.').nth(1).unwrap().to_string(),
        T::TYPE_NAME.to_string(),
        size_of::<T>(),
        align_of::<T>(),
        offsets,
    )
}

const PYTHON: &str = r#"
import ctypes, json, sys
import navsync_types as m

def nested(prefix, base, cls, out):
    for name, ty in cls._fields_:
        off = base + getattr(cls, name).offset
        out[prefix + name] = off
        if isinstance(ty, type) and issubclass(ty, ctypes.Structure):
            nested(prefix + name + ".", off, ty, out)
        elif hasattr(ty, "_length_") and isinstance(ty._type_, type) and issubclass(ty._type_, ctypes.Structure):
            for i in range(ty._length_):
                nested(f"{prefix}{name}[{i}].", off + i * ctypes.sizeof(ty._type_), ty._type_, out)

report = {}
for cls in [v for v in vars(m).values() if isinstance(v, type) and issubclass(v, ctypes.Structure)]:
    offsets = {}
    nested("", 0, cls, offsets)
    assert all(getattr(cls, n).offset == cls.RUST_OFFSETS[n] for n, _ in cls._fields_), cls
    report[cls.__name__] = {
        "type_name": cls.type_name(),
        "size": ctypes.sizeof(cls),
        "align": ctypes.alignment(cls),
        "rust_size": cls.RUST_SIZE,
        "rust_align": cls.RUST_ALIGN,
        "offsets": offsets,
    }
assert m.service_type("navsync/nav/state") is m.NavState
assert m.service_type("navsync/imu/3/sample") is m.ImuSample
assert m.service_type("navsync/health/gps-0") is m.Health
assert m.service_type("navsync/gnss/0/sky") is m.GnssSky
assert m.service_type("navsync/imu//sample") is None
json.dump(report, sys.stdout)
"#;

#[test]
fn generated_python_types_are_current_and_match_the_rust_layouts() {
    let env = TestEnv::new("pytypes");
    let checked_in = repo_root().join("shared/python/navsync_types.py");
    let generated = env.command(&["python-types"]).output().unwrap();
    assert!(generated.status.success());
    let generated = String::from_utf8(generated.stdout).unwrap();
    let file = std::fs::read_to_string(&checked_in).unwrap_or_default();
    assert!(
        file == generated,
        "{} is not what `navsync python-types` generates: regenerate it with\n  cargo run -- python-types > shared/python/navsync_types.py",
        checked_in.display()
    );

    let o = Command::new("python3")
        .arg("-c")
        .arg(PYTHON)
        .env("PYTHONPATH", repo_root().join("shared/python"))
        .output()
        .expect("python3 (ctypes is in its standard library) is needed for this test");
    assert!(o.status.success(), "python: {}", String::from_utf8_lossy(&o.stderr));
    let report: Value = serde_json::from_slice(&o.stdout).unwrap();

    let rust_layouts = [
        rust::<Stamp>(),
        rust::<Counter>(),
        rust::<RateEntry>(),
        rust::<ImuSync>(),
        rust::<GnssFix>(),
        rust::<PpsEdge>(),
        rust::<ImuSample>(),
        rust::<TimeState>(),
        rust::<NavState>(),
        rust::<Health>(),
        rust::<SimTruth>(),
        rust::<GnssTimePulse>(),
        rust::<GnssEvent>(),
        rust::<RawMeasurement>(),
        rust::<GnssRaw>(),
        rust::<GnssNavData>(),
        rust::<EstimatorSettings>(),
        rust::<NetworkTime>(),
        rust::<SkySatellite>(),
        rust::<GnssSky>(),
        rust::<EventPose>(),
    ];
    assert_eq!(report.as_object().unwrap().len(), rust_layouts.len(), "{report}");
    let mut fields = 0;
    for (class, type_name, size, align, offsets) in &rust_layouts {
        let py = &report[class.as_str()];
        assert_eq!(py["type_name"], type_name.as_str(), "{class}");
        assert_eq!(py["size"], *size, "{class}: ctypes.sizeof");
        assert_eq!(py["align"], *align, "{class}: ctypes.alignment");
        assert_eq!(py["rust_size"], *size, "{class}");
        assert_eq!(py["rust_align"], *align, "{class}");
        let py_offsets: BTreeMap<String, usize> = py["offsets"]
            .as_object()
            .unwrap()
            .iter()
            .map(|(k, v)| (k.clone(), v.as_u64().unwrap() as usize))
            .collect();
        assert_eq!(&py_offsets, offsets, "{class}: field offsets");
        fields += offsets.len();
    }
    println!(
        "{} types, {fields} field offsets equal in Python and Rust",
        rust_layouts.len()
    );
    env.finish();
}
