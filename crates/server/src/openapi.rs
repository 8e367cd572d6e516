//! The parts of openapi.yaml generated from the one declaration of what
//! they describe: from the knobs ([`solidtex_core::knobs`]) the upload's
//! query parameters, each knob's parameter component, and the properties
//! of the `Params` and `VariantParams` schemas; from the voxel routes'
//! query structs ([`crate::routes::documented_queries`]) their operations'
//! query parameters, the `Lod` component and the `Vector` schema; from
//! the background jobs' path structs their path parameters' components
//! ([`crate::routes::documented_paths`]); from
//! the types of the JSON bodies the routes answer with
//! ([`crate::routes::documented_responses`], serde and `schemars`) their
//! component schemas. Each sits in the document between a marker
//! line `# generated: NAME` and `# end generated: NAME`; [`regenerate`]
//! rewrites what is between them and leaves the rest as written.
//! tests/server_openapi.rs checks that the file is what it gives.

use crate::routes::{self, QueryParam, ValueSchema};
use schemars::generate::{Contract, SchemaSettings};
use serde_json::Value;
use solidtex_core::knobs::{self, Knob, Part, Values};

/// A YAML node as the document writes it.
enum Node {
    /// A mapping, keys in the order given.
    Map(Vec<(&'static str, Node)>),
    /// A mapping whose keys come from data (a schema's property names).
    Keyed(Vec<(String, Node)>),
    /// A block sequence of mappings.
    List(Vec<Node>),
    /// A flow sequence of scalars: `[a, b]`.
    Flow(Vec<String>),
    /// A scalar, already written.
    Scalar(String),
    /// Prose, folded (`>-`) and wrapped.
    Prose(String),
}

fn text(s: &str) -> Node {
    Node::Scalar(quoted(s))
}

/// A string as a plain scalar where YAML reads it back as the same
/// string, else double-quoted (JSON's quoting is YAML's).
fn quoted(s: &str) -> String {
    let plain = !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
        && s.parse::<f64>().is_err()
        && !matches!(
            s,
            "true" | "false" | "null" | "yes" | "no" | "on" | "off" | "y" | "n"
        );
    if plain {
        s.to_string()
    } else {
        serde_json::to_string(s).expect("a string serialises")
    }
}

fn scalar(v: &Value) -> String {
    match v {
        Value::String(s) => quoted(s),
        other => other.to_string(),
    }
}

fn number(x: f64) -> Node {
    Node::Scalar(format!("{x}"))
}

fn write(out: &mut String, node: &Node, indent: usize) {
    match node {
        Node::Map(entries) => write_entries(out, entries.iter().map(|(k, v)| (*k, v)), indent),
        Node::Keyed(entries) => {
            write_entries(out, entries.iter().map(|(k, v)| (k.as_str(), v)), indent)
        }
        Node::List(items) => {
            let pad = " ".repeat(indent);
            for item in items {
                let mut inner = String::new();
                write(&mut inner, item, indent + 2);
                out.push_str(&pad);
                out.push_str("- ");
                out.push_str(&inner[indent + 2..]);
            }
        }
        Node::Flow(_) | Node::Scalar(_) | Node::Prose(_) => {
            unreachable!("a scalar is written under its key")
        }
    }
}

fn write_entries<'a>(
    out: &mut String,
    entries: impl Iterator<Item = (&'a str, &'a Node)>,
    indent: usize,
) {
    let pad = " ".repeat(indent);
    for (k, v) in entries {
        // `@` and `` ` `` are reserved at the start of a plain YAML scalar.
        let quoted_key;
        let k = if k.starts_with(['@', '`']) {
            quoted_key = quoted(k);
            quoted_key.as_str()
        } else {
            k
        };
        match v {
            Node::Scalar(s) => out.push_str(&format!("{pad}{k}: {s}\n")),
            Node::Flow(items) => out.push_str(&format!("{pad}{k}: [{}]\n", items.join(", "))),
            Node::Prose(t) => {
                out.push_str(&format!("{pad}{k}: >-\n"));
                wrap(out, t, indent + 2);
            }
            Node::Map(m) if m.is_empty() => out.push_str(&format!("{pad}{k}: {{}}\n")),
            Node::Keyed(m) if m.is_empty() => out.push_str(&format!("{pad}{k}: {{}}\n")),
            Node::Map(_) | Node::Keyed(_) | Node::List(_) => {
                out.push_str(&format!("{pad}{k}:\n"));
                write(out, v, indent + 2);
            }
        }
    }
}

/// Prose wrapped at 80 columns, every line at `indent`.
fn wrap(out: &mut String, t: &str, indent: usize) {
    let width = 80usize.saturating_sub(indent).max(40);
    let mut line = String::new();
    for word in t.split_whitespace() {
        if !line.is_empty() && line.chars().count() + 1 + word.chars().count() > width {
            out.push_str(&format!("{}{line}\n", " ".repeat(indent)));
            line.clear();
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.push_str(word);
    }
    out.push_str(&format!("{}{line}\n", " ".repeat(indent)));
}

/// The knob's component name: `finest_passes` → `FinestPasses`.
fn component(name: &str) -> String {
    name.split('_')
        .map(|w| {
            let mut c = w.chars();
            c.next()
                .map(|f| f.to_ascii_uppercase().to_string() + c.as_str())
                .unwrap_or_default()
        })
        .collect()
}

/// The schema of a knob's values as a query string (or a flag) gives them.
fn query_schema(k: &Knob, default: Option<&Value>) -> Vec<(&'static str, Node)> {
    let mut s = match k.values {
        Values::Integer {
            min,
            max,
            odd: true,
        } => vec![
            ("type", text("integer")),
            (
                "enum",
                Node::Flow(
                    (min..=max)
                        .filter(|n| n % 2 == 1)
                        .map(|n| n.to_string())
                        .collect(),
                ),
            ),
        ],
        Values::Integer { min, max, .. } => vec![
            ("type", text("integer")),
            ("minimum", Node::Scalar(min.to_string())),
            ("maximum", Node::Scalar(max.to_string())),
        ],
        Values::Number { min, max } => vec![
            ("type", text("number")),
            ("minimum", number(min)),
            ("maximum", number(max)),
        ],
        Values::Flag => vec![("type", text("boolean"))],
        Values::Choice(names) => vec![
            ("type", text("string")),
            (
                "enum",
                Node::Flow(names.iter().map(|n| quoted(n)).collect()),
            ),
        ],
        Values::Text {
            max_len, pattern, ..
        } => {
            let mut s = vec![("type", text("string"))];
            if let Some(p) = pattern {
                s.push(("pattern", text(p)));
            }
            if let Some(n) = max_len {
                s.push(("maxLength", Node::Scalar(n.to_string())));
            }
            s
        }
    };
    if let Some(d) = default {
        s.push(("default", Node::Scalar(scalar(d))));
    }
    s
}

/// The schema of a knob's values in a JSON body: the query's, or for a
/// knob with a text grammar, that text or its structured form.
fn body_schema(k: &Knob) -> Vec<(&'static str, Node)> {
    let reference =
        |to: &str| Node::Map(vec![("$ref", text(&format!("#/components/schemas/{to}")))]);
    let structured = match k.name {
        "orientation" => vec![
            Node::Map(vec![
                ("type", text("string")),
                ("enum", Node::Flow(vec!["auto".into(), "none".into()])),
            ]),
            reference("Arrangement"),
        ],
        // A sketch's curves make long texts: a body's limit, not a query's.
        "field" => vec![
            Node::Map(vec![
                ("type", text("string")),
                ("maxLength", Node::Scalar("262144".into())),
            ]),
            reference("Field"),
        ],
        "period" => {
            let side = || {
                vec![
                    ("type", text("integer")),
                    ("minimum", Node::Scalar("1".into())),
                    (
                        "maximum",
                        Node::Scalar(solidtex_core::period::MAX_PERIOD.to_string()),
                    ),
                ]
            };
            vec![
                Node::Map(side()),
                Node::Map(vec![
                    ("type", text("array")),
                    ("items", Node::Map(side())),
                    ("minItems", Node::Scalar("3".into())),
                    ("maxItems", Node::Scalar("3".into())),
                ]),
                // As text, read by the query's own parser.
                Node::Map(query_schema(k, None)),
            ]
        }
        _ => return query_schema(k, None),
    };
    vec![("oneOf", Node::List(structured))]
}

fn preset_schema() -> Vec<(&'static str, Node)> {
    vec![
        ("type", text("string")),
        (
            "enum",
            Node::Flow(knobs::PRESETS.iter().map(|(n, _)| quoted(n)).collect()),
        ),
    ]
}

/// The pattern of three numbers `x,y,z` (the parser takes more: any
/// number Rust reads, spaces around each).
const VECTOR: &str = r"^-?[0-9]+(\.[0-9]+)?,-?[0-9]+(\.[0-9]+)?,-?[0-9]+(\.[0-9]+)?$";

/// A route's query parameter as a parameter object.
fn query_parameter(p: &QueryParam) -> Node {
    parameter_object(p, "query")
}

/// A route's parameter `p`, found `location` (`query` or `path`), as a
/// parameter object.
fn parameter_object(p: &QueryParam, location: &'static str) -> Node {
    let mut schema = match p.schema {
        ValueSchema::Integer { min, max } => {
            let mut s = vec![("type", text("integer"))];
            if min < i64::from(i32::MIN) || max > i64::from(i32::MAX) {
                s.push(("format", text("int64")));
            }
            s.push(("minimum", Node::Scalar(min.to_string())));
            s.push(("maximum", Node::Scalar(max.to_string())));
            s
        }
        ValueSchema::Vector => vec![("type", text("string")), ("pattern", text(VECTOR))],
        ValueSchema::Choice(names) => vec![
            ("type", text("string")),
            (
                "enum",
                Node::Flow(names.iter().map(|n| quoted(n)).collect()),
            ),
        ],
        ValueSchema::Number { min, max } => vec![
            ("type", text("number")),
            ("minimum", Node::Scalar(min.to_string())),
            ("maximum", Node::Scalar(max.to_string())),
        ],
        ValueSchema::Text {
            max_len,
            pattern,
            example,
        } => {
            let mut s = vec![("type", text("string"))];
            if let Some(n) = max_len {
                s.push(("maxLength", Node::Scalar(n.to_string())));
            }
            if let Some(p) = pattern {
                s.push(("pattern", text(p)));
            }
            if let Some(e) = example {
                s.push(("example", text(e)));
            }
            s
        }
    };
    if let Some(d) = &p.default {
        let written = match p.schema {
            ValueSchema::Integer { .. } | ValueSchema::Number { .. } => d.clone(),
            _ => quoted(d),
        };
        schema.push(("default", Node::Scalar(written)));
    }
    let mut entries = vec![("name", text(p.name)), ("in", text(location))];
    if p.required {
        entries.push(("required", Node::Scalar("true".into())));
    }
    entries.push(("description", Node::Prose(p.about.to_string())));
    entries.push(("schema", Node::Map(schema)));
    Node::Map(entries)
}

/// The region called `name`, at `indent`.
fn region(name: &str, indent: usize) -> Option<String> {
    let mut out = String::new();
    let node = match name {
        "vector-schema" => Node::Map(vec![(
            "Vector",
            Node::Map(vec![
                ("type", text("string")),
                ("pattern", text(VECTOR)),
                ("example", text("0.5,-3,12")),
            ]),
        )]),
        "lod-parameter" => Node::Map(vec![("Lod", query_parameter(&routes::lod_parameter()))]),
        "path-parameters" => Node::Map(
            routes::documented_paths()
                .iter()
                .flat_map(|(component, params)| {
                    params
                        .iter()
                        .map(|p| (*component, parameter_object(p, "path")))
                })
                .collect(),
        ),
        _ if name.starts_with("query ") => {
            let operation = &name["query ".len()..];
            let (_, params) = routes::documented_queries()
                .into_iter()
                .find(|(op, _)| *op == operation)?;
            Node::List(params.iter().map(query_parameter).collect())
        }
        "upload-query" => Node::List(
            std::iter::once("preset")
                .chain(knobs::KNOBS.iter().map(|k| k.name))
                .map(|n| {
                    Node::Map(vec![(
                        "$ref",
                        text(&format!("#/components/parameters/{}", component(n))),
                    )])
                })
                .collect(),
        ),
        "parameters" => {
            let mut entries = Vec::new();
            let mut preset = preset_schema();
            preset.push(("default", text(knobs::PRESETS[0].0)));
            entries.push(parameter("preset", knobs::PRESET_ABOUT, preset));
            for k in knobs::KNOBS {
                let schema = query_schema(k, knobs::default_of(k).as_ref());
                entries.push(parameter(k.name, k.about, schema));
            }
            let mut out = String::new();
            for (name, node) in entries {
                out.push_str(&format!("{}{name}:\n", " ".repeat(indent)));
                write(&mut out, &node, indent + 2);
            }
            return Some(out);
        }
        "response-schemas" => Node::Keyed(
            response_schemas()
                .into_iter()
                .map(|(name, schema)| (name, schema_node(&schema)))
                .collect(),
        ),
        "params" => properties(knobs::KNOBS.iter(), false),
        "variant-params" => properties(knobs::knobs_of(Part::Synthesis), true),
        _ => return None,
    };
    write(&mut out, &node, indent);
    Some(out)
}

fn parameter(name: &'static str, about: &str, schema: Vec<(&'static str, Node)>) -> (String, Node) {
    (
        component(name),
        Node::Map(vec![
            ("name", text(name)),
            ("in", text("query")),
            ("description", Node::Prose(about.to_string())),
            ("schema", Node::Map(schema)),
        ]),
    )
}

/// The `properties` of a flat object of parameters: `preset`, then the
/// knobs given. In a variant, `null` drops a knob whose default is absent.
fn properties<'a>(knobs: impl Iterator<Item = &'a Knob>, variant: bool) -> Node {
    let mut preset = preset_schema();
    preset.push((
        "description",
        Node::Prose(if variant {
            "Start from this preset's synthesis parameters instead of the source's; keys \
             given beside it win (see the `preset` query parameter)."
                .into()
        } else {
            "Synthesis parameters to start from (see the `preset` query parameter); accepted \
             in uploads, never returned."
                .into()
        }),
    ));
    let mut props = vec![("preset", Node::Map(preset))];
    for k in knobs {
        let mut schema = body_schema(k);
        if variant && knobs::default_of(k).is_none() {
            schema.push(("nullable", Node::Scalar("true".into())));
        }
        schema.push(("description", Node::Prose(k.about.to_string())));
        props.push((k.name, Node::Map(schema)));
    }
    Node::Map(props)
}

