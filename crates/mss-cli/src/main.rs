//! The `mss` binary: everything lives in the `mss_cli` library.

fn main() -> std::process::ExitCode {
    match mss_cli::run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{}", mss_cli::error_report(&e));
            std::process::ExitCode::from(mss_cli::exit_code(&e))
        }
    }
}
