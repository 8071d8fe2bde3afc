//! # mss-cli (skeleton)

/// Entry point of the `mss` binary.
pub fn run() -> anyhow::Result<()> {
    Ok(())
}
