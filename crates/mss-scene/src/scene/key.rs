//! The error of a table's own check, which each front end names its way.

/// A key of a scene table with a bad value, found by the table's own check;
/// the front end names the key its way (`[voxelize] cells` in a scene,
/// `--cells` on the command line, `cells=` in Python).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct KeyError {
    /// The key as the table spells it (empty: the table as a whole).
    pub key: &'static str,
    /// What is wrong with its value, starting with the value (`= 0; ...`).
    pub message: String,
}

impl KeyError {
    /// The key as a scene file names it inside `table` (`"[voxelize] cells"`).
    pub fn scene_key(&self, table: &str) -> String {
        if self.key.is_empty() {
            table.to_owned()
        } else {
            format!("{table} {}", self.key)
        }
    }
}
