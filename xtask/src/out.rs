//! What a command prints as its answer: [`outln!`] and the one writer behind it. A leaf
//! module: it imports nothing of xtask.

/// `println!` for what a command prints as its answer. Rust ignores `SIGPIPE`, so a plain
/// `println!` panics when the reader has gone (`cargo xtask mesh info F | head -3`); this
/// ends the process quietly instead, as a Unix tool killed by `SIGPIPE` would.
macro_rules! outln {
    ($($arg:tt)*) => {
        $crate::out::write_stdout(format_args!($($arg)*))
    };
}

/// Writes one line to standard output (see [`outln`]): a closed pipe ends the process
/// with status 0, any other write error with status 1 after saying so.
pub(crate) fn write_stdout(line: std::fmt::Arguments<'_>) {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    let written = out
        .write_fmt(line)
        .and_then(|()| out.write_all(b"\n"))
        .and_then(|()| out.flush());
    match written {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => std::process::exit(0),
        Err(e) => {
            eprintln!("error: writing to standard output: {e}");
            std::process::exit(1);
        }
    }
}
