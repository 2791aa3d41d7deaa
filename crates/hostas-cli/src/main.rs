fn main() -> std::process::ExitCode {
    hostas_cli::cli::main()
}
