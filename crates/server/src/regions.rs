//! Region textures: two stored textures sharing space across a region
//! (Zhang et al. 2011, Fig. 15; [`solidtex_core::region`]). A region
//! texture is a small definition — outer id, inner id, region, band —
//! kept beside the textures in the [`Storage`] (`regions/ID.json`), so it
//! survives a restart and every replica of a shared store reads it. Each
//! solid keeps synthesizing lazily with its own tiles; nothing is
//! precomputed for the composition.
//!
//! Its id hashes the canonical JSON of the definition, so the same
//! definition is the same texture anywhere. A texture a region texture
//! uses cannot be deleted while it is used (409, naming the users).

use crate::spec::hex;
use crate::store::Storage;
use parking_lot::RwLock;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use solidtex_core::region::{Shape, Split};
use std::collections::HashMap;
use std::io;
use std::sync::Arc;

/// What names a region texture: the prefix of every region texture's id
/// (a content id is hex digits alone).
pub(crate) const ID_PREFIX: &str = "region-";

/// A region texture's definition, as posted and as stored.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RegionDef {
    /// The texture outside the region.
    pub outer: String,
    /// The texture inside it.
    pub inner: String,
    /// The region (voxels of level of detail 0).
    pub region: Shape,
    /// Width of the transition band (0: a hard boundary).
    #[serde(default)]
    pub band: f64,
}

impl RegionDef {
    /// The region and band, checked.
    pub fn split(&self) -> Split {
        Split {
            region: self.region.clone(),
            band: self.band,
        }
    }

    /// The definition as canonical JSON: fields in one order, numbers in
    /// their shortest exact form, −0 written as 0.
    pub fn canonical(&self) -> String {
        let mut v = serde_json::to_value(self).unwrap_or_default();
        positive_zeros(&mut v);
        v.to_string()
    }

    /// Its id: [`ID_PREFIX`] and 32 hex digits of the canonical JSON's hash.
    pub fn id(&self) -> String {
        let h = Sha256::digest(format!("solidtex region v1\0{}", self.canonical()).as_bytes());
        format!("{ID_PREFIX}{}", hex(&h[..16]))
    }

    /// What its answers depend on: the content of the two textures (an id
    /// such as `default` names other content in another version) and the
    /// region.
    pub fn content_hash(&self, outer: &str, inner: &str) -> String {
        let mut h = Sha256::new();
        for part in [
            "solidtex region content v1",
            outer,
            inner,
            &self.canonical(),
        ] {
            h.update(part.as_bytes());
            h.update(b"\0");
        }
        hex(&h.finalize()[..16])
    }
}

/// Turns every −0 in `v` into 0 (one spelling per number).
fn positive_zeros(v: &mut serde_json::Value) {
    match v {
        serde_json::Value::Number(n) if n.as_f64() == Some(0.0) => *v = 0.into(),
        serde_json::Value::Array(a) => a.iter_mut().for_each(positive_zeros),
        serde_json::Value::Object(o) => o.values_mut().for_each(positive_zeros),
        _ => {}
    }
}

/// A stored region texture.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct Stored {
    /// Its id.
    pub id: String,
    /// Creation time, seconds since the Unix epoch.
    pub created: u64,
    /// What it is made of.
    #[serde(flatten)]
    pub def: RegionDef,
}

/// The region textures of a server. Definitions never change under an
/// id, so those read once are kept in memory; the storage is the truth
/// for which exist. Every method blocks (it may read the storage).
pub(crate) struct Regions {
    store: Arc<dyn Storage>,
    known: RwLock<HashMap<String, Stored>>,
}

impl Regions {
    /// The region textures kept in `store`.
    pub fn new(store: Arc<dyn Storage>) -> Regions {
        Regions {
            store,
            known: RwLock::new(HashMap::new()),
        }
    }

