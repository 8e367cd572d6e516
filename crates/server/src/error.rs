//! Errors as the HTTP client sees them: a status, a stable machine-readable
//! `code` and a message, always sent as `{"error": {"code", "message"}}`.
//!
//! Engine errors and the server's own domain errors ([`SpecError`],
//! [`RegistryError`], [`JobError`], [`DecodeError`]) map onto this by kind, here and nowhere
//! else; anything the HTTP layer itself rejects (routing, parsing) is built
//! here too, and
//! [`json_errors`] rewrites the few plain-text rejections of the framework,
//! so that no error leaves the server in another shape.

use crate::decodes::DecodeError;
use crate::jobs::JobError;
use crate::panics::panic_message;
use crate::registry::RegistryError;
use crate::spec::SpecError;
use axum::body::Body;
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use schemars::JsonSchema;
use serde::Serialize;

/// An error answer.
#[derive(Debug, Clone)]
pub struct ApiError {
    /// HTTP status.
    pub status: StatusCode,
    /// Stable identifier of the error class (`not_found`, `invalid_parameter`…).
    pub code: &'static str,
    /// Human-readable explanation.
    pub message: String,
    /// Seconds after which a retry may succeed (sets `Retry-After`).
    pub retry_after: Option<u32>,
}

impl ApiError {
    /// An error with the given status, code and message.
    pub fn new(status: StatusCode, code: &'static str, message: impl Into<String>) -> Self {
        ApiError {
            status,
            code,
            message: message.into(),
            retry_after: None,
        }
    }

    /// Adds a `Retry-After` header.
    pub fn retry_after(mut self, seconds: u32) -> Self {
        self.retry_after = Some(seconds);
        self
    }

    /// 400: a query or path parameter is not what it should be.
    pub fn invalid_parameter(name: &str, message: impl std::fmt::Display) -> Self {
        Self::new(
            StatusCode::BAD_REQUEST,
            "invalid_parameter",
            format!("parameter `{name}`: {message}"),
        )
    }

    /// 400: a parameter lies outside its documented range.
    pub fn out_of_range(
        name: &str,
        value: impl std::fmt::Display,
        min: impl std::fmt::Display,
        max: impl std::fmt::Display,
    ) -> Self {
        Self::new(
            StatusCode::BAD_REQUEST,
            "out_of_range",
            format!("parameter `{name}` = {value} is outside {min}..={max}"),
        )
    }

    /// 400: the request asks for more than the documented caps.
    pub fn too_large(message: impl Into<String>) -> Self {
        Self::new(StatusCode::BAD_REQUEST, "too_large", message)
    }

    /// 400: the request needed more synthesis than one request may do.
    pub fn over_budget(voxels: u64) -> Self {
        Self::new(
            StatusCode::BAD_REQUEST,
            "over_budget",
            format!(
                "this request needs more than {voxels} voxels synthesized, the server's \
                 budget per request (--max-request-work); ask for a smaller area or a \
                 coarser lod"
            ),
        )
    }

    /// 400: the request is predicted, before any work, to need more
    /// synthesis than one request may do (`predicted` is an upper bound;
    /// `complete` false when counting stopped once past the budget), the
    /// `budget` set by the server's option `flag`; `advice` says what to
    /// ask for instead.
    pub fn predicted_over_budget(
        predicted: u64,
        complete: bool,
        budget: u64,
        flag: &str,
        advice: &str,
    ) -> Self {
        let more = if complete { "" } else { "more than " };
        Self::new(
            StatusCode::BAD_REQUEST,
            "over_budget",
            format!(
                "this request is predicted to synthesize up to {more}{predicted} voxels from a \
                 cold cache, over the server's budget of {budget} voxels per request \
                 ({flag}); {advice}"
            ),
        )
    }

    /// 413: the upload's precompute is expected to need more memory than
    /// the server lets precomputes take.
    pub fn precompute_too_large(estimated: u64, bound: u64) -> Self {
        let mib = |b: u64| b.div_ceil(1 << 20);
        Self::new(
            StatusCode::PAYLOAD_TOO_LARGE,
            "precompute_too_large",
            format!(
                "precomputing this texture is estimated to take {} MiB of memory at its peak, \
                 more than the {} MiB this server allows (--max-precompute-bytes); send a \
                 smaller exemplar, one image for all planes, or fewer levels or triples",
                mib(estimated),
                mib(bound)
            ),
        )
    }

