//! Helpers shared by the end-to-end test files (each file uses some of them).
#![allow(dead_code)]

use std::path::PathBuf;
use std::process::Command;

/// Run the `embodied` binary: exit code, stdout, stderr.
pub fn embodied(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_embodied")).args(args).output().expect("binary runs");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A path `name` in this test file's own temporary folder (one per test binary and process).
pub fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("embodied-{}-{}", env!("CARGO_CRATE_NAME"), std::process::id()));
    std::fs::create_dir_all(&dir).expect("temporary folder");
    dir.join(name)
}
