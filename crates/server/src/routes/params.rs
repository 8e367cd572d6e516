//! Typed path and query parameters.
//!
//! A route declares its parameters as a struct deriving `Deserialize`;
//! [`TypedPath`] and [`TypedQuery`] fill it from the path captures or the
//! query string, each value a string the field's type parses. The types
//! carry their own rules: [`Int`] its range and default, [`Vec3`] three
//! finite numbers, [`Stem`] a file extension on the last path segment. So
//! every failure names its parameter and has one of the API's codes:
//! `invalid_parameter` (malformed, given twice), `out_of_range`,
//! `invalid_axis`, `unknown_parameter` (a query parameter the route does
//! not take: the structs deny unknown fields), or 404 `no_route` for a
//! segment without its extension, as the router would answer.

use crate::error::ApiError;
use axum::extract::{FromRequestParts, RawPathParams};
use axum::http::StatusCode;
use axum::http::request::Parts;
use axum::response::{IntoResponse, Response};
use serde::de::{
    self, DeserializeOwned, Deserializer, Expected, IntoDeserializer, MapAccess, Unexpected,
    Visitor,
};
use serde::{Deserialize, forward_to_deserialize_any};
use std::fmt;
use std::marker::PhantomData;

/// Why a parameter was refused, before its name is attached.
#[derive(Debug)]
enum Problem {
    /// Malformed: `invalid_parameter`.
    Invalid(String),
    /// A value outside its range: `out_of_range`.
    OutOfRange { value: String, range: String },
    /// An axis that is not x, y or z: `invalid_axis`.
    Axis(String),
    /// A query parameter the route does not take: `unknown_parameter`.
    Unknown { expected: &'static [&'static str] },
    /// A path segment without its extension: 404 `no_route`.
    NoRoute(&'static str),
}

/// A refused parameter: the error type of the deserializers below.
#[derive(Debug)]
pub(super) struct ParamError {
    name: Option<String>,
    problem: Problem,
}

impl ParamError {
    fn new(problem: Problem) -> ParamError {
        ParamError {
            name: None,
            problem,
        }
    }

    /// Names the parameter, unless the error already names one.
    fn named(mut self, name: &str) -> ParamError {
        self.name.get_or_insert_with(|| name.to_string());
        self
    }
}

impl fmt::Display for ParamError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.to_api().message)
    }
}

impl std::error::Error for ParamError {}

impl de::Error for ParamError {
    fn custom<T: fmt::Display>(msg: T) -> Self {
        let msg = msg.to_string();
        match MISSING_EXTENSION.iter().find(|m| **m == msg) {
            Some(m) => ParamError::new(Problem::NoRoute(m)),
            None => ParamError::new(Problem::Invalid(msg)),
        }
    }

    fn invalid_type(unexp: Unexpected<'_>, exp: &dyn Expected) -> Self {
        ParamError::new(Problem::Invalid(format!("`{}` is not {exp}", shown(unexp))))
    }

    /// A value of the right type that the field refuses: every such value
    /// here is a number outside the field's range.
    fn invalid_value(unexp: Unexpected<'_>, exp: &dyn Expected) -> Self {
        ParamError::new(Problem::OutOfRange {
            value: shown(unexp),
            range: exp.to_string(),
        })
    }

    fn unknown_variant(variant: &str, expected: &'static [&'static str]) -> Self {
        if expected == ["x", "y", "z"] {
            return ParamError::new(Problem::Axis(variant.to_string()));
        }
        ParamError::new(Problem::Invalid(format!(
            "`{variant}` is not one of {}",
            expected.join(", ")
        )))
    }

    fn unknown_field(field: &str, expected: &'static [&'static str]) -> Self {
        ParamError::new(Problem::Unknown { expected }).named(field)
    }

    fn duplicate_field(field: &'static str) -> Self {
        ParamError::new(Problem::Invalid("given more than once".into())).named(field)
    }

    fn missing_field(field: &'static str) -> Self {
        ParamError::new(Problem::Invalid(MISSING.into())).named(field)
    }
}

