//! `deog completions` and `deog man` through the real binary: the scripts
//! name the subcommands, and the pages are written one per command.

use deog_tests::{failure, run_deog, succeeded};

#[test]
fn completion_scripts_name_the_subcommands() {
    for shell in ["bash", "zsh", "fish"] {
        let script = succeeded(&run_deog(&["completions", shell], &[]));
        for subcommand in ["server", "localize", "status", "completions"] {
            assert!(
                script.contains(subcommand),
                "{shell} script lacks {subcommand}"
            );
        }
    }
    let bash = succeeded(&run_deog(&["completions", "bash"], &[]));
    assert!(bash.contains("complete -F _deog"), "{bash}");
    assert!(
        bash.contains("--interval-s"),
        "status options are completed"
    );
}

#[test]
fn an_unknown_shell_is_refused() {
    let stderr = failure(&run_deog(&["completions", "tcsh"], &[]));
    assert!(stderr.contains("tcsh"), "{stderr}");
}

#[test]
fn man_writes_a_page_for_deog_and_each_subcommand() {
    let out = tempfile::tempdir().expect("temp dir");
    let folder = out.path().join("man1");
    succeeded(&run_deog(
        &["man", "--out", folder.to_str().expect("utf-8 path")],
        &[],
    ));
    for page in [
        "deog.1",
        "deog-server.1",
        "deog-status.1",
        "deog-eval-map.1",
    ] {
        let text =
            std::fs::read_to_string(folder.join(page)).unwrap_or_else(|e| panic!("{page}: {e}"));
        assert!(text.contains(".TH"), "{page}: {text}");
    }
    let server = std::fs::read_to_string(folder.join("deog-server.1")).expect("page");
    assert!(
        server.contains("listen"),
        "the server's page lists its options"
    );
}

#[test]
fn man_reports_a_folder_it_cannot_write() {
    let out = tempfile::tempdir().expect("temp dir");
    let file = out.path().join("a-file");
    std::fs::write(&file, "").expect("write");
    let stderr = failure(&run_deog(
        &["man", "--out", file.to_str().expect("utf-8 path")],
        &[],
    ));
    assert!(stderr.contains("a-file"), "{stderr}");
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
}
