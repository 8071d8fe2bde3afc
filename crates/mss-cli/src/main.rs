//! The `mss` binary: everything lives in the `mss_cli` library.

fn main() -> std::process::ExitCode {
    keep_freed_memory();
    match mss_cli::run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            if !mss_cli::is_broken_pipe(&e) {
                use std::io::Write;
                // A full or closed standard error has nowhere to say so:
                // the exit code still tells.
                let _ = writeln!(std::io::stderr(), "{}", mss_cli::error_report(&e));
            }
            std::process::ExitCode::from(mss_cli::exit_code(&e))
        }
    }
}

/// glibc gives blocks above 128 KiB back to the system when they are freed,
/// so the sparse factorizations of an implicit run (megabytes, made and
/// dropped at every Newton iteration) were page-faulted in afresh each time:
/// 688,000 page faults and 1.1 s of system time against 1.9 s of user time
/// for a 512-cell cube landing on the ground. Up to 64 MiB a block stays in
/// the heap, and up to 512 MiB of free heap is kept for the next one.
fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets allocator parameters; called before any
    // other thread exists.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 64 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 512 << 20);
    }
}