/// A value as an error message shows it.
fn shown(unexp: Unexpected<'_>) -> String {
    match unexp {
        Unexpected::Str(s) => s.to_string(),
        Unexpected::Signed(v) => v.to_string(),
        Unexpected::Unsigned(v) => v.to_string(),
        Unexpected::Float(v) => v.to_string(),
        other => other.to_string(),
    }
}

impl ParamError {
    /// The answer to the client.
    fn to_api(&self) -> ApiError {
        let name = self.name.as_deref().unwrap_or("?");
        match &self.problem {
            Problem::Invalid(message) => ApiError::invalid_parameter(name, message),
            Problem::OutOfRange { value, range } => ApiError::new(
                StatusCode::BAD_REQUEST,
                "out_of_range",
                format!("parameter `{name}` = {value} is outside {range}"),
            ),
            Problem::Axis(axis) => ApiError::new(
                StatusCode::BAD_REQUEST,
                "invalid_axis",
                format!("unknown axis `{axis}` (expected x, y or z)"),
            ),
            Problem::Unknown { expected } => ApiError::new(
                StatusCode::BAD_REQUEST,
                "unknown_parameter",
                match expected {
                    [] => format!("unknown query parameter `{name}`: this route takes none"),
                    _ => format!(
                        "unknown query parameter `{name}`: this route takes {}",
                        expected.join(", ")
                    ),
                },
            ),
            Problem::NoRoute(message) => ApiError::new(StatusCode::NOT_FOUND, "no_route", *message),
        }
    }
}

impl From<ParamError> for ApiError {
    fn from(e: ParamError) -> ApiError {
        e.to_api()
    }
}

/// Parameters as (name, value) pairs, deserialized as a struct whose
/// fields each parse their value.
struct Pairs<I>(I);

impl<'de, I, K, T> Deserializer<'de> for Pairs<I>
where
    I: Iterator<Item = (K, T)>,
    K: AsRef<str>,
    T: AsRef<str>,
{
    type Error = ParamError;

    fn deserialize_any<W: Visitor<'de>>(self, visitor: W) -> Result<W::Value, ParamError> {
        visitor.visit_map(PairsAccess {
            pairs: self.0,
            value: None,
        })
    }

    forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string
        bytes byte_buf option unit unit_struct newtype_struct seq tuple
        tuple_struct map struct enum identifier ignored_any
    }
}

struct PairsAccess<I, K, V> {
    pairs: I,
    value: Option<(K, V)>,
}

impl<'de, I, K, V> MapAccess<'de> for PairsAccess<I, K, V>
where
    I: Iterator<Item = (K, V)>,
    K: AsRef<str>,
    V: AsRef<str>,
{
    type Error = ParamError;

    fn next_key_seed<S: de::DeserializeSeed<'de>>(
        &mut self,
        seed: S,
    ) -> Result<Option<S::Value>, ParamError> {
        let Some((k, v)) = self.pairs.next() else {
            return Ok(None);
        };
        let key = seed.deserialize(k.as_ref().into_deserializer())?;
        self.value = Some((k, v));
        Ok(Some(key))
    }

    fn next_value_seed<S: de::DeserializeSeed<'de>>(
        &mut self,
        seed: S,
    ) -> Result<S::Value, ParamError> {
        let (k, v) = self.value.take().expect("a value follows its key");
        seed.deserialize(Text(v.as_ref()))
            .map_err(|e| e.named(k.as_ref()))
    }
}

/// One parameter's text, handed to its field's type to parse.
struct Text<'a>(&'a str);

impl<'de> Deserializer<'de> for Text<'_> {
    type Error = ParamError;

    fn deserialize_any<W: Visitor<'de>>(self, visitor: W) -> Result<W::Value, ParamError> {
        visitor.visit_str(self.0)
    }

    fn deserialize_option<W: Visitor<'de>>(self, visitor: W) -> Result<W::Value, ParamError> {
        visitor.visit_some(self)
    }

    fn deserialize_newtype_struct<W: Visitor<'de>>(
        self,
        _name: &'static str,
        visitor: W,
    ) -> Result<W::Value, ParamError> {
        visitor.visit_newtype_struct(self)
    }

    fn deserialize_enum<W: Visitor<'de>>(
        self,
        _name: &'static str,
        _variants: &'static [&'static str],
        visitor: W,
    ) -> Result<W::Value, ParamError> {
        visitor.visit_enum(self.0.into_deserializer())
    }

    forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string
        bytes byte_buf unit unit_struct seq tuple tuple_struct map struct
        identifier ignored_any
    }
}

