//! Something kept for the next call behind a mutex, for types shared by the
//! solver's threads (`&self` methods).

/// Something kept for the next call, behind a mutex. A clone starts empty:
/// what it held belongs to the original (the positions it last saw, the
/// scratch it lends).
pub(crate) struct Cache<T>(std::sync::Mutex<Option<T>>);

impl<T> Cache<T> {
    /// The guarded value; a panic elsewhere while it was held leaves it as
    /// it was (each user overwrites or validates what it finds).
    pub(crate) fn lock(&self) -> std::sync::MutexGuard<'_, Option<T>> {
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Takes what is kept, leaving it empty.
    pub(crate) fn take(&self) -> Option<T> {
        self.lock().take()
    }

    /// Keeps `value` (replacing what was kept).
    pub(crate) fn put(&self, value: T) {
        *self.lock() = Some(value);
    }
}

impl<T> Default for Cache<T> {
    fn default() -> Self {
        Self(std::sync::Mutex::new(None))
    }
}

impl<T> Clone for Cache<T> {
    fn clone(&self) -> Self {
        Self::default()
    }
}

impl<T> std::fmt::Debug for Cache<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Cache")
    }
}