    /// 404: no texture has this id.
    pub fn unknown_texture(id: &str) -> Self {
        Self::new(
            StatusCode::NOT_FOUND,
            "unknown_texture",
            format!("no texture with id `{id}`"),
        )
    }

    /// 507: the server keeps no more textures until some are deleted.
    pub fn storage_full(message: impl Into<String>) -> Self {
        Self::new(StatusCode::INSUFFICIENT_STORAGE, "storage_full", message)
    }

    /// 503: too much work queued; retry later.
    pub fn overloaded(what: &str) -> Self {
        Self::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "overloaded",
            format!("{what}; retry later"),
        )
        .retry_after(1)
    }

    /// 500: something went wrong inside the server.
    pub fn internal(message: impl Into<String>) -> Self {
        Self::new(StatusCode::INTERNAL_SERVER_ERROR, "internal", message)
    }
}

impl std::fmt::Display for ApiError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} {}: {}",
            self.status.as_u16(),
            self.code,
            self.message
        )
    }
}

impl From<solidtex_core::Error> for ApiError {
    fn from(e: solidtex_core::Error) -> Self {
        use solidtex_core::Error as E;
        let message = e.to_string();
        let (status, code) = match &e {
            E::MalformedImage(_) => (StatusCode::BAD_REQUEST, "malformed_image"),
            E::ImageSize { .. } => (StatusCode::BAD_REQUEST, "image_size"),
            E::SizeMismatch(_) => (StatusCode::BAD_REQUEST, "size_mismatch"),
            E::InvalidRange { .. } => (StatusCode::BAD_REQUEST, "out_of_range"),
            E::TooLarge(_) => (StatusCode::BAD_REQUEST, "too_large"),
            E::InvalidParameter { .. } => (StatusCode::BAD_REQUEST, "invalid_parameter"),
            E::InvalidRequest(_) => (StatusCode::BAD_REQUEST, "invalid_request"),
            E::CorruptFile(_) => (StatusCode::INTERNAL_SERVER_ERROR, "corrupt_file"),
            E::Io(_) => (StatusCode::INTERNAL_SERVER_ERROR, "io"),
        };
        ApiError::new(status, code, message)
    }
}

impl From<SpecError> for ApiError {
    fn from(e: SpecError) -> Self {
        match e {
            SpecError::InvalidParams(message) => {
                ApiError::new(StatusCode::BAD_REQUEST, "invalid_params", message)
            }
            SpecError::Engine(e) => e.into(),
        }
    }
}

impl From<RegistryError> for ApiError {
    fn from(e: RegistryError) -> Self {
        use RegistryError as E;
        let message = e.to_string();
        match e {
            E::UnknownTexture(id) => ApiError::unknown_texture(&id),
            // Being loaded back is brief: worth a retry, unlike a conflict.
            E::Loading(_) => {
                ApiError::new(StatusCode::SERVICE_UNAVAILABLE, "texture_loading", message)
                    .retry_after(1)
            }
            E::Starting => {
                ApiError::new(StatusCode::SERVICE_UNAVAILABLE, "starting", message).retry_after(1)
            }
            E::Pending { .. } => {
                ApiError::new(StatusCode::CONFLICT, "texture_pending", message).retry_after(1)
            }
            E::Failed { .. } => ApiError::new(StatusCode::CONFLICT, "texture_failed", message),
            E::QueueFull => ApiError::overloaded("precompute queue is full"),
            E::PrecomputeTooLarge { estimated, bound } => {
                ApiError::precompute_too_large(estimated, bound)
            }
            E::StorageFull(message) => ApiError::storage_full(message),
            E::Internal(message) => ApiError::internal(message),
        }
    }
}

