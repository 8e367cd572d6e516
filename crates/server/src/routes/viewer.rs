//! The browser viewer: one page and its script, embedded in the binary so
//! that `solidtex serve` needs no files and no build step at install. The
//! page only uses the public API (list, upload, slices, cuts, bricks).

use axum::http::{HeaderValue, header};
use axum::response::{IntoResponse, Response};
use solidtex_core::knobs;

/// The viewer page as written: its upload form's parameter controls are
/// markers that [`page_html`] fills from the knob table.
const TEMPLATE: &str = include_str!("../viewer/index.html");

/// A short word on each preset beside its name in the menu; the default
/// is the empty choice (the server's own defaults).
const PRESET_NOTES: &[(&str, &str)] = &[
    ("preview", "faster, coarser"),
    (
        "structured",
        "about 2× slower; cleaner spots and cracks, blotchier wood",
    ),
];

/// The viewer page, its parameter controls built from the knob table so
/// that their ranges, defaults and descriptions are the ones the server
/// checks: a `<!-- knob NAME -->` marker becomes a number input, and
/// `<!-- presets -->` the preset menu.
fn page_html() -> String {
    let mut page = TEMPLATE.to_string();
    while let Some(at) = page.find("<!-- knob ") {
        let end = at + page[at..].find(" -->").expect("a closed marker") + 4;
        let name = page[at + 10..end - 4].to_string();
        let knob = knobs::knob(&name).unwrap_or_else(|| panic!("no knob `{name}`"));
        page.replace_range(at..end, &number_input(knob));
    }
    page.replace("<!-- presets -->", &preset_menu())
}

/// A number input for `knob`: its range, a step, its default as the
/// placeholder and its description as the title.
fn number_input(knob: &knobs::Knob) -> String {
    let (min, max, step) = match knob.values {
        knobs::Values::Integer { min, max, odd } => (
            min.to_string(),
            max.to_string(),
            if odd { "2" } else { "1" }.to_string(),
        ),
        knobs::Values::Number { min, max } => (
            min.to_string(),
            max.to_string(),
            ((max - min) / 16.0).to_string(),
        ),
        _ => panic!("`{}` is not a number", knob.name),
    };
    let default = knobs::default_of(knob).map_or(String::new(), |v| v.to_string());
    let id = format!("p-{}", knob.flag_name());
    format!(
        "<label for=\"{id}\">{label}</label><input id=\"{id}\" type=\"number\" \
         min=\"{min}\" max=\"{max}\" step=\"{step}\" placeholder=\"{default}\" \
         title=\"{title}\">",
        label = knob.name.replace('_', " "),
        title = escape(knob.about),
    )
}

/// The preset menu: the default as the empty choice, then every other.
fn preset_menu() -> String {
    let mut options = String::from("<option value=\"\">default</option>");
    for (name, _) in &knobs::PRESETS[1..] {
        let note = PRESET_NOTES
            .iter()
            .find(|(n, _)| n == name)
            .map_or(String::new(), |(_, note)| format!(" ({note})"));
        options.push_str(&format!(
            "<option value=\"{name}\">{name}{}</option>",
            escape(&note)
        ));
    }
    format!(
        "<label for=\"p-preset\">preset</label>\n      <select id=\"p-preset\" title=\"{}\">{options}</select>",
        escape(knobs::PRESET_ABOUT)
    )
}

/// Text as HTML attribute or element content.
fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('"', "&quot;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// The page, built once.
static PAGE: std::sync::LazyLock<String> = std::sync::LazyLock::new(page_html);

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
    asset(PAGE.as_str(), "text/html; charset=utf-8")
}

/// `GET /viewer.js`
pub async fn script() -> Response {
    asset(SCRIPT, "text/javascript; charset=utf-8")
}

#[cfg(test)]
mod tests {
    use super::{PAGE, escape};
    use solidtex_core::knobs::{self, PRESETS, Values};

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

    #[test]
    fn the_parameter_controls_are_the_knob_tables() {
        assert!(!PAGE.contains("<!--"), "a marker is left");
        for name in ["seed", "feature_weight", "passes"] {
            let k = knobs::knob(name).unwrap();
            let (min, max) = match k.values {
                Values::Integer { min, max, .. } => (min.to_string(), max.to_string()),
                Values::Number { min, max } => (min.to_string(), max.to_string()),
                _ => unreachable!(),
            };
            let default = knobs::default_of(k).unwrap().to_string();
            let id = format!("id=\"p-{}\"", k.flag_name());
            let input = &PAGE[PAGE.find(&id).unwrap_or_else(|| panic!("no {id}"))..];
            let input = &input[..input.find('>').unwrap()];
            for attribute in [
                format!("min=\"{min}\""),
                format!("max=\"{max}\""),
                format!("placeholder=\"{default}\""),
                format!("title=\"{}\"", escape(k.about)),
            ] {
                assert!(
                    input.contains(&attribute),
                    "{name}: {attribute} not in {input}"
                );
            }
        }
        assert!(PAGE.contains("placeholder=\"1\"") && PAGE.contains("max=\"6\""));
    }
}
