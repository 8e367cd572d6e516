//! The browser viewer: one page and its script, embedded in the binary so
//! that `solidtex serve` needs no files and no build step at install. The
//! page only uses the public API (list, upload, slices, cuts, bricks).

use axum::http::{HeaderValue, header};
use axum::response::{IntoResponse, Response};

/// The viewer page.
const PAGE: &str = include_str!("../viewer/index.html");

/// The viewer's script (plain JavaScript and WebGL).
const SCRIPT: &str = include_str!("../viewer/viewer.js");

fn asset(body: &'static str, content_type: &'static str) -> Response {
    let mut res = body.into_response();
    let h = res.headers_mut();
    h.insert(header::CONTENT_TYPE, HeaderValue::from_static(content_type));
    // Revalidated so that a new binary's viewer is picked up at once.
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    res
}

/// `GET /`
pub async fn page() -> Response {
    asset(PAGE, "text/html; charset=utf-8")
}

/// `GET /viewer.js`
pub async fn script() -> Response {
    asset(SCRIPT, "text/javascript; charset=utf-8")
}

#[cfg(test)]
mod tests {
    use super::PAGE;
    use solidtex_core::knobs::PRESETS;

    #[test]
    fn the_upload_form_offers_every_preset() {
        // The default is the empty choice (the server's own defaults).
        for (name, _) in &PRESETS[1..] {
            assert!(
                PAGE.contains(&format!("<option value=\"{name}\">")),
                "the viewer's preset menu lacks `{name}`"
            );
        }
    }
}
