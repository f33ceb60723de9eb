//! Records the git commit the binary is built from (`EMBODIED_GIT_COMMIT`, "unknown" without git
//! or outside a repository), for `--version`, log headers, plan files and reports.

use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    let out = Command::new("git").args(args).output().ok()?;
    let text = String::from_utf8(out.stdout).ok()?;
    let text = text.trim();
    (out.status.success() && !text.is_empty()).then(|| text.to_string())
}

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    let commit = git(&["rev-parse", "--short=12", "HEAD"]).unwrap_or_else(|| "unknown".to_string());
    println!("cargo:rustc-env=EMBODIED_GIT_COMMIT={commit}");
    // Build again when HEAD moves: the HEAD file, the branch it points to, packed refs.
    if let Some(head) = git(&["rev-parse", "--git-path", "HEAD"]) {
        println!("cargo:rerun-if-changed={head}");
    }
    if let Some(branch) = git(&["symbolic-ref", "-q", "HEAD"])
        && let Some(reference) = git(&["rev-parse", "--git-path", &branch])
        && std::path::Path::new(&reference).exists()
    {
        println!("cargo:rerun-if-changed={reference}");
    }
    if let Some(packed) = git(&["rev-parse", "--git-path", "packed-refs"])
        && std::path::Path::new(&packed).exists()
    {
        println!("cargo:rerun-if-changed={packed}");
    }
}