    /// Region texture `id`, when it exists.
    pub fn get(&self, id: &str) -> io::Result<Option<Stored>> {
        if !id.starts_with(ID_PREFIX) {
            return Ok(None);
        }
        if let Some(s) = self.known.read().get(id) {
            return Ok(Some(s.clone()));
        }
        let Some(bytes) = self.store.read_region(id)? else {
            return Ok(None);
        };
        let stored: Stored = serde_json::from_slice(&bytes).map_err(|e| {
            io::Error::new(
                io::ErrorKind::InvalidData,
                format!("region texture `{id}`: {e}"),
            )
        })?;
        if stored.id != id || stored.def.id() != id {
            return Err(io::Error::new(
                io::ErrorKind::InvalidData,
                format!("region texture `{id}`: its definition has another id"),
            ));
        }
        self.known.write().insert(id.to_string(), stored.clone());
        Ok(Some(stored))
    }

    /// Stores `def` (created now), or finds it stored: true when new.
    pub fn create(&self, def: RegionDef, created: u64) -> io::Result<(Stored, bool)> {
        let id = def.id();
        if let Some(s) = self.get(&id)? {
            return Ok((s, false));
        }
        let stored = Stored { id, created, def };
        let json = serde_json::to_vec_pretty(&stored).map_err(io::Error::other)?;
        self.store.write_region(&stored.id, &json)?;
        self.known.write().insert(stored.id.clone(), stored.clone());
        Ok((stored, true))
    }

    /// Every region texture stored, oldest first.
    pub fn list(&self) -> io::Result<Vec<Stored>> {
        let mut all = Vec::new();
        for id in self.store.region_ids()? {
            match self.get(&id) {
                Ok(Some(s)) => all.push(s),
                Ok(None) => {}
                Err(e) => tracing::warn!(id, error = %e, "skipping an unreadable region texture"),
            }
        }
        // Deleted elsewhere (another replica): forgotten here too.
        self.known
            .write()
            .retain(|id, _| all.iter().any(|s| &s.id == id));
        all.sort_by(|a, b| (a.created, &a.id).cmp(&(b.created, &b.id)));
        Ok(all)
    }

    /// The region textures made of texture `id` (as outer or inner).
    pub fn users_of(&self, id: &str) -> io::Result<Vec<String>> {
        Ok(self
            .list()?
            .into_iter()
            .filter(|s| s.def.outer == id || s.def.inner == id)
            .map(|s| s.id)
            .collect())
    }

    /// Removes region texture `id`: false when there was none.
    pub fn remove(&self, id: &str) -> io::Result<bool> {
        if self.get(id)?.is_none() {
            return Ok(false);
        }
        self.store.remove_region(id)?;
        self.known.write().remove(id);
        Ok(true)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn def(json: &str) -> RegionDef {
        serde_json::from_str(json).unwrap()
    }

    #[test]
    fn the_id_depends_on_the_definition_not_its_spelling() {
        let a = def(
            r#"{"outer":"a","inner":"b","band":4,"region":{"shape":"sphere","centre":[0,-0.0,1],"radius":8}}"#,
        );
        let b = def(
            r#"{"region":{"radius":8.0,"centre":[0.0,0,1e0],"shape":"sphere"},"inner":"b","outer":"a","band":4.0}"#,
        );
        assert_eq!(a.id(), b.id());
        assert!(a.id().starts_with(ID_PREFIX));
        assert!(crate::spec::valid_id(&a.id()));
        let c = def(
            r#"{"outer":"b","inner":"a","band":4,"region":{"shape":"sphere","centre":[0,0,1],"radius":8}}"#,
        );
        assert_ne!(a.id(), c.id());
        // Pinned: the id is stable across builds and replicas.
        assert_eq!(
            a.canonical(),
            r#"{"band":4.0,"inner":"b","outer":"a","region":{"centre":[0,0,1.0],"radius":8.0,"shape":"sphere"}}"#
        );
    }

    #[test]
    fn unknown_fields_are_refused() {
        assert!(
            serde_json::from_str::<RegionDef>(
                r#"{"outer":"a","inner":"b","region":{"shape":"shell","thickness":2},"x":1}"#
            )
            .is_err()
        );
    }
}
