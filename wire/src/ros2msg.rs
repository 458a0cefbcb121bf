//! ROS 2 message definitions (`.msg`, the `ros2msg` schema encoding of MCAP) of every sample
//! type, generated from its [`Reflect`] field table: package `navsync_msgs`, one message per
//! type (`navsync_msgs/msg/ImuSample`), each field's units and frame as a comment, the layout
//! version in the header comment. What [`cdr`](crate::cdr) encodes follows these definitions.
//!
//! Type mapping: `i64` → `int64` … `f64` → `float64`, `[u8; N]` strings → `string` (at most N
//! bytes), `[T; N]` → `T[N]`, `[[f64; 3]; N]` → `float64[3N]` (row after row: ROS has no
//! nested arrays), nested structs → `navsync_msgs/Name`. `reserved` fields are left out.
//!
//! [`definition`] is the full text as rosbag2 stores it in a schema: the message, then each
//! message it uses after a line of 80 `=` and `MSG: navsync_msgs/Name` (the format of
//! `rosbag2_cpp`'s `LocalMessageDefinitionSource` that Foxglove, rosbags and `ros2 bag` read).

use crate::reflect::{Field, FieldType, Reflect};

/// The ROS 2 package of navsync's messages.
pub const PACKAGE: &str = "navsync_msgs";

/// The separator between a message and each message it uses, in a schema.
pub const SEPARATOR: &str = "================================================================================";

/// The message name of a navsync type name: `navsync.ImuSample.v1` → `ImuSample`.
pub fn short_name(type_name: &str) -> &str {
    let rest = type_name.split_once('.').map_or(type_name, |(_, r)| r);
    rest.rsplit_once('.').map_or(rest, |(n, _)| n)
}

/// The ROS 2 type name of a navsync type name: `navsync.ImuSample.v1` →
/// `navsync_msgs/msg/ImuSample`.
pub fn ros_type_name(type_name: &str) -> String {
    format!("{PACKAGE}/msg/{}", short_name(type_name))
}

fn primitive(ty: &FieldType) -> Option<&'static str> {
    Some(match ty {
        FieldType::I64 => "int64",
        FieldType::U64 => "uint64",
        FieldType::I32 => "int32",
        FieldType::U32 => "uint32",
        FieldType::I16 => "int16",
        FieldType::U16 => "uint16",
        FieldType::U8 => "uint8",
        FieldType::F64 => "float64",
        FieldType::F32 => "float32",
        FieldType::Str(_) => "string",
        FieldType::Array(..) | FieldType::Struct(..) => return None,
    })
}

/// The `.msg` type of a field, e.g. `float64[3]`, `navsync_msgs/Stamp`.
fn msg_type(ty: &FieldType) -> String {
    match ty {
        FieldType::Array(inner, n) => {
            // Flatten nested arrays: ROS 2 has none.
            let (mut t, mut count) = (*inner, *n);
            while let FieldType::Array(i, m) = t {
                t = i;
                count *= m;
            }
            format!("{}[{count}]", msg_type(t))
        }
        FieldType::Struct(name, _) => format!("{PACKAGE}/{}", short_name(name)),
        t => primitive(t).unwrap_or("?").to_string(),
    }
}

fn message_text(doc: &str, type_name: &str, fields: &[Field]) -> String {
    let mut s = String::new();
    for line in doc.lines() {
        s.push_str(format!("# {}", line.trim()).trim_end());
        s.push('\n');
    }
    s.push_str(&format!(
        "# Layout {type_name}: the fields of navsync's #[repr(C)] type, in order.\n"
    ));
    for f in fields.iter().filter(|f| f.name != "reserved") {
        s.push('\n');
        for line in f.doc.lines() {
            s.push_str(format!("# {}", line.trim()).trim_end());
            s.push('\n');
        }
        s.push_str(&format!("{} {}\n", msg_type(&f.ty), f.name));
    }
    s
}

fn nested(fields: &[Field], out: &mut Vec<(&'static str, &'static [Field])>) {
    for f in fields {
        let mut t = &f.ty;
        while let FieldType::Array(inner, _) = t {
            t = inner;
        }
        if let FieldType::Struct(name, inner) = t
            && !out.iter().any(|(n, _)| n == name)
        {
            out.push((name, inner));
            nested(inner, out);
        }
    }
}

/// The full `ros2msg` schema text of `T`: its message, then every message it uses.
pub fn definition<T: Reflect>() -> String {
    let mut s = message_text(T::DOC, T::TYPE_NAME, T::FIELDS);
    let mut deps = Vec::new();
    nested(T::FIELDS, &mut deps);
    for (name, fields) in deps {
        s.push_str(SEPARATOR);
        s.push('\n');
        s.push_str(&format!("MSG: {PACKAGE}/{}\n", short_name(name)));
        s.push_str(&message_text("", name, fields));
    }
    s
}

