//! Typed path parameters.
//!
//! Some routes name a file in their last segment (`{at}.png`, `{at}.json`,
//! `{bx}_{by}_{bz}.raw`). The router matches whole segments only, so the
//! segment is captured whole and deserialized into a [`Stem`], which
//! checks the extension and keeps the rest; [`TypedPath`] answers a
//! segment without it as an unknown route, as the router would.

use crate::error::ApiError;
use axum::extract::path::ErrorKind;
use axum::extract::rejection::PathRejection;
use axum::extract::{FromRequestParts, Path};
use axum::http::StatusCode;
use axum::http::request::Parts;
use axum::response::{IntoResponse, Response};
use serde::de::{DeserializeOwned, Error as _};
use serde::{Deserialize, Deserializer};
use std::marker::PhantomData;

/// The extension a path segment must end with.
pub(super) trait Extension {
    /// The extension, dot included.
    const SUFFIX: &'static str;
    /// What the client is told when a segment lacks it.
    const EXPECTED: &'static str;
}

/// Slices: `{at}.png`.
pub(super) struct Png;

impl Extension for Png {
    const SUFFIX: &'static str = ".png";
    const EXPECTED: &'static str = "slices are served as `{at}.png`";
}

/// Bricks: `{bx}_{by}_{bz}.raw`.
pub(super) struct Raw;

impl Extension for Raw {
    const SUFFIX: &'static str = ".raw";
    const EXPECTED: &'static str = "bricks are served as `{bx}_{by}_{bz}.raw`";
}

/// Frames of a field: `{at}.json`.
pub(super) struct Json;

impl Extension for Json {
    const SUFFIX: &'static str = ".json";
    const EXPECTED: &'static str = "frames are served as `{at}.json`";
}

/// Every [`Extension::EXPECTED`]: the deserialization errors that mean
/// "no such route" rather than a malformed path.
const MISSING_EXTENSION: [&str; 3] = [Png::EXPECTED, Raw::EXPECTED, Json::EXPECTED];

/// A path segment `<stem><E::SUFFIX>`, holding the stem.
pub(super) struct Stem<E> {
    stem: String,
    extension: PhantomData<E>,
}

impl<E> Stem<E> {
    /// The segment without its extension.
    pub(super) fn as_str(&self) -> &str {
        &self.stem
    }
}

impl<'de, E: Extension> Deserialize<'de> for Stem<E> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let segment = String::deserialize(d)?;
        match segment.strip_suffix(E::SUFFIX) {
            Some(stem) => Ok(Stem {
                stem: stem.to_string(),
                extension: PhantomData,
            }),
            None => Err(D::Error::custom(E::EXPECTED)),
        }
    }
}

/// `axum::extract::Path`, answering a segment that lacks its [`Stem`]'s
/// extension with 404 `no_route`; other rejections are axum's own.
pub(super) struct TypedPath<T>(pub T);

impl<S: Send + Sync, T: DeserializeOwned + Send> FromRequestParts<S> for TypedPath<T> {
    type Rejection = Response;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, Response> {
        match Path::<T>::from_request_parts(parts, state).await {
            Ok(Path(t)) => Ok(TypedPath(t)),
            Err(PathRejection::FailedToDeserializePathParams(e)) => {
                let missing = match e.kind() {
                    ErrorKind::Message(m) | ErrorKind::DeserializeError { message: m, .. } => {
                        MISSING_EXTENSION.iter().find(|x| **x == m.as_str())
                    }
                    _ => None,
                };
                Err(match missing {
                    Some(expected) => {
                        ApiError::new(StatusCode::NOT_FOUND, "no_route", *expected).into_response()
                    }
                    None => PathRejection::FailedToDeserializePathParams(e).into_response(),
                })
            }
            Err(e) => Err(e.into_response()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde::de::IntoDeserializer;
    use serde::de::value::{Error as ValueError, StrDeserializer};

    fn stem<E: Extension>(s: &str) -> Result<String, ValueError> {
        let d: StrDeserializer<'_, ValueError> = s.into_deserializer();
        Stem::<E>::deserialize(d).map(|s| s.as_str().to_string())
    }

    #[test]
    fn stems_keep_all_but_the_extension() {
        assert_eq!(stem::<Png>("12.png").unwrap(), "12");
        assert_eq!(stem::<Png>("12.png.png").unwrap(), "12.png");
        assert_eq!(stem::<Png>(".png").unwrap(), "");
        assert_eq!(stem::<Raw>("0_1_2.raw").unwrap(), "0_1_2");
        assert_eq!(stem::<Json>("-7.json").unwrap(), "-7");
        assert_eq!(
            stem::<Json>("7.png").unwrap_err().to_string(),
            Json::EXPECTED
        );
        assert_eq!(
            stem::<Png>("12.jpg").unwrap_err().to_string(),
            Png::EXPECTED
        );
        assert_eq!(
            stem::<Raw>("0_1_2.png").unwrap_err().to_string(),
            Raw::EXPECTED
        );
    }
}
