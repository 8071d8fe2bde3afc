//! One registry style for every plug point of the workspace: [`Named`], an
//! ordered list of entries by name, where registering a name again
//! replaces its entry (so a program overrides a built-in by registering
//! under its name) and lookups fail with the list of known names.
//!
//! An entry is whatever the plug point needs: a factory, plus the facts a
//! caller asks about without building it (whether an integrator is
//! explicit, which file extension an exporter writes). No name list lives
//! outside the registry that holds the entries.
//!
//! Why a crate of its own: the registries live in crates that do not
//! depend on each other (`mss-core`'s integrators, `mss-io`'s exporters,
//! `mss-scene`'s obstacle shapes), and this one depends on nothing.
//!
//! ```
//! use mss_registry::Named;
//!
//! let mut shapes: Named<f64> = Named::new();
//! shapes.register("unit", 1.0);
//! shapes.register("half", 0.5);
//! shapes.register("unit", 2.0); // replaces, keeps the order
//! assert_eq!(shapes.get("unit"), Some(&2.0));
//! assert_eq!(shapes.names(), ["unit", "half"]);
//! let err = shapes.lookup("quarter").unwrap_err();
//! assert_eq!(err.to_string(), "unknown name \"quarter\"; known: unit, half");
//! ```

#![warn(missing_docs)]

use std::fmt;

/// Entries of type `T` by name, in registration order.
#[derive(Clone)]
pub struct Named<T> {
    entries: Vec<(String, T)>,
}

impl<T> Default for Named<T> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T> fmt::Debug for Named<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_list()
            .entries(self.entries.iter().map(|(n, _)| n))
            .finish()
    }
}

/// A name that no entry has.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnknownName {
    /// The name asked for.
    pub name: String,
    /// The registered names, comma separated.
    pub known: String,
}

impl fmt::Display for UnknownName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "unknown name {:?}; known: {}", self.name, self.known)
    }
}

impl std::error::Error for UnknownName {}

impl<T> Named<T> {
    /// An empty registry.
    pub fn new() -> Self {
        Self {
            entries: Vec::new(),
        }
    }

    /// Registers `entry` as `name`; an entry already called so is replaced
    /// in place.
    pub fn register(&mut self, name: impl Into<String>, entry: T) {
        let name = name.into();
        match self.entries.iter_mut().find(|(n, _)| *n == name) {
            Some(slot) => slot.1 = entry,
            None => self.entries.push((name, entry)),
        }
    }

    /// The entry called `name`.
    pub fn get(&self, name: &str) -> Option<&T> {
        self.entries.iter().find(|(n, _)| n == name).map(|(_, e)| e)
    }

    /// The entry called `name`, or an error listing the known names.
    pub fn lookup(&self, name: &str) -> Result<&T, UnknownName> {
        self.get(name).ok_or_else(|| UnknownName {
            name: name.to_owned(),
            known: self.names().join(", "),
        })
    }

    /// Whether an entry is called `name`.
    pub fn contains(&self, name: &str) -> bool {
        self.get(name).is_some()
    }

    /// The names, in registration order.
    pub fn names(&self) -> Vec<String> {
        self.entries.iter().map(|(n, _)| n.clone()).collect()
    }

    /// The entries and their names, in registration order.
    pub fn iter(&self) -> impl Iterator<Item = (&str, &T)> {
        self.entries.iter().map(|(n, e)| (n.as_str(), e))
    }

    /// The number of entries.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether there is no entry.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_registration_replaces_in_place() {
        let mut r = Named::new();
        r.register("a", 1);
        r.register("b", 2);
        r.register("a", 3);
        assert_eq!(r.iter().collect::<Vec<_>>(), [("a", &3), ("b", &2)]);
        assert_eq!(r.len(), 2);
        assert!(!r.is_empty() && r.contains("b") && !r.contains("c"));
    }
}
