//! JSON codec for every sample type, driven by its [`Reflect`] field table.
//!
//! Encoding rules (also in the JSON schemas written into recordings):
//! integers as JSON integers (exact for all `i64`/`u64`), floats in the shortest text that
//! parses back to the same bits, NaN as `null`, `[u8; N]` strings as JSON strings, arrays as
//! arrays and nested structs as objects. Decoding is the exact inverse, so a sample survives
//! a JSON round trip bit for bit (up to the payload of NaNs and padding bytes).

use serde_json::{Map, Number, Value};

use crate::reflect::{Field, FieldType, Reflect, str_of};

/// A JSON document that does not describe a sample of the expected type.
#[derive(Debug, thiserror::Error)]
#[error("field `{field}`: {problem}")]
pub struct JsonError {
    /// Dotted path of the field.
    pub field: String,
    /// What was wrong.
    pub problem: String,
}

/// Encodes a sample as a JSON object.
pub fn to_json<T: Reflect>(value: &T) -> Value {
    // SAFETY: the field table was generated from T's own declaration (offset_of!), so every
    // read below is of the declared type at an in-bounds offset.
    unsafe { encode_struct(T::FIELDS, (value as *const T).cast::<u8>()) }
}

unsafe fn encode_struct(fields: &[Field], base: *const u8) -> Value {
    let mut m = Map::new();
    for f in fields {
        if f.name == "reserved" {
            continue;
        }
        m.insert(f.name.to_string(), unsafe { encode_value(&f.ty, base.add(f.offset)) });
    }
    Value::Object(m)
}

fn float(v: f64) -> Value {
    Number::from_f64(v).map_or(Value::Null, Value::Number)
}

unsafe fn encode_value(ty: &FieldType, p: *const u8) -> Value {
    unsafe {
        match ty {
            FieldType::I64 => Value::from(p.cast::<i64>().read_unaligned()),
            FieldType::U64 => Value::from(p.cast::<u64>().read_unaligned()),
            FieldType::I32 => Value::from(p.cast::<i32>().read_unaligned()),
            FieldType::U32 => Value::from(p.cast::<u32>().read_unaligned()),
            FieldType::I16 => Value::from(p.cast::<i16>().read_unaligned()),
            FieldType::U16 => Value::from(p.cast::<u16>().read_unaligned()),
            FieldType::U8 => Value::from(p.read()),
            FieldType::F64 => float(p.cast::<f64>().read_unaligned()),
            FieldType::F32 => float(p.cast::<f32>().read_unaligned() as f64),
            FieldType::Str(n) => Value::from(str_of(core::slice::from_raw_parts(p, *n))),
            FieldType::Array(t, n) => {
                let sz = t.size();
                Value::Array((0..*n).map(|i| encode_value(t, p.add(i * sz))).collect())
            }
            FieldType::Struct(_, fields) => encode_struct(fields, p),
        }
    }
}

/// Decodes a sample from a JSON object written by [`to_json`]. Missing `reserved` fields are
/// zero; any other missing or mistyped field is an error.
pub fn from_json<T: Reflect>(v: &Value) -> Result<T, JsonError> {
    let mut out = T::zeroed();
    // SAFETY: as in `to_json`; writes are of the declared type at in-bounds offsets of `out`.
    unsafe { decode_struct(T::FIELDS, (&mut out as *mut T).cast::<u8>(), v, "", false)? };
    Ok(out)
}

/// Decodes a sample of an older layout of `T` (a subset of its fields) onto `base`: fields the
/// JSON has are decoded as [`from_json`] does, fields it lacks (added since) keep `base`'s
/// values (the type's "not known" values).
pub fn from_json_onto<T: Reflect>(v: &Value, base: T) -> Result<T, JsonError> {
    let mut out = base;
    // SAFETY: as in `from_json`.
    unsafe { decode_struct(T::FIELDS, (&mut out as *mut T).cast::<u8>(), v, "", true)? };
    Ok(out)
}

fn bad(path: &str, problem: impl Into<String>) -> JsonError {
    JsonError {
        field: path.to_string(),
        problem: problem.into(),
    }
}

unsafe fn decode_struct(
    fields: &[Field],
    base: *mut u8,
    v: &Value,
    path: &str,
    lenient: bool,
) -> Result<(), JsonError> {
    let obj = v.as_object().ok_or_else(|| bad(path, "expected an object"))?;
    for f in fields {
        if f.name == "reserved" {
            continue;
        }
        let p = if path.is_empty() {
            f.name.to_string()
        } else {
            format!("{path}.{}", f.name)
        };
        let Some(fv) = obj.get(f.name) else {
            if lenient {
                continue;
            }
            return Err(bad(&p, "missing"));
        };
        unsafe { decode_value(&f.ty, base.add(f.offset), fv, &p, lenient)? };
    }
    Ok(())
}

