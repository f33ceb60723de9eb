//! Helpers shared by the end-to-end test files (each file uses some of them): the system crate's
//! test helpers (temporary folders and files), and the `embodied` binary.
#![allow(dead_code)]

use std::process::Command;

#[path = "../../system/tests/common/mod.rs"]
mod shared;
pub use shared::*;

/// Run the `embodied` binary: exit code, stdout, stderr.
pub fn embodied(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_embodied")).args(args).output().expect("binary runs");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}
