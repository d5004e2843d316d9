//! `deog bench view`: the live view under load, in a real headless
//! Chromium. A map server, the simulator, `--robots` wanderers with their
//! cartographers and `deog view` run as processes of this binary; the page
//! is opened through ChromeDriver.
//!
//! Measured, in one run:
//! - the page's rendering rate (animation frames per second) and drawing
//!   time per frame, first on the idle page (no map, no robot: what this
//!   browser gives at all, the baseline), then with every robot driving
//!   and the map growing;
//! - how long after its acknowledgement a tile written through the server
//!   is drawn by the page (`--probes` tiles, one at a time, beside the
//!   map);
//! - the view process's memory (resident set sampled every 100 ms, and
//!   its peak `VmHWM`) and CPU.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use anyhow::{Context, Result, bail};
use clap::Args;
use deog_grid::{TileDelta, TileKey, TileSize};
use deog_harness::browser::Browser;
use deog_harness::progress::Progress;
use deog_harness::{Role, Supervisor, connect, free_loopback_addr, os, proc_stats};
use deog_robot_client::{ClientConfig, MapClient, UpdateSenderConfig};
use serde::Serialize;
use serde_json::{Value, json};

/// The map the cartographers build.
const MAP: &str = "bench";
/// Seconds the idle page is measured over.
const IDLE_S: f64 = 5.0;

/// Options of `deog bench view`.
#[derive(Debug, Clone, Args)]
pub struct ViewBenchOptions {
    /// Robots driving, each with its cartographer (1 to 8).
    #[arg(long, default_value_t = 8)]
    pub robots: u32,
    /// The world: a built-in name or a world file, as `deog sim` takes it.
    #[arg(long, default_value = "office")]
    pub world: String,
    /// Wall-clock seconds the loaded page's rendering is measured over.
    #[arg(long, default_value_t = 20.0)]
    pub seconds: f64,
    /// Wall-clock seconds the robots drive before measuring.
    #[arg(long, default_value_t = 10.0)]
    pub warmup_s: f64,
    /// Tiles written one at a time to time their way to the page.
    #[arg(long, default_value_t = 20)]
    pub probes: u32,
    /// Simulated seconds per wall-clock second.
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// The browser window, pixels (width x height).
    #[arg(long, default_value = "1280x800")]
    pub window: String,
    /// Also write the figures here as JSON.
    #[arg(long)]
    pub out_json: Option<PathBuf>,
    /// Also save a screenshot of the loaded page here (PNG).
    #[arg(long)]
    pub screenshot: Option<PathBuf>,
}

/// Rendering over one stretch of time, as the page measured it.
#[derive(Debug, Clone, Serialize)]
pub struct Rendering {
    /// Animation frames per second.
    pub fps: f64,
    /// Mean time to draw one frame, milliseconds.
    pub draw_ms_mean: f64,
    /// 95th percentile of the same.
    pub draw_ms_p95: f64,
}

/// Everything `deog bench view` measured.
#[derive(Debug, Clone, Serialize)]
pub struct ViewFigures {
    /// Robots driving.
    pub robots: u32,
    /// The world.
    pub world: String,
    /// The idle page: the baseline.
    pub idle: Rendering,
    /// The page with every robot driving.
    pub loaded: Rendering,
    /// Loaded fps over idle fps.
    pub fps_ratio: f64,
    /// Tiles on the page at the end of the loaded stretch.
    pub tiles: u64,
    /// Robot updates the page took in the loaded stretch, per second.
    pub robot_messages_per_s: f64,
    /// Milliseconds from each probe tile's acknowledgement to the page.
    pub tile_latency_ms: Vec<f64>,
    /// Median of the same.
    pub tile_latency_ms_median: f64,
    /// Largest of the same.
    pub tile_latency_ms_max: f64,
    /// The view process's largest resident set sampled, MiB.
    pub view_rss_mib_max: f64,
    /// Its peak resident set (`VmHWM`), MiB.
    pub view_hwm_mib: f64,
    /// Its CPU over the loaded stretch, percent of one core.
    pub view_cpu_percent: f64,
}