/// Deserializes `T` from (name, value) pairs.
pub(super) fn from_pairs<T, K, V>(pairs: impl Iterator<Item = (K, V)>) -> Result<T, ApiError>
where
    T: DeserializeOwned,
    K: AsRef<str>,
    V: AsRef<str>,
{
    T::deserialize(Pairs(pairs)).map_err(ApiError::from)
}

/// The query string as the struct `T` (which should deny unknown fields).
pub(super) struct TypedQuery<T>(pub T);

impl<S: Send + Sync, T: DeserializeOwned> FromRequestParts<S> for TypedQuery<T> {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, _: &S) -> Result<Self, ApiError> {
        let raw = parts.uri.query().unwrap_or("");
        from_pairs(form_urlencoded::parse(raw.as_bytes())).map(TypedQuery)
    }
}

/// A route that takes no query parameters: any given is refused.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct NoQuery {}

/// The path captures as the struct `T`.
pub(super) struct TypedPath<T>(pub T);

impl<S: Send + Sync, T: DeserializeOwned> FromRequestParts<S> for TypedPath<T> {
    type Rejection = Response;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, Response> {
        let raw = RawPathParams::from_request_parts(parts, state)
            .await
            .map_err(IntoResponse::into_response)?;
        from_pairs(raw.iter())
            .map(TypedPath)
            .map_err(IntoResponse::into_response)
    }
}

/// An integer in `MIN..=MAX`, `DEFAULT` when not given.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Int<const MIN: i64, const MAX: i64, const DEFAULT: i64 = 0>(pub i64);

impl<const MIN: i64, const MAX: i64, const DEFAULT: i64> Int<MIN, MAX, DEFAULT> {
    /// The value, which lies in `MIN..=MAX`.
    pub(super) fn get(self) -> i64 {
        self.0
    }

    /// The value as a `u32`, for fields whose range fits one.
    pub(super) fn get_u32(self) -> u32 {
        const { assert!(MIN >= 0 && MAX <= u32::MAX as i64) };
        self.0 as u32
    }
}

impl<const MIN: i64, const MAX: i64, const DEFAULT: i64> Default for Int<MIN, MAX, DEFAULT> {
    fn default() -> Self {
        Int(DEFAULT)
    }
}

/// What an [`Int`] accepts, as error messages write it.
struct Range(i64, i64);

impl Expected for Range {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}..={}", self.0, self.1)
    }
}

impl<'de, const MIN: i64, const MAX: i64, const DEFAULT: i64> Deserialize<'de>
    for Int<MIN, MAX, DEFAULT>
{
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V<const MIN: i64, const MAX: i64>;
        impl<const MIN: i64, const MAX: i64> Visitor<'_> for V<MIN, MAX> {
            type Value = i64;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write!(f, "an integer")
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<i64, E> {
                if (MIN..=MAX).contains(&v) {
                    Ok(v)
                } else {
                    Err(E::invalid_value(Unexpected::Signed(v), &Range(MIN, MAX)))
                }
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<i64, E> {
                match i64::try_from(v) {
                    Ok(v) => self.visit_i64(v),
                    Err(_) => Err(E::invalid_value(Unexpected::Unsigned(v), &Range(MIN, MAX))),
                }
            }
            fn visit_str<E: de::Error>(self, s: &str) -> Result<i64, E> {
                match s.trim().parse::<i64>() {
                    Ok(v) => self.visit_i64(v),
                    // Digits that do not fit an i64 are out of range too.
                    Err(_) if is_integer(s.trim()) => {
                        Err(E::invalid_value(Unexpected::Str(s), &Range(MIN, MAX)))
                    }
                    Err(_) => Err(E::invalid_type(Unexpected::Str(s), &self)),
                }
            }
        }
        d.deserialize_any(V::<MIN, MAX>).map(Int)
    }
}

