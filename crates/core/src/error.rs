//! The one error type of the engine. Every variant carries what a user needs
//! to act on it; the HTTP layer maps variants to status codes.

use std::fmt;

/// Errors from loading exemplars, precomputing candidates, reading `.stx`
/// files and synthesizing voxels.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An image could not be decoded (not a PNG, truncated, unsupported).
    #[error("malformed image: {0}")]
    MalformedImage(String),
    /// An image's declared size is outside what solidtex accepts.
    #[error("image is {width}x{height}; each side must be between {min} and {max} pixels")]
    ImageSize {
        /// Width of the offending image.
        width: u32,
        /// Height of the offending image.
        height: u32,
        /// Smallest accepted side.
        min: u32,
        /// Largest accepted side.
        max: u32,
    },
    /// The three plane exemplars differ in size.
    #[error("exemplar sizes differ: {0}")]
    SizeMismatch(String),
    /// A numeric parameter is outside its documented range.
    #[error("parameter `{name}` = {value} is outside {min}..={max}")]
    InvalidRange {
        /// Parameter name as the user spells it.
        name: &'static str,
        /// The value given.
        value: f64,
        /// Smallest accepted value.
        min: f64,
        /// Largest accepted value.
        max: f64,
    },
    /// A named parameter is malformed (not a range problem: see
    /// [`Error::InvalidRange`]).
    #[error("parameter `{name}`: {reason}")]
    InvalidParameter {
        /// Parameter name as the user spells it.
        name: &'static str,
        /// What is wrong with it.
        reason: String,
    },
    /// A request is larger than the configured limit.
    #[error("request too large: {0}")]
    TooLarge(String),
    /// A request is empty or otherwise malformed.
    #[error("invalid request: {0}")]
    InvalidRequest(String),
    /// A `.stx` file is truncated, corrupt or of another version.
    #[error("corrupt candidate file: {0}")]
    CorruptFile(CorruptKind),
    /// An underlying I/O failure.
    #[error("i/o error: {0}")]
    Io(#[from] std::io::Error),
}

/// Why a candidate file was rejected.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CorruptKind {
    /// The file does not start with the solidtex magic bytes.
    BadMagic,
    /// The file was written by an incompatible format version.
    Version(u32),
    /// The file ends before its declared length.
    Truncated,
    /// The stored checksum does not match the content.
    Checksum,
    /// A field holds an impossible value.
    Invalid(String),
}

impl fmt::Display for CorruptKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CorruptKind::BadMagic => write!(f, "not a solidtex .stx file (bad magic)"),
            CorruptKind::Version(v) => write!(f, "unsupported format version {v}"),
            CorruptKind::Truncated => write!(f, "file is truncated"),
            CorruptKind::Checksum => write!(f, "checksum mismatch"),
            CorruptKind::Invalid(s) => write!(f, "invalid field: {s}"),
        }
    }
}

/// Result alias used throughout the crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;
