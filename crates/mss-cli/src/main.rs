//! The `mss` binary: everything lives in the `mss_cli` library.

fn main() -> std::process::ExitCode {
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