impl From<DecodeError> for ApiError {
    fn from(e: DecodeError) -> Self {
        match e {
            DecodeError::TooLarge { needed, bound } => {
                let mib = |b: u64| b.div_ceil(1 << 20);
                ApiError::new(
                    StatusCode::PAYLOAD_TOO_LARGE,
                    "image_too_large",
                    format!(
                        "decoding these images takes about {} MiB of memory, more than the {} \
                         MiB this server allows decodes (--max-decode-bytes); send a smaller \
                         image (larger than 512 pixels it is downscaled anyway)",
                        mib(needed),
                        mib(bound)
                    ),
                )
            }
            DecodeError::Busy => ApiError::overloaded("image decoding is busy"),
        }
    }
}

impl From<JobError> for ApiError {
    fn from(e: JobError) -> Self {
        match e {
            JobError::Overloaded {
                reason,
                retry_after,
            } => ApiError::overloaded(reason).retry_after(retry_after),
            JobError::OverBudget { budget } => ApiError::over_budget(budget),
            JobError::Failed(message) => ApiError::internal(message),
        }
    }
}

/// Most characters of a request's own text (a key, a value, a path) that
/// an error message repeats.
pub const MAX_ECHO_CHARS: usize = 80;

/// Most characters of an error message.
pub const MAX_MESSAGE_CHARS: usize = 2048;

/// `text` as an error message repeats it: at most [`MAX_ECHO_CHARS`]
/// characters, the rest elided with its length said.
pub fn echo(text: &str) -> std::borrow::Cow<'_, str> {
    match text.char_indices().nth(MAX_ECHO_CHARS) {
        None => text.into(),
        Some((end, _)) => format!("{}… ({} bytes)", &text[..end], text.len()).into(),
    }
}

/// An error message with every `quoted` part (what messages repeat of the
/// request, by convention) elided past [`MAX_ECHO_CHARS`], and the whole
/// cut at [`MAX_MESSAGE_CHARS`]: a client sending a 500 KB key gets its
/// error, not its key back.
fn bounded(message: &str) -> std::borrow::Cow<'_, str> {
    if message.len() <= MAX_ECHO_CHARS {
        return message.into();
    }
    let mut out = String::with_capacity(message.len().min(MAX_MESSAGE_CHARS + 64));
    for (i, part) in message.split('`').enumerate() {
        if i > 0 {
            out.push('`');
        }
        out.push_str(if i % 2 == 1 { echo(part) } else { part.into() }.as_ref());
    }
    if let Some((end, _)) = out.char_indices().nth(MAX_MESSAGE_CHARS) {
        out.truncate(end);
        out.push('…');
    }
    out.into()
}

/// The JSON body of an error.
pub fn error_body(code: &str, message: &str) -> String {
    bounded_body(code, &bounded(message))
}

// openapi.yaml's `Error` schema is generated from this type: its doc
// comments are the document's descriptions.
/// The body of every error answer.
#[derive(Serialize, JsonSchema)]
#[schemars(rename = "Error")]
pub(crate) struct ErrorBody<'a> {
    pub(crate) error: ErrorDetail<'a>,
}

/// What went wrong.
#[derive(Serialize, JsonSchema)]
#[schemars(inline)]
pub(crate) struct ErrorDetail<'a> {
    /// Stable identifier of the error class.
    pub(crate) code: &'a str,
    /// Human-readable explanation.
    pub(crate) message: &'a str,
}

fn bounded_body(code: &str, message: &str) -> String {
    let body = ErrorBody {
        error: ErrorDetail { code, message },
    };
    serde_json::to_string(&body).expect("an error body serialises")
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        // Shedding load (503) is the server working as configured, not a
        // failure; `log_response` reports it at INFO.
        let message = bounded(&self.message);
        if self.status == StatusCode::SERVICE_UNAVAILABLE {
            tracing::debug!(code = self.code, %message, "request shed");
        } else if self.status.is_server_error() {
            tracing::error!(code = self.code, %message, "request failed");
        } else {
            tracing::debug!(code = self.code, %message, "request rejected");
        }
        let mut res = Response::new(Body::from(bounded_body(self.code, &message)));
        *res.status_mut() = self.status;
        res.headers_mut().insert(
            header::CONTENT_TYPE,
            HeaderValue::from_static("application/json"),
        );
        if let Some(s) = self.retry_after {
            res.headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from(s));
        }
        res
    }
}

