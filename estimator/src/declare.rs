//! One declaration per setting. A settings group is declared once, where its settings act,
//! with [`settings_group!`]: each field with its doc comment, type, default, the section of
//! the configuration file it is read from, its command-line flag and its validity check. The
//! struct, its `Default`, the table of [`Spec`]s (from which the binary builds the flags, reads
//! the file and writes the configuration reference), setting a value from a flag's text or a
//! file's value, and the check all come from that one declaration. [`crate::settings::Settings`]
//! composes the groups.
//!
//! The check runs on the merged value, whatever its source (default, file or flag), so a bad
//! flag fails as clearly as a bad file.

/// One declared setting.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Spec {
    /// The setting's name: its field, and its key in the configuration file.
    pub name: &'static str,
    /// Its doc comment (units, frame, what it does).
    pub doc: &'static str,
    /// The configuration file's section it is read from (`estimator`, `timing`); `None`: not
    /// in the file (set by code, or from devices' sections).
    pub section: Option<&'static str>,
    /// Its command-line flag without the dashes; `None`: no flag.
    pub flag: Option<&'static str>,
    /// For a switch (a flag without a value): the value the switch sets.
    pub switch: Option<bool>,
}

/// A setting whose value fails its check.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{name}: {message}")]
pub struct Invalid {
    /// The setting.
    pub name: &'static str,
    /// The element of a list or vector that fails, when it is one.
    pub index: Option<usize>,
    /// What is wrong and what was expected.
    pub message: String,
}

/// What a check found wrong: the message, and the element of a list or vector it is about.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Problem {
    /// The failing element, when the value is a list or vector.
    pub index: Option<usize>,
    /// What is wrong and what was expected.
    pub message: String,
}

impl From<String> for Problem {
    fn from(message: String) -> Self {
        Self { index: None, message }
    }
}

/// A value a setting can hold: its text form on the command line and in messages.
pub trait SettingValue: Sized {
    /// Parses the command line's text.
    fn parse_text(text: &str) -> Result<Self, String>;
    /// The value as the command line writes it (for defaults in help and reference).
    fn show(&self) -> String;
}

impl SettingValue for f64 {
    fn parse_text(text: &str) -> Result<Self, String> {
        text.trim().parse().map_err(|_| format!("`{text}` is not a number"))
    }
    fn show(&self) -> String {
        format!("{self}")
    }
}

impl SettingValue for bool {
    fn parse_text(text: &str) -> Result<Self, String> {
        match text.trim() {
            "true" | "on" | "yes" => Ok(true),
            "false" | "off" | "no" => Ok(false),
            _ => Err(format!("`{text}`: expected true or false")),
        }
    }
    fn show(&self) -> String {
        format!("{self}")
    }
}

macro_rules! integer_setting {
    ($($t:ty),*) => {$(
        impl SettingValue for $t {
            fn parse_text(text: &str) -> Result<Self, String> {
                text.trim()
                    .parse()
                    .map_err(|_| format!("`{text}` is not a whole number"))
            }
            fn show(&self) -> String {
                format!("{self}")
            }
        }
    )*};
}
integer_setting!(u32, u64, i64, usize);

impl SettingValue for [f64; 3] {
    fn parse_text(text: &str) -> Result<Self, String> {
        let v: Vec<f64> = text
            .split(',')
            .map(|x| x.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|_| format!("`{text}`: expected three numbers x,y,z"))?;
        <[f64; 3]>::try_from(v.as_slice()).map_err(|_| format!("`{text}`: expected three numbers x,y,z"))
    }
    fn show(&self) -> String {
        format!("{},{},{}", self[0], self[1], self[2])
    }
}

/// A list of device ids, comma-separated on the command line.
impl SettingValue for Vec<String> {
    fn parse_text(text: &str) -> Result<Self, String> {
        Ok(text.split(',').map(|s| s.trim().to_string()).collect())
    }
    fn show(&self) -> String {
        self.join(",")
    }
}

/// A text (a path, a name), as given.
impl SettingValue for String {
    fn parse_text(text: &str) -> Result<Self, String> {
        Ok(text.to_string())
    }
    fn show(&self) -> String {
        self.clone()
    }
}

/// An optional value: `none` when absent.
impl<T: SettingValue> SettingValue for Option<T> {
    fn parse_text(text: &str) -> Result<Self, String> {
        T::parse_text(text).map(Some)
    }
    fn show(&self) -> String {
        self.as_ref().map_or_else(|| "none".into(), T::show)
    }
}

