use clap::Parser;
use zwidth::cli::{run, Cli};

fn main() {
    // clap exits with code 2 on usage errors and prints the usage line.
    let cli = Cli::parse();
    let stdin = std::io::stdin().lock();
    let mut stdout = std::io::stdout().lock();
    if let Err(e) = run(cli, stdin, &mut stdout) {
        eprintln!("error: {e}");
        std::process::exit(e.exit_code());
    }
}
