//! Errors of world loading: each names the source, the field and the problem.

use std::path::PathBuf;

/// A world that could not be loaded.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum WorldError {
    /// The file could not be read.
    #[error("{source_name}: cannot read: {error}")]
    Io {
        /// File path or world name.
        source_name: String,
        /// The I/O error.
        error: std::io::Error,
    },
    /// The TOML (or YAML) is malformed or has unknown, missing or mistyped keys.
    #[error("{source_name}: {message}")]
    Parse {
        /// File path or world name.
        source_name: String,
        /// The parser's message, with line and column where known.
        message: String,
    },
    /// A value is well-formed but wrong (negative size, non-convex polygon, …).
    #[error("{source_name}: {field}: {problem}")]
    Invalid {
        /// File path or world name.
        source_name: String,
        /// The offending field, e.g. `obstacle[3].size`.
        field: String,
        /// What is wrong, with the value.
        problem: String,
    },
    /// Neither a built-in world name nor an existing file.
    #[error(
        "unknown world '{name}': not a built-in world ({builtins}), a generated one (gen-N) nor an existing .toml or map_server .yaml file"
    )]
    Unknown {
        /// What was asked for.
        name: String,
        /// The built-in names, comma-separated.
        builtins: String,
    },
    /// A map_server image that cannot be used.
    #[error("{path}: {problem}")]
    Image {
        /// Image path.
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },
}

impl WorldError {
    pub(crate) fn invalid(
        source_name: &str,
        field: impl Into<String>,
        problem: impl Into<String>,
    ) -> Self {
        WorldError::Invalid {
            source_name: source_name.to_string(),
            field: field.into(),
            problem: problem.into(),
        }
    }
}
