//! What the command-line tests share: running the `unacorda` binary and reading what it says.

use std::process::Command;

/// Run `unacorda args`; its exit status and standard error, both printed. It must not panic.
pub fn cli(args: &[&str]) -> (Option<i32>, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_unacorda"))
        .args(args)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    println!(
        "unacorda {}\n  → exit {:?}: {}",
        args.join(" "),
        out.status.code(),
        stderr.trim()
    );
    assert!(!stderr.contains("panicked"), "the CLI must not panic");
    (out.status.code(), stderr)
}