/// The error code used for a bare status.
pub fn code_for_status(status: StatusCode) -> &'static str {
    match status {
        StatusCode::BAD_REQUEST => "bad_request",
        StatusCode::NOT_FOUND => "no_route",
        StatusCode::METHOD_NOT_ALLOWED => "method_not_allowed",
        StatusCode::PAYLOAD_TOO_LARGE => "payload_too_large",
        StatusCode::UNSUPPORTED_MEDIA_TYPE => "unsupported_media_type",
        StatusCode::UNPROCESSABLE_ENTITY => "unprocessable",
        StatusCode::REQUEST_TIMEOUT => "timeout",
        StatusCode::SERVICE_UNAVAILABLE => "unavailable",
        s if s.is_server_error() => "internal",
        _ => "error",
    }
}

/// Middleware: rewrites any error response that is not already JSON
/// (framework rejections, empty 405s) into the JSON error shape, keeping
/// its status and headers. An error to an upload closes the connection.
pub async fn json_errors(req: axum::extract::Request, next: axum::middleware::Next) -> Response {
    let upload = req.method() == axum::http::Method::POST;
    let mut res = next.run(req).await;
    let status = res.status();
    if !(status.is_client_error() || status.is_server_error()) {
        return res;
    }
    if upload {
        // The upload may have been refused before its body was read (too
        // large, bad query or type): the connection cannot be reused, and
        // saying so keeps the client from sending its next request on it.
        res.headers_mut()
            .insert(header::CONNECTION, HeaderValue::from_static("close"));
    }
    let is_json = res
        .headers()
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.starts_with("application/json"));
    if is_json {
        return res;
    }
    let (mut parts, body) = res.into_parts();
    let text = axum::body::to_bytes(body, 4096)
        .await
        .map(|b| String::from_utf8_lossy(&b).trim().to_string())
        .unwrap_or_default();
    let message = if text.is_empty() {
        status
            .canonical_reason()
            .unwrap_or("error")
            .to_ascii_lowercase()
    } else {
        text
    };
    parts.headers.remove(header::CONTENT_LENGTH);
    parts.headers.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/json"),
    );
    Response::from_parts(
        parts,
        Body::from(error_body(code_for_status(status), &message)),
    )
}

