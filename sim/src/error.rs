//! The simulator's error type: every error names where it came from (file, line, field).

/// Why a scenario could not be loaded or a world not built.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The scenario file could not be read.
    #[error("{origin}: cannot read scenario: {source}")]
    Io {
        /// The file's path as given.
        origin: String,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// The text is not valid TOML, or a field has the wrong type, is unknown or missing.
    #[error("{origin}:{line}:{column}: {field}: {message}")]
    Parse {
        /// The file (or other origin) of the text.
        origin: String,
        /// 1-based line of the offending text.
        line: usize,
        /// 1-based column of the offending text.
        column: usize,
        /// Dotted path of the field, e.g. `trajectory.segment[3].duration_s` (`(document)`
        /// when the error is not inside a key/value pair).
        field: String,
        /// What was found and what was expected.
        message: String,
    },
    /// A field has a well-typed but physically or logically invalid value.
    #[error("{origin}{}: {field}: {message}", line_suffix(*.line))]
    Invalid {
        /// The file (or other origin) of the configuration; `overrides` when the value came
        /// from a setter after loading.
        origin: String,
        /// 1-based line of the field (or of its table) when known.
        line: Option<usize>,
        /// Dotted path of the field.
        field: String,
        /// What is wrong and what is expected.
        message: String,
    },
}

fn line_suffix(line: Option<usize>) -> String {
    line.map_or_else(String::new, |l| format!(":{l}"))
}