/// True for an optional sign and at least one decimal digit.
fn is_integer(s: &str) -> bool {
    let digits = s.strip_prefix(['-', '+']).unwrap_or(s);
    !digits.is_empty() && digits.bytes().all(|b| b.is_ascii_digit())
}

/// Three finite numbers written `x,y,z`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Vec3(pub [f64; 3]);

impl<'de> Deserialize<'de> for Vec3 {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        let parts: Vec<&str> = s.split(',').collect();
        if parts.len() != 3 {
            return Err(de::Error::custom(format_args!(
                "`{s}` is not three comma-separated numbers"
            )));
        }
        let mut out = [0.0; 3];
        for (o, p) in out.iter_mut().zip(parts) {
            let v: f64 = p
                .trim()
                .parse()
                .map_err(|_| de::Error::custom(format_args!("`{p}` is not a number")))?;
            if !v.is_finite() {
                return Err(de::Error::custom("components must be finite"));
            }
            *o = v;
        }
        Ok(Vec3(out))
    }
}

/// Three integers written `a_b_c` (a brick's indices).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Triple(pub [i64; 3]);

impl<'de> Deserialize<'de> for Triple {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        let parts: Vec<&str> = s.split('_').collect();
        if parts.len() != 3 {
            return Err(de::Error::custom(format_args!("`{s}` is not bx_by_bz")));
        }
        let mut out = [0i64; 3];
        for (o, p) in out.iter_mut().zip(parts) {
            *o = Int::<{ i64::MIN }, { i64::MAX }>::deserialize(p.into_deserializer())?.get();
        }
        Ok(Triple(out))
    }
}

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

/// Every [`Extension::EXPECTED`]: the errors that mean "no such route"
/// rather than a malformed parameter.
const MISSING_EXTENSION: [&str; 3] = [Png::EXPECTED, Raw::EXPECTED, Json::EXPECTED];

/// A path segment `<stem><E::SUFFIX>` whose stem parses as `T`. Some
/// routes name a file in their last segment; the router matches whole
/// segments only, so the segment is captured whole and split here.
pub(super) struct Stem<E, T>(pub T, PhantomData<E>);

impl<'de, E: Extension, T: DeserializeOwned> Deserialize<'de> for Stem<E, T> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let segment = String::deserialize(d)?;
        let stem = segment
            .strip_suffix(E::SUFFIX)
            .ok_or_else(|| de::Error::custom(E::EXPECTED))?;
        T::deserialize(stem.into_deserializer()).map(|t| Stem(t, PhantomData))
    }
}

/// What a query parameter takes, as the API document states it.
#[derive(Clone, Debug, PartialEq)]
pub enum ValueSchema {
    /// An integer in `min..=max`.
    Integer {
        /// The least accepted.
        min: i64,
        /// The greatest accepted.
        max: i64,
    },
    /// A number in `min..=max`.
    Number {
        /// The least accepted.
        min: f64,
        /// The greatest accepted.
        max: f64,
    },
    /// Three numbers written `x,y,z`.
    Vector,
    /// One of these names.
    Choice(&'static [&'static str]),
    /// A string, of at most `max_len` bytes and matching `pattern` when
    /// given.
    Text {
        /// The longest accepted.
        max_len: Option<u32>,
        /// A regular expression every accepted value matches.
        pattern: Option<&'static str>,
        /// A value to show.
        example: Option<&'static str>,
    },
}

/// One query parameter as the API document describes it: declared beside
/// the route's query struct (`document_query!`), its values and default
/// read from the field's type and the struct's `Default`.
#[derive(Clone, Debug)]
pub struct QueryParam {
    /// The name in the query string.
    pub name: &'static str,
    /// What it means, for the document.
    pub about: &'static str,
    /// What it takes.
    pub schema: ValueSchema,
    /// The value taken when it is not given, as the query writes it.
    pub default: Option<String>,
    /// Whether the query must give it.
    pub required: bool,
}