/// The component schemas of the routes' JSON bodies, by name: what
/// `schemars` reads from their types (serde's attributes, doc comments as
/// descriptions) in OpenAPI 3.0's dialect.
fn response_schemas() -> serde_json::Map<String, Value> {
    let mut generator = SchemaSettings::openapi3()
        .with(|s| {
            // What the server writes: a field it may leave out is the one
            // it skips, not the one it would default.
            s.contract = Contract::Serialize;
            s.meta_schema = None;
        })
        .into_generator();
    routes::documented_responses(&mut generator);
    generator.take_definitions(true)
}

/// The order a reader expects a schema's keywords in; others follow in
/// alphabetical order.
const KEYWORDS: [&str; 20] = [
    "$ref",
    "type",
    "format",
    "nullable",
    "enum",
    "minimum",
    "maximum",
    "minLength",
    "maxLength",
    "pattern",
    "items",
    "minItems",
    "maxItems",
    "description",
    "required",
    "additionalProperties",
    "properties",
    "oneOf",
    "anyOf",
    "allOf",
];

/// A JSON Schema as the document writes it: keywords in [`KEYWORDS`]'
/// order, properties in the type's; titles left out, and formats but
/// `int32` and `int64` (the range is in the minimum and maximum; every
/// number is a double).
fn schema_node(schema: &Value) -> Node {
    let Value::Object(m) = schema else {
        return Node::Scalar(scalar(schema));
    };
    let mut keys: Vec<&String> = m.keys().collect();
    keys.sort_by_key(|k| {
        KEYWORDS
            .iter()
            .position(|w| w == k)
            .unwrap_or(KEYWORDS.len())
    });
    let mut entries = Vec::new();
    for k in keys {
        let v = &m[k];
        let node = match (k.as_str(), v) {
            ("title", _) => continue,
            ("format", Value::String(f)) if !matches!(f.as_str(), "int32" | "int64") => {
                continue;
            }
            ("properties", Value::Object(props)) => Node::Keyed(
                props
                    .iter()
                    .map(|(name, s)| (name.clone(), schema_node(s)))
                    .collect(),
            ),
            ("items" | "additionalProperties" | "not", _) => schema_node(v),
            ("oneOf" | "anyOf" | "allOf", Value::Array(a)) => {
                Node::List(a.iter().map(schema_node).collect())
            }
            ("description", Value::String(t)) => Node::Prose(t.clone()),
            _ => value_node(v),
        };
        entries.push((k.clone(), node));
    }
    Node::Keyed(entries)
}