/// One message of a schema text: its name (`""` for the first) and its fields as
/// (type, name), comments and constants left out.
pub type MessageFields = (String, Vec<(String, String)>);

/// The messages and fields of a `ros2msg` schema text (written by navsync or by another
/// tool: comments, blank lines and constants are ignored; `pkg/msg/Name` and `pkg/Name` are
/// the same type).
pub fn parse(text: &str) -> Vec<MessageFields> {
    let mut out: Vec<MessageFields> = vec![(String::new(), Vec::new())];
    for raw in text.lines() {
        let line = raw.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        if line.starts_with("====") {
            continue;
        }
        if let Some(name) = line.strip_prefix("MSG:") {
            out.push((name.trim().replace("/msg/", "/"), Vec::new()));
            continue;
        }
        let mut parts = line.split_whitespace();
        let (Some(ty), Some(name)) = (parts.next(), parts.next()) else {
            continue;
        };
        if name.contains('=') || parts.next().is_some_and(|p| p.starts_with('=')) {
            continue; // a constant (or a default value, which navsync does not use)
        }
        let ty = ty.replace("/msg/", "/");
        if let Some(last) = out.last_mut() {
            last.1.push((ty, name.to_string()));
        }
    }
    out
}

/// Checks that a schema text from a file describes the same messages as navsync's definition
/// of `T` (field names and types, nested messages included); the error says what differs.
pub fn check_compatible<T: Reflect>(text: &str) -> Result<(), String> {
    let ours = parse(&definition::<T>());
    let theirs = parse(text);
    let Some((_, top)) = theirs.first() else {
        return Err("an empty definition".into());
    };
    if *top != ours[0].1 {
        return Err(format!(
            "its fields differ from {}: {}",
            ros_type_name(T::TYPE_NAME),
            first_difference(top, &ours[0].1)
        ));
    }
    for (name, fields) in ours.iter().skip(1) {
        if let Some((_, f)) = theirs.iter().find(|(n, _)| n == name)
            && f != fields
        {
            return Err(format!("{name} differs: {}", first_difference(f, fields)));
        }
    }
    Ok(())
}

fn first_difference(theirs: &[(String, String)], ours: &[(String, String)]) -> String {
    for (i, o) in ours.iter().enumerate() {
        match theirs.get(i) {
            Some(t) if t == o => {}
            Some(t) => return format!("field {} is `{} {}`, expected `{} {}`", i + 1, t.0, t.1, o.0, o.1),
            None => return format!("field `{} {}` is missing", o.0, o.1),
        }
    }
    format!("{} extra fields", theirs.len().saturating_sub(ours.len()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::samples::{Health, ImuSample, NavState};

    #[test]
    fn definitions_name_every_field_with_its_units_and_dependencies() {
        let d = definition::<ImuSample>();
        assert!(d.contains("\nfloat64[3] gyro_rps\n"), "{d}");
        assert!(d.contains("rad/s"), "{d}");
        assert!(d.contains("\nnavsync_msgs/Stamp stamp\n"), "{d}");
        assert!(d.contains(&format!("{SEPARATOR}\nMSG: navsync_msgs/Stamp\n")), "{d}");
        assert!(!d.contains(" reserved\n"), "{d}");
        let h = definition::<Health>();
        assert!(
            h.contains("navsync_msgs/Counter[") && h.contains("MSG: navsync_msgs/RateEntry"),
            "{h}"
        );
        assert_eq!(ros_type_name(NavState::TYPE_NAME), "navsync_msgs/msg/NavState");
    }

    #[test]
    fn compatibility_ignores_comments_and_sees_changed_fields() {
        let d = definition::<ImuSample>();
        let stripped: String = d
            .lines()
            .filter(|l| !l.starts_with('#'))
            .map(|l| format!("{}\n", l.replace("navsync_msgs/Stamp", "navsync_msgs/msg/Stamp")))
            .collect();
        assert_eq!(check_compatible::<ImuSample>(&stripped), Ok(()));
        let changed = d.replace("float64[3] gyro_rps", "float32[3] gyro_rps");
        assert!(
            check_compatible::<ImuSample>(&changed)
                .unwrap_err()
                .contains("gyro_rps")
        );
        let nested = d.replace("uint64 seq", "uint32 seq");
        assert!(check_compatible::<ImuSample>(&nested).unwrap_err().contains("Stamp"));
    }
}