/// A settings group declared with [`settings_group!`].
pub trait Group {
    /// Every setting of the group, in declaration order.
    const SPECS: &'static [Spec];
    /// Sets setting `name` from a flag's text; `None` when the group has no such flag.
    fn set_text(&mut self, name: &str, text: &str) -> Option<Result<(), String>>;
    /// Sets setting `name` of file section `section` from the file's value; `None` when the
    /// group has no such setting in that section.
    fn set_value<'de, D: serde::Deserializer<'de>>(
        &mut self,
        section: &str,
        name: &str,
        value: D,
    ) -> Option<Result<(), D::Error>>;
    /// The first setting whose value fails its check.
    fn check(&self) -> Result<(), Invalid>;
    /// Every setting read from the file, as (section, name, value): what [`Self::set_value`]
    /// reads back.
    fn file_values(&self) -> Vec<(&'static str, &'static str, serde_json::Value)>;
    /// Setting `name`'s value as text; `None` when the group has no such setting in the file
    /// or on the command line.
    fn show(&self, name: &str) -> Option<String>;
}

/// `None` or `Some(x)`: the optional parts of a declaration.
#[doc(hidden)]
#[macro_export]
macro_rules! __setting_opt {
    () => {
        None
    };
    ($x:expr) => {
        Some($x)
    };
}

