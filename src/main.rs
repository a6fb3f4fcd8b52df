//! The `geodex` binary: see [`geodex::cli`].

fn main() -> std::process::ExitCode {
    geodex::cli::main()
}