/// The field of `T` that an empty query lacks, if one is required.
pub(super) fn required_of<T: DeserializeOwned>() -> Option<String> {
    match T::deserialize(Pairs(std::iter::empty::<(&str, &str)>())) {
        Err(ParamError {
            name,
            problem: Problem::Invalid(why),
        }) if why == MISSING => name,
        _ => None,
    }
}

/// What a required field that was not given is told.
const MISSING: &str = "missing";

/// A query (or path) struct whose parameters the document describes.
pub(super) trait DocumentedQuery: DeserializeOwned {
    /// Its parameters, in the struct's order.
    fn params() -> Vec<QueryParam>;
}

/// A field type of a query struct, as the document describes its values.
pub(super) trait QueryValue {
    /// What the field takes.
    fn schema() -> ValueSchema;
    /// The value as a query writes it; `None` for one that is absent.
    fn written(&self) -> Option<String>;
}

impl<const MIN: i64, const MAX: i64, const DEFAULT: i64> QueryValue for Int<MIN, MAX, DEFAULT> {
    fn schema() -> ValueSchema {
        ValueSchema::Integer { min: MIN, max: MAX }
    }

    fn written(&self) -> Option<String> {
        Some(self.0.to_string())
    }
}

impl QueryValue for Vec3 {
    fn schema() -> ValueSchema {
        ValueSchema::Vector
    }

    fn written(&self) -> Option<String> {
        Some(self.0.map(|c| c.to_string()).join(","))
    }
}

/// A texture's id as a path gives it. Any text reads; one that no texture
/// can have is answered as unknown (404 `unknown_texture`) where it is
/// looked up, like an id that is not stored.
#[derive(Clone, Debug, Default, Deserialize)]
pub(super) struct TextureId(pub String);

impl QueryValue for TextureId {
    fn schema() -> ValueSchema {
        ValueSchema::Text {
            max_len: None,
            pattern: Some("^[A-Za-z0-9_-]{1,64}$"),
            example: Some(crate::DEFAULT_ID),
        }
    }

    fn written(&self) -> Option<String> {
        None
    }
}

/// The path of a route about one texture: `/v1/textures/{id}…`.
#[derive(Deserialize, Default)]
pub(super) struct TexturePath {
    pub id: TextureId,
}

document_query!(TexturePath {
    id: "Texture id (a content hash, or `default` for the bundled exemplar).",
});

impl QueryValue for String {
    fn schema() -> ValueSchema {
        ValueSchema::Text {
            max_len: None,
            pattern: None,
            example: None,
        }
    }

    fn written(&self) -> Option<String> {
        Some(self.clone()).filter(|s| !s.is_empty())
    }
}

impl<T: QueryValue> QueryValue for Option<T> {
    fn schema() -> ValueSchema {
        T::schema()
    }

    fn written(&self) -> Option<String> {
        self.as_ref().and_then(T::written)
    }
}

/// A unit enum deserialized from its serde name.
macro_rules! named_value {
    ($($t:ty),*) => {$(
        impl $crate::routes::params::QueryValue for $t {
            fn schema() -> $crate::routes::params::ValueSchema {
                $crate::routes::params::ValueSchema::Choice(
                    $crate::routes::params::variants_of::<$t>(),
                )
            }

            fn written(&self) -> Option<String> {
                serde_json::to_value(self).ok()?.as_str().map(str::to_string)
            }
        }
    )*};
}

pub(super) use named_value;

named_value!(
    solidtex_core::Filter,
    solidtex_core::export::Format,
    solidtex_core::export::Mips
);

/// The names serde reads a unit enum from, in declaration order.
pub(super) fn variants_of<T: DeserializeOwned>() -> &'static [&'static str] {
    /// Stops the enum's deserialization at the names it hands over.
    struct Names;
    #[derive(Debug)]
    struct Found(&'static [&'static str]);
    impl fmt::Display for Found {
        fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
            write!(f, "{}", self.0.join(", "))
        }
    }
    impl std::error::Error for Found {}
    impl de::Error for Found {
        fn custom<M: fmt::Display>(_: M) -> Self {
            Found(&[])
        }
    }
    impl<'de> Deserializer<'de> for Names {
        type Error = Found;
        fn deserialize_any<W: Visitor<'de>>(self, _: W) -> Result<W::Value, Found> {
            Err(Found(&[]))
        }
        fn deserialize_enum<W: Visitor<'de>>(
            self,
            _: &'static str,
            variants: &'static [&'static str],
            _: W,
        ) -> Result<W::Value, Found> {
            Err(Found(variants))
        }
        forward_to_deserialize_any! {
            bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string
            bytes byte_buf option unit unit_struct newtype_struct seq tuple
            tuple_struct map struct identifier ignored_any
        }
    }
    match T::deserialize(Names) {
        Err(Found(names)) => names,
        Ok(_) => &[],
    }
}