/// A value (a default, an example, an enum) as YAML.
fn value_node(v: &Value) -> Node {
    match v {
        Value::Array(a) if a.iter().all(|x| !x.is_array() && !x.is_object()) => {
            Node::Flow(a.iter().map(scalar).collect())
        }
        Value::Array(a) => Node::List(a.iter().map(value_node).collect()),
        Value::Object(m) => {
            Node::Keyed(m.iter().map(|(k, v)| (k.clone(), value_node(v))).collect())
        }
        _ => Node::Scalar(scalar(v)),
    }
}

const BEGIN: &str = "# generated: ";
const END: &str = "# end generated: ";

/// The document with every generated region written anew from the knobs.
/// Errors name a marker without its end, or an unknown region.
pub fn regenerate(document: &str) -> Result<String, String> {
    let mut out = String::with_capacity(document.len());
    let mut lines = document.split_inclusive('\n');
    while let Some(line) = lines.next() {
        out.push_str(line);
        let trimmed = line.trim_start();
        let Some(name) = trimmed.strip_prefix(BEGIN).map(str::trim) else {
            continue;
        };
        let indent = line.len() - trimmed.len();
        let body = region(name, indent).ok_or(format!("unknown generated region `{name}`"))?;
        out.push_str(&body);
        let end = format!("{END}{name}");
        loop {
            match lines.next() {
                Some(l) if l.trim() == end => {
                    out.push_str(l);
                    break;
                }
                Some(_) => {}
                None => return Err(format!("`{BEGIN}{name}` has no `{end}`")),
            }
        }
    }
    Ok(out)
}

/// Whether `body` is written with its keys in the order a JSON map
/// (alphabetical) would write them: the bodies were such maps before they
/// were types, and their bytes stay the same.
#[cfg(test)]
pub(crate) fn keys_in_map_order<T: serde::Serialize>(body: &T) -> bool {
    let text = serde_json::to_string(body).expect("serialises");
    let value = serde_json::to_value(body).expect("serialises");
    let as_map = serde_json::to_string(&value).expect("serialises");
    text == as_map
}
