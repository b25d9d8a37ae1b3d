//! Helpers for the end-to-end tests in `tests/tests/`: they start the real programs, built by cargo.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

/// The repository's root folder.
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("tests/ lives in the repository").to_path_buf()
}

/// Path of a workspace binary, built once per test process by the cargo that runs the tests, with the profile
/// the tests were built with. `--workspace --bins --tests` resolves the features as `cargo test --workspace`
/// does (dev-dependencies included), so after scripts/test's build this only links the programs: no
/// dependency is built a second time.
pub fn binary(name: &str) -> PathBuf {
    static PROFILE_DIR: OnceLock<PathBuf> = OnceLock::new();
    let dir = PROFILE_DIR.get_or_init(|| {
        // A test program lives in <target dir>/<profile dir>/deps/: `release` for `cargo test --release`,
        // `debug` for the test profile.
        let exe = std::env::current_exe().expect("the test program's own path");
        let profile_dir = exe.parent().and_then(Path::parent).expect("a test program lives in <profile dir>/deps");
        let profile = if profile_dir.ends_with("release") { "release" } else { "test" };
        let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
        let status = Command::new(cargo)
            .args(["build", "--quiet", "--profile", profile, "--workspace", "--bins", "--tests"])
            .current_dir(repo_root())
            .status()
            .expect("cannot run cargo to build the programs under test");
        assert!(status.success(), "building the programs under test failed");
        profile_dir.to_path_buf()
    });
    dir.join(name)
}

/// A fresh, empty folder for one test's outputs.
pub fn scratch_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("photonfarm-e2e-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("cannot create a scratch folder");
    dir
}

/// The shipped Cornell box at `size` × `size` pixels, copied with its meshes into `dir`: a scene the tests can
/// resize without touching `scenes/`.
pub fn cornell_at(dir: &Path, size: u32) -> PathBuf {
    let root = repo_root().join("scenes");
    let text = std::fs::read_to_string(root.join("cornell.toml")).expect("scenes/cornell.toml");
    let text =
        text.replace("width = 256", &format!("width = {size}")).replace("height = 256", &format!("height = {size}"));
    std::fs::create_dir_all(dir.join("cornell")).expect("cannot create the scene folder");
    for e in std::fs::read_dir(root.join("cornell")).expect("scenes/cornell/") {
        let e = e.expect("a mesh of scenes/cornell/");
        std::fs::copy(e.path(), dir.join("cornell").join(e.file_name())).expect("cannot copy a mesh");
    }
    let path = dir.join("cornell.toml");
    std::fs::write(&path, text).expect("cannot write the scene");
    path
}

/// Runs `coordinator render SCENE --out OUT --quiet ARGS…` from the repository root and returns its output.
pub fn render_output(scene: &Path, out: &Path, args: &[&str]) -> Output {
    Command::new(binary("coordinator"))
        .arg("render")
        .arg(scene)
        .arg("--out")
        .arg(out)
        .arg("--quiet")
        .args(args)
        .current_dir(repo_root())
        .output()
        .expect("cannot start the coordinator")
}
