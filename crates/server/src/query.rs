//! Query-string parameters: typed lookups with the server's error shape.
//!
//! Unknown parameters are ignored; a parameter given twice, a value that
//! does not parse and a value out of range are each a 400 naming the
//! parameter.

use super::error::ApiError;
use std::collections::HashMap;
use std::str::FromStr;

/// The parsed query string of one request.
#[derive(Debug, Default)]
pub struct Query {
    pairs: HashMap<String, String>,
}

impl Query {
    /// Parses a raw (percent-encoded) query string.
    pub fn parse(raw: Option<&str>) -> Result<Query, ApiError> {
        let mut pairs = HashMap::new();
        for (k, v) in form_urlencoded::parse(raw.unwrap_or("").as_bytes()) {
            if pairs.insert(k.to_string(), v.to_string()).is_some() {
                return Err(ApiError::invalid_parameter(&k, "given more than once"));
            }
        }
        Ok(Query { pairs })
    }

    /// The raw value of `name`.
    pub fn raw(&self, name: &str) -> Option<&str> {
        self.pairs.get(name).map(String::as_str)
    }

    /// Every (name, value) pair, in no particular order.
    pub fn pairs(&self) -> impl Iterator<Item = (&str, &str)> {
        self.pairs.iter().map(|(k, v)| (k.as_str(), v.as_str()))
    }

    /// An integer in `min..=max`, or `default` when absent.
    pub fn int<T>(&self, name: &str, default: T, min: T, max: T) -> Result<T, ApiError>
    where
        T: FromStr + PartialOrd + Copy + std::fmt::Display,
    {
        match self.raw(name) {
            None => Ok(default),
            Some(s) => parse_int(name, s, min, max),
        }
    }

    /// A vector of three finite numbers written `x,y,z`, or `default`.
    pub fn vec3(&self, name: &str, default: [f64; 3]) -> Result<[f64; 3], ApiError> {
        match self.raw(name) {
            None => Ok(default),
            Some(s) => parse_vec3(name, s),
        }
    }
}

/// Parses an integer parameter and checks its range.
pub fn parse_int<T>(name: &str, s: &str, min: T, max: T) -> Result<T, ApiError>
where
    T: FromStr + PartialOrd + Copy + std::fmt::Display,
{
    let v: T = s.trim().parse().map_err(|_| {
        if !s.is_empty()
            && s.trim()
                .trim_start_matches(['-', '+'])
                .bytes()
                .all(|b| b.is_ascii_digit())
        {
            ApiError::out_of_range(name, s, min, max)
        } else {
            ApiError::invalid_parameter(name, format_args!("`{s}` is not an integer"))
        }
    })?;
    if v < min || v > max {
        return Err(ApiError::out_of_range(name, v, min, max));
    }
    Ok(v)
}

/// Parses `x,y,z` into three finite numbers.
pub fn parse_vec3(name: &str, s: &str) -> Result<[f64; 3], ApiError> {
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != 3 {
        return Err(ApiError::invalid_parameter(
            name,
            format_args!("`{s}` is not three comma-separated numbers"),
        ));
    }
    let mut out = [0.0; 3];
    for (o, p) in out.iter_mut().zip(parts) {
        let v: f64 = p.trim().parse().map_err(|_| {
            ApiError::invalid_parameter(name, format_args!("`{p}` is not a number"))
        })?;
        if !v.is_finite() {
            return Err(ApiError::invalid_parameter(
                name,
                "components must be finite",
            ));
        }
        *o = v;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ints() {
        let q = Query::parse(Some("a=5&b=-7&c=x&d=99999999999999999999999")).unwrap();
        assert_eq!(q.int("a", 0i64, -10, 10).unwrap(), 5);
        assert_eq!(q.int("b", 0i64, -10, 10).unwrap(), -7);
        assert_eq!(q.int("missing", 3i64, -10, 10).unwrap(), 3);
        assert_eq!(
            q.int("c", 0i64, -10, 10).unwrap_err().code,
            "invalid_parameter"
        );
        assert_eq!(
            q.int("d", 0i64, i64::MIN, i64::MAX).unwrap_err().code,
            "out_of_range"
        );
        assert_eq!(q.int("a", 0u32, 6, 10).unwrap_err().code, "out_of_range");
        assert_eq!(q.int("b", 0u32, 0, 10).unwrap_err().code, "out_of_range");
    }

    #[test]
    fn duplicates_rejected() {
        assert_eq!(
            Query::parse(Some("a=1&a=2")).unwrap_err().code,
            "invalid_parameter"
        );
    }

    #[test]
    fn vectors() {
        let q = Query::parse(Some("o=1,2.5,-3&bad=1,2&nan=1,NaN,2&enc=1%2C2%2C3")).unwrap();
        assert_eq!(q.vec3("o", [0.0; 3]).unwrap(), [1.0, 2.5, -3.0]);
        assert_eq!(q.vec3("enc", [0.0; 3]).unwrap(), [1.0, 2.0, 3.0]);
        assert_eq!(q.vec3("none", [1.0, 0.0, 0.0]).unwrap(), [1.0, 0.0, 0.0]);
        assert!(q.vec3("bad", [0.0; 3]).is_err());
        assert!(q.vec3("nan", [0.0; 3]).is_err());
    }
}