/// Declares a settings group: the struct, its `Default`, and its [`Group`] table.
///
/// ```text
/// settings_group! {
///     /// What the group is.
///     #[derive(Debug, Clone, Copy, PartialEq)]
///     pub struct NavSettings {
///         /// Scale of the 99.9 % chi-square innovation gate.
///         pub gate_scale: f64 = 1.0, file "estimator", flag "gate-scale", check positive;
///         /// Do not estimate Δ.
///         pub estimate_delay: bool = true, file "estimator", switch "no-delay-state" => false;
///     }
/// }
/// ```
#[macro_export]
macro_rules! settings_group {
    (
        $(#[doc = $sdoc:literal])*
        #[derive($($derive:ident),*)]
        pub struct $name:ident {
            $(
                $(#[doc = $doc:literal])+
                pub $field:ident : $ty:ty = $default:expr
                $(, file $section:literal)?
                $(, flag $flag:literal)?
                $(, switch $switch:literal => $on:literal)?
                $(, check $check:expr)?
                ;
            )*
        }
    ) => {
        $(#[doc = $sdoc])*
        #[derive($($derive),*)]
        pub struct $name {
            $( $(#[doc = $doc])+ pub $field: $ty, )*
        }

        impl Default for $name {
            fn default() -> Self {
                Self { $( $field: $default, )* }
            }
        }

        impl $crate::declare::Group for $name {
            const SPECS: &'static [$crate::declare::Spec] = &[$(
                $crate::declare::Spec {
                    name: stringify!($field),
                    doc: concat!($($doc, "\n"),+),
                    section: $crate::__setting_opt!($($section)?),
                    flag: $crate::__setting_opt!($($flag)? $($switch)?),
                    switch: $crate::__setting_opt!($($on)?),
                },
            )*];

            #[allow(unused_variables)]
            fn set_text(&mut self, name: &str, text: &str) -> Option<Result<(), String>> {
                $($(
                    if name == stringify!($field) {
                        let _ = $flag;
                        return Some(
                            <$ty as $crate::declare::SettingValue>::parse_text(text).map(|v| self.$field = v),
                        );
                    }
                )?)*
                $($(
                    if name == stringify!($field) {
                        let _ = $switch;
                        return Some(
                            <$ty as $crate::declare::SettingValue>::parse_text(text).map(|v| self.$field = v),
                        );
                    }
                )?)*
                None
            }

            #[allow(unused_variables)]
            fn set_value<'de, D: serde::Deserializer<'de>>(
                &mut self,
                section: &str,
                name: &str,
                value: D,
            ) -> Option<Result<(), D::Error>> {
                $($(
                    if section == $section && name == stringify!($field) {
                        return Some(<$ty as serde::Deserialize>::deserialize(value).map(|v| self.$field = v));
                    }
                )?)*
                None
            }

            #[allow(clippy::vec_init_then_push)]
            fn file_values(&self) -> Vec<(&'static str, &'static str, serde_json::Value)> {
                #[allow(unused_mut)]
                let mut out = Vec::new();
                $($(
                    out.push((
                        $section,
                        stringify!($field),
                        serde_json::to_value(&self.$field).unwrap_or(serde_json::Value::Null),
                    ));
                )?)*
                out
            }

            fn check(&self) -> Result<(), $crate::declare::Invalid> {
                $($(
                    ($check)(&self.$field).map_err(|e| {
                        let p = $crate::declare::Problem::from(e);
                        $crate::declare::Invalid {
                            name: stringify!($field),
                            index: p.index,
                            message: p.message,
                        }
                    })?;
                )?)*
                Ok(())
            }

            #[allow(unused_variables)]
            fn show(&self, name: &str) -> Option<String> {
                $($(
                    if name == stringify!($field) {
                        let _ = $section;
                        return Some($crate::declare::SettingValue::show(&self.$field));
                    }
                )?)*
                $($(
                    if name == stringify!($field) {
                        let _ = $flag;
                        return Some($crate::declare::SettingValue::show(&self.$field));
                    }
                )?)*
                $($(
                    if name == stringify!($field) {
                        let _ = $switch;
                        return Some($crate::declare::SettingValue::show(&self.$field));
                    }
                )?)*
                None
            }
        }
    };
}

/// Checks: each a function of the value returning what was expected when it fails.
pub mod checks {
    /// A finite number > 0.
    pub fn positive(v: &f64) -> Result<(), String> {
        if v.is_finite() && *v > 0.0 {
            Ok(())
        } else {
            Err(format!("{v}: expected a finite number > 0"))
        }
    }

    /// A finite number ≥ 0.
    pub fn non_negative(v: &f64) -> Result<(), String> {
        if v.is_finite() && *v >= 0.0 {
            Ok(())
        } else {
            Err(format!("{v}: expected a finite number ≥ 0"))
        }
    }

    /// A finite number in `lo..=hi`.
    pub fn within(lo: f64, hi: f64) -> impl Fn(&f64) -> Result<(), String> {
        move |v| {
            if v.is_finite() && (lo..=hi).contains(v) {
                Ok(())
            } else {
                Err(format!("{v}: expected {lo} to {hi}"))
            }
        }
    }

    /// A whole number in `lo..=hi`.
    pub fn count_within<T: Copy + PartialOrd + std::fmt::Display>(lo: T, hi: T) -> impl Fn(&T) -> Result<(), String> {
        move |v| {
            if (lo..=hi).contains(v) {
                Ok(())
            } else {
                Err(format!("{v}: expected {lo} to {hi}"))
            }
        }
    }

    /// Three finite numbers.
    pub fn finite3(v: &[f64; 3]) -> Result<(), super::Problem> {
        match v.iter().position(|x| !x.is_finite()) {
            Some(i) => Err(super::Problem {
                index: Some(i),
                message: format!("{}: expected a finite number", v[i]),
            }),
            None => Ok(()),
        }
    }

    /// A device id as used in service names: 1 to 16 letters, digits, `-` and `_`.
    pub fn valid_id(s: &str) -> bool {
        !s.is_empty() && s.len() <= 16 && s.chars().all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
    }

    /// Device ids: between `min` and `max` of them, each a [`valid_id`].
    pub fn ids(min: usize, max: usize) -> impl Fn(&Vec<String>) -> Result<(), super::Problem> {
        move |v| {
            if let Some(i) = v.iter().position(|s| !valid_id(s)) {
                return Err(super::Problem {
                    index: Some(i),
                    message: format!("`{}` is not an id: expected 1 to 16 letters, digits, `-` or `_`", v[i]),
                });
            }
            if v.len() < min || v.len() > max {
                return Err(format!("{} ids: expected {min} to {max}", v.len()).into());
            }
            Ok(())
        }
    }

    /// No check (for settings whose type says everything, or that check themselves).
    pub fn any<T>(_: &T) -> Result<(), String> {
        Ok(())
    }
}

/// [`SettingValue`] for an enum with `FromStr`, written in lower case (its `Debug` name).
#[macro_export]
macro_rules! enum_setting {
    ($($t:ty),*) => {$(
        impl $crate::declare::SettingValue for $t {
            fn parse_text(text: &str) -> Result<Self, String> {
                text.trim().parse()
            }
            fn show(&self) -> String {
                format!("{self:?}").to_ascii_lowercase()
            }
        }
    )*};
}
enum_setting!(navsync_wire::imu_spec::ImuPreset);

/// The IMU's noise model has no text form: it is given in the file (or field by field with
/// its own flags).
impl SettingValue for navsync_wire::imu_spec::ImuNoise {
    fn parse_text(text: &str) -> Result<Self, String> {
        Err(format!(
            "`{text}`: an IMU noise model is given in the configuration file"
        ))
    }
    fn show(&self) -> String {
        format!("{self:?}")
    }
}
