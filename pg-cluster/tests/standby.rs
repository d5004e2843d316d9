//! Streaming standbys of a real server, and failover to them.

use deog_pg_cluster::{ClusterOptions, LocalCluster, Replication};

#[test]
fn a_promoted_synchronous_standby_has_every_commit_and_takes_writes() -> anyhow::Result<()> {
    let mut primary = LocalCluster::start()?;
    let standby = primary.start_standby(Replication::Synchronous)?;
    assert_ne!(standby.port(), primary.port());
    assert!(!primary.is_standby()?);
    assert!(standby.is_standby()?);
    assert_eq!(
        primary.psql("postgres", "SELECT sync_state FROM pg_stat_replication")?,
        "sync"
    );

    // Made after the standby: it replicates all the same.
    primary.create_database("maps")?;
    primary.psql("maps", "CREATE TABLE t (n int PRIMARY KEY)")?;
    primary.psql("maps", "INSERT INTO t SELECT generate_series(1, 100)")?;
    // Synchronous commit waits for the standby's flush, not its replay;
    // replay follows at once.
    let mut seen = String::new();
    for _ in 0..200 {
        seen = standby
            .psql("maps", "SELECT count(*) FROM t")
            .unwrap_or_default();
        if seen == "100" {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(25));
    }
    assert_eq!(seen, "100");
    assert!(
        standby.psql("maps", "INSERT INTO t VALUES (0)").is_err(),
        "a standby refuses writes"
    );

    primary.kill()?;
    standby.promote()?;
    assert!(!standby.is_standby()?);
    assert_eq!(standby.psql("maps", "SELECT count(*) FROM t")?, "100");
    // The promoted server has no synchronous standby to wait for.
    standby.psql("maps", "INSERT INTO t VALUES (101)")?;
    assert_eq!(standby.psql("maps", "SELECT max(n) FROM t")?, "101");
    Ok(())
}

#[test]
fn an_asynchronous_standby_follows_and_is_removed_with_its_primary() -> anyhow::Result<()> {
    let options = ClusterOptions {
        fsync: false,
        ..ClusterOptions::default()
    };
    let primary = LocalCluster::start_with(&options)?;
    let standby = primary.start_standby(Replication::Asynchronous)?;
    assert_eq!(
        primary.psql("postgres", "SELECT sync_state FROM pg_stat_replication")?,
        "async"
    );
    assert_eq!(standby.psql("postgres", "SHOW fsync")?, "off");
    let data_dir = standby.data_dir().to_path_buf();
    assert!(data_dir.join("standby.signal").is_file());
    drop(standby);
    drop(primary);
    assert!(!data_dir.exists(), "{} is left behind", data_dir.display());
    Ok(())
}
