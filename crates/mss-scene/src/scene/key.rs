//! The error of a table's own check, which each front end names its way.

/// A key of a scene table with a bad value, found by the table's own check;
/// the front end names the key its way (`[voxelize] cells` in a scene,
/// `--cells` on the command line, `cells=` in Python).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct KeyError {
    /// The key as the table spells it (empty: the table as a whole; an
    /// entry of a list of tables as `forces #2`).
    pub key: String,
    /// What is wrong with its value, starting with the value (`= 0; ...`).
    pub message: String,
}

impl KeyError {
    /// The key `key` has a bad value: `message` says what is wrong,
    /// starting with the value (`= 0; ...`).
    pub fn new(key: impl Into<String>, message: impl Into<String>) -> KeyError {
        KeyError {
            key: key.into(),
            message: message.into(),
        }
    }

    /// The same error, its key inside the list entry `entry` (`forces #2`).
    pub fn within(self, entry: &str) -> KeyError {
        let key = if self.key.is_empty() {
            entry.to_owned()
        } else {
            format!("{entry} {}", self.key)
        };
        KeyError { key, ..self }
    }

    /// The key as a scene file names it inside `table` (`"[voxelize] cells"`).
    pub fn scene_key(&self, table: &str) -> String {
        if self.key.is_empty() {
            table.to_owned()
        } else {
            format!("{table} {}", self.key)
        }
    }
}

/// A scene value given as text (a command-line flag, a Python keyword),
/// read exactly as the scene file reads it, so that every front end accepts
/// the same names (`"cm"`, `"largest"`, `"iterative"`) with the same
/// message for a bad one.
///
/// ```
/// use mss_scene::scene::{Units, value_from_str};
/// assert_eq!(value_from_str::<Units>("cm"), Ok(Units::Centimetres));
/// let err = value_from_str::<Units>("km").unwrap_err();
/// assert!(err.contains("expected one of `m`, `cm`, `mm`"), "{err}");
/// ```
pub fn value_from_str<T: serde::de::DeserializeOwned>(text: &str) -> Result<T, String> {
    use serde::de::IntoDeserializer;
    let value: serde::de::value::StrDeserializer<'_, serde::de::value::Error> =
        text.into_deserializer();
    T::deserialize(value).map_err(|e| e.to_string())
}