/// The answer to a panic inside a handler: a JSON 500; the server goes on.
pub fn panic_response(err: Box<dyn std::any::Any + Send + 'static>) -> Response {
    let what = panic_message(err.as_ref());
    tracing::error!(panic = %what, "handler panicked");
    ApiError::internal(format!("internal error: {what}")).into_response()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_body_is_written_as_its_json_map_was() {
        let body = ErrorBody {
            error: ErrorDetail {
                code: "a",
                message: "b",
            },
        };
        assert!(crate::openapi::keys_in_map_order(&body));
        assert_eq!(
            error_body("a", "b"),
            r#"{"error":{"code":"a","message":"b"}}"#
        );
    }

    #[test]
    fn engine_errors_map_to_statuses() {
        let e: ApiError = solidtex_core::Error::MalformedImage("x".into()).into();
        assert_eq!(
            (e.status, e.code),
            (StatusCode::BAD_REQUEST, "malformed_image")
        );
        let e: ApiError = solidtex_core::Error::TooLarge("x".into()).into();
        assert_eq!(e.code, "too_large");
        let e: ApiError = solidtex_core::Error::InvalidRange {
            name: "lod",
            value: 9.0,
            min: 0.0,
            max: 3.0,
        }
        .into();
        assert_eq!(
            (e.status, e.code),
            (StatusCode::BAD_REQUEST, "out_of_range")
        );
        let e: ApiError = solidtex_core::Error::Io(std::io::Error::other("disk")).into();
        assert_eq!(e.status, StatusCode::INTERNAL_SERVER_ERROR);
    }

    #[test]
    fn domain_errors_map_to_statuses() {
        let e: ApiError = RegistryError::UnknownTexture("t".into()).into();
        assert_eq!(
            (e.status, e.code),
            (StatusCode::NOT_FOUND, "unknown_texture")
        );
        assert_eq!(e.message, "no texture with id `t`");
        let e: ApiError = RegistryError::Pending {
            id: "t".into(),
            progress: 0.426,
        }
        .into();
        assert_eq!(
            (e.status, e.code),
            (StatusCode::CONFLICT, "texture_pending")
        );
        assert_eq!(e.message, "texture `t` is still being precomputed (43%)");
        assert_eq!(e.retry_after, Some(1));
        let e: ApiError = RegistryError::Failed {
            id: "t".into(),
            reason: "r".into(),
        }
        .into();
        assert_eq!((e.status, e.code), (StatusCode::CONFLICT, "texture_failed"));
        assert_eq!(e.retry_after, None);
        let e: ApiError = RegistryError::Loading("t".into()).into();
        assert_eq!(
            (e.status, e.code, e.retry_after),
            (StatusCode::SERVICE_UNAVAILABLE, "texture_loading", Some(1))
        );
        let e: ApiError = RegistryError::Starting.into();
        assert_eq!(
            (e.status, e.code, e.retry_after),
            (StatusCode::SERVICE_UNAVAILABLE, "starting", Some(1))
        );
        let e: ApiError = RegistryError::QueueFull.into();
        assert_eq!(e.message, "precompute queue is full; retry later");
        let e: ApiError = RegistryError::PrecomputeTooLarge {
            estimated: 3 << 20,
            bound: 1 << 20,
        }
        .into();
        assert_eq!(
            (e.status, e.code),
            (StatusCode::PAYLOAD_TOO_LARGE, "precompute_too_large")
        );
        let e: ApiError = RegistryError::StorageFull("full".into()).into();
        assert_eq!(e.status, StatusCode::INSUFFICIENT_STORAGE);
        let e: ApiError = JobError::Overloaded {
            reason: "synthesis queue is full",
            retry_after: 7,
        }
        .into();
        assert_eq!(
            (e.status, e.code, e.retry_after),
            (StatusCode::SERVICE_UNAVAILABLE, "overloaded", Some(7))
        );
        assert_eq!(e.message, "synthesis queue is full; retry later");
        let e: ApiError = JobError::OverBudget { budget: 9 }.into();
        assert_eq!((e.status, e.code), (StatusCode::BAD_REQUEST, "over_budget"));
        let e: ApiError = DecodeError::TooLarge {
            needed: 3 << 20,
            bound: 1 << 20,
        }
        .into();
        assert_eq!(
            (e.status, e.code),
            (StatusCode::PAYLOAD_TOO_LARGE, "image_too_large")
        );
        let e: ApiError = DecodeError::Busy.into();
        assert_eq!(
            (e.status, e.code, e.retry_after),
            (StatusCode::SERVICE_UNAVAILABLE, "overloaded", Some(1))
        );
        let e: ApiError = JobError::Failed("boom".into()).into();
        assert_eq!(e.status, StatusCode::INTERNAL_SERVER_ERROR);
        let e: ApiError = SpecError::InvalidParams("p".into()).into();
        assert_eq!(
            (e.status, e.code),
            (StatusCode::BAD_REQUEST, "invalid_params")
        );
    }

    #[test]
    fn echoed_input_is_capped() {
        let key = "k".repeat(500 << 10);
        let body = error_body(
            "invalid_params",
            &format!("unknown parameter `{key}` (known: seed, scheme)"),
        );
        assert!(body.len() < 400, "{} bytes", body.len());
        let v: serde_json::Value = serde_json::from_str(&body).unwrap();
        let m = v["error"]["message"].as_str().unwrap();
        assert!(m.ends_with("` (known: seed, scheme)"), "{m}");
        assert!(m.contains(&format!("… ({} bytes)`", key.len())), "{m}");
        // Short quotes and messages are left as they are; a long message
        // is cut whatever it quotes.
        assert_eq!(bounded("a `b` c"), "a `b` c");
        assert_eq!(
            echo("é".repeat(MAX_ECHO_CHARS).as_str()).chars().count(),
            MAX_ECHO_CHARS
        );
        let long = "x ".repeat(MAX_MESSAGE_CHARS);
        assert_eq!(bounded(&long).chars().count(), MAX_MESSAGE_CHARS + 1);
    }

    #[test]
    fn body_shape() {
        let v: serde_json::Value = serde_json::from_str(&error_body("a", "b \"c\"")).unwrap();
        assert_eq!(v["error"]["code"], "a");
        assert_eq!(v["error"]["message"], "b \"c\"");
    }
}