fn int<T: TryFrom<i128>>(v: &Value, path: &str) -> Result<T, JsonError> {
    let n = v
        .as_i64()
        .map(i128::from)
        .or_else(|| v.as_u64().map(i128::from))
        .ok_or_else(|| bad(path, "expected an integer"))?;
    T::try_from(n).map_err(|_| bad(path, "integer out of range"))
}

fn flt(v: &Value, path: &str) -> Result<f64, JsonError> {
    match v {
        Value::Null => Ok(f64::NAN),
        _ => v.as_f64().ok_or_else(|| bad(path, "expected a number or null")),
    }
}

unsafe fn decode_value(ty: &FieldType, p: *mut u8, v: &Value, path: &str, lenient: bool) -> Result<(), JsonError> {
    unsafe {
        match ty {
            FieldType::I64 => p.cast::<i64>().write_unaligned(int(v, path)?),
            FieldType::U64 => p.cast::<u64>().write_unaligned(int(v, path)?),
            FieldType::I32 => p.cast::<i32>().write_unaligned(int(v, path)?),
            FieldType::U32 => p.cast::<u32>().write_unaligned(int(v, path)?),
            FieldType::I16 => p.cast::<i16>().write_unaligned(int(v, path)?),
            FieldType::U16 => p.cast::<u16>().write_unaligned(int(v, path)?),
            FieldType::U8 => p.write(int(v, path)?),
            FieldType::F64 => p.cast::<f64>().write_unaligned(flt(v, path)?),
            FieldType::F32 => p.cast::<f32>().write_unaligned(flt(v, path)? as f32),
            FieldType::Str(n) => {
                let s = v.as_str().ok_or_else(|| bad(path, "expected a string"))?;
                if s.len() > *n {
                    return Err(bad(path, format!("longer than {n} bytes")));
                }
                core::ptr::write_bytes(p, 0, *n);
                core::ptr::copy_nonoverlapping(s.as_ptr(), p, s.len());
            }
            FieldType::Array(t, n) => {
                let a = v.as_array().ok_or_else(|| bad(path, "expected an array"))?;
                if a.len() != *n {
                    return Err(bad(path, format!("expected {n} elements, got {}", a.len())));
                }
                for (i, e) in a.iter().enumerate() {
                    decode_value(t, p.add(i * t.size()), e, &format!("{path}[{i}]"), lenient)?;
                }
            }
            FieldType::Struct(_, fields) => decode_struct(fields, p, v, path, lenient)?,
        }
    }
    Ok(())
}

/// JSON Schema (draft 2020-12) of a sample type's JSON encoding, with each field's doc
/// comment as its description.
pub fn schema<T: Reflect>() -> Value {
    let mut s = struct_schema(T::FIELDS);
    if let Value::Object(m) = &mut s {
        m.insert(
            "$schema".into(),
            Value::from("https://json-schema.org/draft/2020-12/schema"),
        );
        m.insert("title".into(), Value::from(T::TYPE_NAME));
    }
    s
}

fn struct_schema(fields: &[Field]) -> Value {
    let mut props = Map::new();
    let mut required = Vec::new();
    for f in fields.iter().filter(|f| f.name != "reserved") {
        let mut p = type_schema(&f.ty);
        if let Value::Object(m) = &mut p {
            m.insert("description".into(), Value::from(f.doc.trim()));
        }
        props.insert(f.name.to_string(), p);
        required.push(Value::from(f.name));
    }
    serde_json::json!({ "type": "object", "properties": props, "required": required })
}

fn type_schema(ty: &FieldType) -> Value {
    match ty {
        FieldType::I64
        | FieldType::U64
        | FieldType::I32
        | FieldType::U32
        | FieldType::I16
        | FieldType::U16
        | FieldType::U8 => serde_json::json!({ "type": "integer" }),
        FieldType::F64 | FieldType::F32 => serde_json::json!({ "type": ["number", "null"] }),
        FieldType::Str(n) => serde_json::json!({ "type": "string", "maxLength": n }),
        FieldType::Array(t, n) => {
            serde_json::json!({ "type": "array", "items": type_schema(t), "minItems": n, "maxItems": n })
        }
        FieldType::Struct(_, fields) => struct_schema(fields),
    }
}
