//! The query string of an upload, whose parameters are texture parameters
//! (see [`crate::spec`]); a parameter given twice is a 400 naming it. The
//! other routes declare theirs as typed structs (`routes::params`).

use super::error::ApiError;
use std::collections::HashMap;

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
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn duplicates_rejected() {
        assert_eq!(
            Query::parse(Some("a=1&a=2")).unwrap_err().code,
            "invalid_parameter"
        );
    }
}
