//! The `deog` binary as cargo builds it for this package's tests: it
//! names its version, and every subcommand its help lists shows a help of
//! its own. Building it here also builds it with the features the whole
//! workspace's tests unify, the build `deog-tests` then finds fresh.

use std::process::{Command, Output};

fn deog(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_deog"))
        .args(args)
        .output()
        .expect("deog runs")
}

fn stdout_of(args: &[&str]) -> String {
    let output = deog(args);
    assert!(
        output.status.success(),
        "deog {args:?} failed:\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8_lossy(&output.stdout).into_owned()
}

#[test]
fn the_version_is_the_packages() {
    assert_eq!(
        stdout_of(&["--version"]).trim(),
        format!("deog {}", env!("CARGO_PKG_VERSION"))
    );
}

#[test]
fn every_subcommand_the_help_lists_has_a_help_of_its_own() {
    let help = stdout_of(&["--help"]);
    let commands: Vec<&str> = help
        .lines()
        .skip_while(|line| *line != "Commands:")
        .skip(1)
        .take_while(|line| !line.trim().is_empty())
        .filter_map(|line| line.split_whitespace().next())
        .filter(|name| *name != "help")
        .collect();
    for expected in ["demo", "server", "sim", "map", "localize", "bench", "view"] {
        assert!(commands.contains(&expected), "{expected} in {commands:?}");
    }
    for command in commands {
        let own = stdout_of(&[command, "--help"]);
        assert!(
            own.contains(&format!("Usage: deog {command}")),
            "{command}:\n{own}"
        );
    }
}