/// Runs `deog bench view`.
pub fn run(options: ViewBenchOptions) -> Result<()> {
    if !(1..=8).contains(&options.robots) {
        bail!("--robots must be 1 to 8, got {}", options.robots);
    }
    for (name, value) in [
        ("--seconds", options.seconds),
        ("--warmup-s", options.warmup_s),
        ("--speed", options.speed),
    ] {
        if !(value.is_finite() && value > 0.0 && value <= 3_600.0) {
            bail!("{name} must be above 0 and at most 3600, got {value}");
        }
    }
    let (width, height) = parse_window(&options.window)?;
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let figures = runtime.block_on(measure(&options, width, height))?;
    print!("{}", table(&figures));
    if let Some(path) = &options.out_json {
        std::fs::write(path, serde_json::to_string_pretty(&figures)? + "\n")
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

fn parse_window(text: &str) -> Result<(u32, u32)> {
    let parsed = text
        .split_once('x')
        .and_then(|(w, h)| Some((w.parse::<u32>().ok()?, h.parse::<u32>().ok()?)));
    match parsed {
        Some((w, h)) if (200..=4000).contains(&w) && (200..=4000).contains(&h) => Ok((w, h)),
        _ => bail!("--window takes WIDTHxHEIGHT, each 200 to 4000 pixels, got {text:?}"),
    }
}

async fn measure(options: &ViewBenchOptions, width: u32, height: u32) -> Result<ViewFigures> {
    let folder = tempfile::tempdir().context("a temporary folder")?;
    let mut children = Supervisor::new(&folder.path().join("logs"))?;
    let server_addr = free_loopback_addr()?;
    let sim_addr = free_loopback_addr()?;
    let view_addr = free_loopback_addr()?;
    let data = folder.path().join("server-data");
    let server_url = format!("http://{server_addr}");
    let sim_url = format!("http://{sim_addr}");
    children.start(
        "server",
        Role::Service,
        &os(&[
            "server",
            "--listen",
            &server_addr.to_string(),
            "--data",
            &data.to_string_lossy(),
        ]),
    )?;
    children.start(
        "sim",
        Role::Service,
        &os(&[
            "sim",
            "--world",
            &options.world,
            "--listen",
            &sim_addr.to_string(),
            "--speed",
            &options.speed.to_string(),
            "--seed",
            "1",
        ]),
    )?;
    let client = connect(&mut children, "map server", || {
        MapClient::connect(ClientConfig::new(server_url.clone()))
    })
    .await?;
    children.start(
        "view",
        Role::Service,
        &os(&[
            "view",
            "--listen",
            &view_addr.to_string(),
            "--map",
            MAP,
            "--server",
            &server_url,
            "--sim",
            &sim_url,
        ]),
    )?;
    wait_listening(&mut children, view_addr).await?;
    let view_pid = children.pid("view").context("the view's process")?;

    let browser = Browser::start(width, height)?;
    browser.goto(&format!("http://{view_addr}/"))?;
    let progress = Progress::new(
        "view bench",
        "s",
        (IDLE_S + options.warmup_s + options.seconds).ceil() as u64,
    );
    let begun = Instant::now();
    let idle = rendering_over(&browser, Duration::from_secs_f64(IDLE_S)).await?;
    progress.set_done(begun.elapsed().as_secs());

    for i in 1..=options.robots {
        let robot = format!("scout-{i}");
        children.start(
            &format!("wander-{robot}"),
            Role::Service,
            &os(&[
                "wander",
                "--robot",
                &robot,
                "--spawn",
                "--seed",
                &i.to_string(),
                "--duration",
                "100000",
                "--sim",
                &sim_url,
                "--server",
                &server_url,
            ]),
        )?;
        children.start(
            &format!("map-{robot}"),
            Role::Service,
            &os(&[
                "map",
                "--robot",
                &robot,
                "--map",
                MAP,
                "--server",
                &server_url,
            ]),
        )?;
    }
    pause(
        &mut children,
        Duration::from_secs_f64(options.warmup_s),
        &progress,
        begun,
    )
    .await?;

    let cpu_before = proc_stats::cpu_seconds(view_pid)?;
    let started = Instant::now();
    let messages_before = page_stats(&browser)?["robotMessages"]
        .as_f64()
        .unwrap_or(0.0);
    browser.eval("window.deogView.resetStats();", json!([]))?;
    let mut rss_max_kb = 0;
    while started.elapsed().as_secs_f64() < options.seconds {
        children.check()?;
        rss_max_kb = rss_max_kb.max(proc_stats::status_kb(view_pid, "VmRSS")?);
        progress.set_done(begun.elapsed().as_secs());
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    progress.finish();
    let elapsed = started.elapsed().as_secs_f64();
    let view_cpu_percent = 100.0 * (proc_stats::cpu_seconds(view_pid)? - cpu_before) / elapsed;
    let stats = page_stats(&browser)?;
    let loaded = rendering_of(&stats);
    let robot_messages_per_s =
        (stats["robotMessages"].as_f64().unwrap_or(0.0) - messages_before) / elapsed;
    let tiles = stats["tiles"].as_u64().unwrap_or(0);
    if let Some(path) = &options.screenshot {
        std::fs::write(path, browser.screenshot()?)
            .with_context(|| format!("writing {}", path.display()))?;
    }

    let tile_latency_ms = probe_tiles(&client, &browser, options.probes).await?;
    let view_hwm_kb = proc_stats::status_kb(view_pid, "VmHWM")?;
    children.check()?;
    drop(browser);
    children.stop_all();

    let mut sorted = tile_latency_ms.clone();
    sorted.sort_by(f64::total_cmp);
    Ok(ViewFigures {
        robots: options.robots,
        world: options.world.clone(),
        fps_ratio: if idle.fps > 0.0 {
            loaded.fps / idle.fps
        } else {
            0.0
        },
        idle,
        loaded,
        tiles,
        robot_messages_per_s,
        tile_latency_ms_median: sorted.get(sorted.len() / 2).copied().unwrap_or(0.0),
        tile_latency_ms_max: sorted.last().copied().unwrap_or(0.0),
        tile_latency_ms,
        view_rss_mib_max: rss_max_kb as f64 / 1024.0,
        view_hwm_mib: view_hwm_kb as f64 / 1024.0,
        view_cpu_percent,
    })
}

async fn wait_listening(children: &mut Supervisor, addr: SocketAddr) -> Result<()> {
    let deadline = Instant::now() + Duration::from_secs(30);
    while tokio::net::TcpStream::connect(addr).await.is_err() {
        children.check()?;
        if Instant::now() > deadline {
            bail!("deog view did not listen on {addr} within 30 s");
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    Ok(())
}

async fn pause(
    children: &mut Supervisor,
    time: Duration,
    progress: &Progress,
    begun: Instant,
) -> Result<()> {
    let until = Instant::now() + time;
    while Instant::now() < until {
        children.check()?;
        progress.set_done(begun.elapsed().as_secs());
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    Ok(())
}

fn page_stats(browser: &Browser) -> Result<Value> {
    browser.eval("return window.deogView.stats();", json!([]))
}

fn rendering_of(stats: &Value) -> Rendering {
    Rendering {
        fps: stats["fps"].as_f64().unwrap_or(0.0),
        draw_ms_mean: stats["drawMsMean"].as_f64().unwrap_or(0.0),
        draw_ms_p95: stats["drawMsP95"].as_f64().unwrap_or(0.0),
    }
}

async fn rendering_over(browser: &Browser, time: Duration) -> Result<Rendering> {
    browser.eval("window.deogView.resetStats();", json!([]))?;
    tokio::time::sleep(time).await;
    Ok(rendering_of(&page_stats(browser)?))
}

/// Writes `probes` tiles one at a time, each far from the map, and times
/// each from its acknowledgement to the page drawing it.
async fn probe_tiles(client: &MapClient, browser: &Browser, probes: u32) -> Result<Vec<f64>> {
    let size = TileSize::new(client.map_info(MAP).await?.tile_size)?;
    let mut sender = client
        .updates(MAP, "bench-view-probe", UpdateSenderConfig::default())
        .await?;
    let mut latencies = Vec::new();
    let progress = Progress::new("probe tiles", "tiles", u64::from(probes));
    for i in 0..probes {
        let key = TileKey::new(-40 - i as i32, -40);
        sender
            .push(TileDelta::from_raw(key, size, vec![1_500; size.area()])?)
            .await?;
        sender.flush().await?;
        let acked = epoch_ms();
        let deadline = Instant::now() + Duration::from_secs(10);
        let script = format!("return window.deogView.tileSeenAt({}, {});", key.x, key.y);
        loop {
            if let Some(seen) = browser.eval(&script, json!([]))?.as_f64() {
                latencies.push((seen - acked).max(0.0));
                progress.inc(1);
                break;
            }
            if Instant::now() > deadline {
                bail!("probe tile ({}, {}) never reached the page", key.x, key.y);
            }
            tokio::time::sleep(Duration::from_millis(2)).await;
        }
    }
    progress.finish();
    Ok(latencies)
}

fn epoch_ms() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs_f64() * 1000.0)
        .unwrap_or(0.0)
}

fn table(f: &ViewFigures) -> String {
    format!(
        "deog bench view: {robots} robots in {world}\n\
         | page | fps | draw ms (mean) | draw ms (p95) |\n\
         |---|---|---|---|\n\
         | idle (baseline) | {ifps:.1} | {idm:.2} | {idp:.2} |\n\
         | {robots} robots driving, {tiles} tiles | {lfps:.1} | {ldm:.2} | {ldp:.2} |\n\
         loaded / idle fps: {ratio:.2}; robot updates {rps:.0}/s\n\
         tile on the page after its acknowledgement: median {med:.0} ms, max {max:.0} ms ({n} probes)\n\
         deog view: resident set at most {rss:.1} MiB (VmHWM {hwm:.1} MiB), CPU {cpu:.0}% of a core\n",
        robots = f.robots,
        world = f.world,
        ifps = f.idle.fps,
        idm = f.idle.draw_ms_mean,
        idp = f.idle.draw_ms_p95,
        tiles = f.tiles,
        lfps = f.loaded.fps,
        ldm = f.loaded.draw_ms_mean,
        ldp = f.loaded.draw_ms_p95,
        ratio = f.fps_ratio,
        rps = f.robot_messages_per_s,
        med = f.tile_latency_ms_median,
        max = f.tile_latency_ms_max,
        n = f.tile_latency_ms.len(),
        rss = f.view_rss_mib_max,
        hwm = f.view_hwm_mib,
        cpu = f.view_cpu_percent,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn windows_are_read_and_checked() {
        assert_eq!(parse_window("1280x800").unwrap(), (1280, 800));
        assert!(parse_window("1280").is_err());
        assert!(parse_window("10x10").is_err());
        assert!(parse_window("axb").is_err());
    }
}