/// The parameter `name` of the query struct `S`, read from `field`.
pub(super) fn query_param<S: Default, T: QueryValue>(
    field: fn(S) -> T,
    name: &'static str,
    about: &'static str,
) -> QueryParam {
    QueryParam {
        name,
        about,
        schema: T::schema(),
        default: field(S::default()).written(),
        required: false,
    }
}

/// The fields a query struct takes, as serde names them when refusing a
/// stranger.
#[cfg(test)]
pub(super) fn fields_of<T: DeserializeOwned>() -> &'static [&'static str] {
    match T::deserialize(Pairs(std::iter::once(("\u{1}", "")))) {
        Err(ParamError {
            problem: Problem::Unknown { expected },
            ..
        }) => expected,
        _ => panic!("the struct should refuse an unknown field"),
    }
}

/// Declares what each field of a query struct means, in the struct's
/// order: `document_query!(SliceQuery { u0: "First u.", … })`, a field
/// that serde renames with its query name (`whole as "box": …`). The field's
/// type gives its values, the struct's `Default` its default; a test checks
/// that the list is every field serde reads.
macro_rules! document_query {
    (@name $field:ident) => {
        stringify!($field)
    };
    (@name $field:ident $name:literal) => {
        $name
    };
    ($query:ident { $($field:ident $(as $name:literal)?: $about:expr),* $(,)? }) => {
        impl $crate::routes::params::DocumentedQuery for $query {
            fn params() -> Vec<$crate::routes::params::QueryParam> {
                let required = $crate::routes::params::required_of::<$query>();
                let mut params = vec![$($crate::routes::params::query_param(
                    |q: $query| q.$field,
                    document_query!(@name $field $($name)?),
                    $about,
                )),*];
                for p in &mut params {
                    // A required field's value in the struct's `Default`
                    // is no default of the query's.
                    p.required = required.as_deref() == Some(p.name);
                    if p.required {
                        p.default = None;
                    }
                }
                params
            }
        }
    };
}

pub(super) use document_query;

#[cfg(test)]
mod tests {
    use super::*;
    use solidtex_core::Axis;

    type Small = Int<-10, 10, 3>;

    #[derive(Deserialize, Debug)]
    #[serde(deny_unknown_fields)]
    struct Q {
        #[serde(default)]
        a: Small,
        #[serde(default)]
        b: Int<0, 5>,
        #[serde(default)]
        o: Option<Vec3>,
        #[serde(default)]
        axis: Option<Axis>,
    }

    fn parse(q: &str) -> Result<Q, ApiError> {
        from_pairs(form_urlencoded::parse(q.as_bytes()))
    }

