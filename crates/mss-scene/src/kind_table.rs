//! [`KindTable`]: a scene table whose `kind` names an entry of a registry
//! (an obstacle shape, a load, a region selector), the entry's factory
//! reading the table's other keys.
//!
//! The built-ins are registered the same way a program registers its own,
//! so a scene names both alike and a program can replace a built-in.
//!
//! ```
//! use mss_scene::kind_table::KindTable;
//!
//! #[derive(Debug, serde::Deserialize)]
//! #[serde(deny_unknown_fields)]
//! struct Wind {
//!     speed: f64,
//! }
//!
//! let table: KindTable = toml::from_str("kind = \"wind\"\nspeed = 3.0\n").unwrap();
//! assert_eq!(table.kind, "wind");
//! assert_eq!(table.keys_as::<Wind>().unwrap().speed, 3.0);
//! let typo: KindTable = toml::from_str("kind = \"wind\"\nsped = 3.0\n").unwrap();
//! let err = typo.keys_as::<Wind>().unwrap_err().to_string();
//! assert!(err.starts_with("kind \"wind\": unknown field `sped`"), "{err}");
//! ```

use serde::Deserialize;

/// A table with a `kind` name and the other keys, kept as TOML until the
/// factory registered under `kind` reads them ([`KindTable::keys_as`]).
#[derive(Debug, Clone, PartialEq)]
pub struct KindTable {
    /// The entry's name in its registry.
    pub kind: String,
    /// The table's other keys.
    pub keys: toml::Table,
}

/// A [`KindTable`]'s keys that its factory could not read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("kind {kind:?}: {message}")]
pub struct KindKeysError {
    /// The table's kind.
    pub kind: String,
    /// Serde's message (an unknown or missing key, a wrong type).
    pub message: String,
}

impl<'de> Deserialize<'de> for KindTable {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let mut keys = toml::Table::deserialize(d)?;
        match keys.remove("kind") {
            Some(toml::Value::String(kind)) if !kind.trim().is_empty() => {
                Ok(KindTable { kind, keys })
            }
            Some(toml::Value::String(_)) => Err(serde::de::Error::custom(
                "kind is empty; give the name of a registered kind",
            )),
            Some(other) => Err(serde::de::Error::custom(format!(
                "kind = {other}: a kind is a name (a string)"
            ))),
            None => Err(serde::de::Error::missing_field("kind")),
        }
    }
}

impl KindTable {
    /// A table of `kind` with no other key.
    pub fn new(kind: &str) -> KindTable {
        KindTable {
            kind: kind.to_owned(),
            keys: toml::Table::new(),
        }
    }

    /// The other keys read as `T` (a factory's own table type, usually with
    /// `deny_unknown_fields`), with serde's message on a bad key.
    pub fn keys_as<T: serde::de::DeserializeOwned>(&self) -> Result<T, KindKeysError> {
        toml::Value::Table(self.keys.clone())
            .try_into()
            .map_err(|e: toml::de::Error| self.error(e.message().trim().to_owned()))
    }

    /// The whole table, `kind` included, read as `T` (an internally tagged
    /// enum of built-ins).
    pub fn tagged_as<T: serde::de::DeserializeOwned>(&self) -> Result<T, KindKeysError> {
        let mut table = self.keys.clone();
        table.insert("kind".into(), toml::Value::String(self.kind.clone()));
        toml::Value::Table(table)
            .try_into()
            .map_err(|e: toml::de::Error| self.error(e.message().trim().to_owned()))
    }

    /// An error about this table.
    pub fn error(&self, message: String) -> KindKeysError {
        KindKeysError {
            kind: self.kind.clone(),
            message,
        }
    }
}