    fn code(q: &str) -> &'static str {
        parse(q).unwrap_err().code
    }

    #[test]
    fn integers_in_range_with_defaults() {
        let q = parse("a=-7&o=1,2.5,-3").unwrap();
        assert_eq!((q.a.get(), q.b.get()), (-7, 0));
        assert_eq!(q.o, Some(Vec3([1.0, 2.5, -3.0])));
        assert_eq!(parse("").unwrap().a.get(), 3);
        assert_eq!(parse("a=%2B5").unwrap().a.get(), 5);
        assert_eq!(code("a=x"), "invalid_parameter");
        assert_eq!(code("a=8.5"), "invalid_parameter");
        assert_eq!(code("a=11"), "out_of_range");
        assert_eq!(code("b=-1"), "out_of_range");
        assert_eq!(code("a=99999999999999999999999"), "out_of_range");
        let e = parse("a=11").unwrap_err();
        assert_eq!(e.message, "parameter `a` = 11 is outside -10..=10");
        let e = parse("a=left").unwrap_err();
        assert_eq!(e.message, "parameter `a`: `left` is not an integer");
    }

    #[test]
    fn twice_unknown_and_malformed_are_refused_by_name() {
        assert_eq!(code("a=1&a=2"), "invalid_parameter");
        let e = parse("a0=5").unwrap_err();
        assert_eq!(e.code, "unknown_parameter");
        assert!(e.message.contains("`a0`") && e.message.contains("a, b, o, axis"));
        assert_eq!(code("o=1,2"), "invalid_parameter");
        assert_eq!(code("o=1,NaN,2"), "invalid_parameter");
        assert_eq!(code("o=inf,0,0"), "invalid_parameter");
        assert_eq!(parse("axis=y").unwrap().axis, Some(Axis::Y));
        assert_eq!(code("axis=w"), "invalid_axis");
        #[derive(Deserialize, Debug)]
        #[serde(deny_unknown_fields)]
        struct None_ {}
        let e = from_pairs::<None_, _, _>([("x", "1")].into_iter()).unwrap_err();
        assert_eq!(e.code, "unknown_parameter");
    }

    #[test]
    fn documented_values_come_from_the_types_and_defaults() {
        use solidtex_core::Filter;
        assert_eq!(variants_of::<Filter>(), ["nearest", "trilinear"]);
        assert_eq!(variants_of::<Axis>(), ["x", "y", "z"]);
        assert_eq!(Filter::Trilinear.written().as_deref(), Some("trilinear"));
        assert_eq!(
            Vec3([1.0, -0.5, 0.0]).written().as_deref(),
            Some("1,-0.5,0")
        );
        assert_eq!(None::<Small>.written(), None);
        assert_eq!(
            <Option<Small>>::schema(),
            ValueSchema::Integer { min: -10, max: 10 }
        );
        #[derive(Deserialize, Default)]
        #[serde(default, deny_unknown_fields)]
        struct D {
            a: Small,
            o: Option<Vec3>,
            f: Filter,
        }
        document_query!(D {
            a: "A.",
            o: "O.",
            f: "F.",
        });
        let params = D::params();
        let shown: Vec<_> = params
            .iter()
            .map(|p| (p.name, p.about, p.default.as_deref()))
            .collect();
        assert_eq!(
            shown,
            [
                ("a", "A.", Some("3")),
                ("o", "O.", None),
                ("f", "F.", Some("nearest"))
            ]
        );
        assert_eq!(fields_of::<D>(), ["a", "o", "f"]);
        assert_eq!(
            params[2].schema,
            ValueSchema::Choice(&["nearest", "trilinear"])
        );
    }

    #[test]
    fn stems_keep_all_but_the_extension() {
        #[derive(Deserialize)]
        struct P {
            at: Stem<Png, Int<-100, 100>>,
        }
        let at = |s: &str| from_pairs::<P, _, _>([("at", s)].into_iter()).map(|p| p.at.0.get());
        assert_eq!(at("12.png").unwrap(), 12);
        assert_eq!(at("-7.png").unwrap(), -7);
        assert_eq!(at("12.jpg").unwrap_err().code, "no_route");
        assert_eq!(at("12.jpg").unwrap_err().status, StatusCode::NOT_FOUND);
        assert_eq!(at("abc.png").unwrap_err().code, "invalid_parameter");
        assert_eq!(at("101.png").unwrap_err().code, "out_of_range");
        #[derive(Deserialize)]
        struct B {
            brick: Stem<Raw, Triple>,
        }
        let brick = |s: &str| from_pairs::<B, _, _>([("brick", s)].into_iter()).map(|b| b.brick.0);
        assert_eq!(brick("1_-2_3.raw").unwrap(), Triple([1, -2, 3]));
        assert_eq!(brick("0_0.raw").unwrap_err().code, "invalid_parameter");
        assert_eq!(brick("a_0_0.raw").unwrap_err().code, "invalid_parameter");
        assert_eq!(brick("0_0_0.png").unwrap_err().code, "no_route");
    }
}
