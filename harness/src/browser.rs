//! A headless Chromium driven through ChromeDriver's WebDriver protocol,
//! for the view's browser test and benchmark: open a page, run a script in
//! it, take a screenshot. Plain HTTP/1.1 over loopback, one request per
//! connection; nothing else is asked of the driver.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, anyhow, bail};
use serde_json::{Value, json};

use crate::free_loopback_addr;

/// Where Debian's packages put the browser and its driver.
pub const CHROMIUM: &str = "/usr/bin/chromium";
/// See [`CHROMIUM`].
pub const CHROMEDRIVER: &str = "/usr/bin/chromedriver";

/// How long one WebDriver call may take.
const CALL_TIMEOUT: Duration = Duration::from_secs(60);

/// A ChromeDriver process and one headless Chromium session of it; both
/// end when it is dropped.
pub struct Browser {
    driver: Child,
    addr: SocketAddr,
    session: String,
    _profile: tempfile_dir::TempDir,
}

impl Browser {
    /// Starts ChromeDriver and a headless Chromium of `width` × `height`
    /// pixels. The binaries are Debian's `chromium` and `chromium-driver`,
    /// or those `DEOG_CHROMIUM` and `DEOG_CHROMEDRIVER` name.
    pub fn start(width: u32, height: u32) -> Result<Self> {
        let chromium = binary("DEOG_CHROMIUM", CHROMIUM)?;
        let chromedriver = binary("DEOG_CHROMEDRIVER", CHROMEDRIVER)?;
        let addr = free_loopback_addr()?;
        let driver = Command::new(&chromedriver)
            .arg(format!("--port={}", addr.port()))
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .with_context(|| format!("starting {}", chromedriver.display()))?;
        let profile = tempfile_dir::TempDir::new("deog-chromium")?;
        let mut browser = Self {
            driver,
            addr,
            session: String::new(),
            _profile: profile,
        };
        browser.wait_ready()?;
        // The flags a closed network and a root user need: no sandbox, no
        // background fetches that the machine refuses.
        let args = vec![
            "--headless=new".to_string(),
            "--no-sandbox".to_string(),
            "--disable-gpu".to_string(),
            "--disable-quic".to_string(),
            "--no-first-run".to_string(),
            "--disable-background-networking".to_string(),
            "--disable-component-update".to_string(),
            "--disable-sync".to_string(),
            "--disable-dev-shm-usage".to_string(),
            format!("--window-size={width},{height}"),
            format!("--user-data-dir={}", browser._profile.path().display()),
        ];
        let reply = browser.call(
            "POST",
            "/session",
            Some(json!({
                "capabilities": {"alwaysMatch": {
                    "browserName": "chrome",
                    "goog:chromeOptions": {"binary": chromium, "args": args},
                }}
            })),
        )?;
        browser.session = reply["sessionId"]
            .as_str()
            .ok_or_else(|| anyhow!("ChromeDriver gave no session: {reply}"))?
            .to_string();
        Ok(browser)
    }

    fn wait_ready(&self) -> Result<()> {
        let deadline = Instant::now() + Duration::from_secs(20);
        loop {
            if let Ok(status) = self.call("GET", "/status", None)
                && status["ready"].as_bool() == Some(true)
            {
                return Ok(());
            }
            if Instant::now() > deadline {
                bail!(
                    "ChromeDriver did not become ready on {} within 20 s",
                    self.addr
                );
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// Opens `url` and waits for its load.
    pub fn goto(&self, url: &str) -> Result<()> {
        self.call("POST", &self.path("url"), Some(json!({ "url": url })))?;
        Ok(())
    }

    /// Runs `script` (a function body; `return` gives its value) in the
    /// page with `args`.
    pub fn eval(&self, script: &str, args: Value) -> Result<Value> {
        self.call(
            "POST",
            &self.path("execute/sync"),
            Some(json!({ "script": script, "args": args })),
        )
    }

    /// The page as PNG bytes.
    pub fn screenshot(&self) -> Result<Vec<u8>> {
        let encoded = self.call("GET", &self.path("screenshot"), None)?;
        let text = encoded
            .as_str()
            .ok_or_else(|| anyhow!("the screenshot is not text"))?;
        decode_base64(text)
    }

    /// The process id of the driver (the browser is its child).
    pub fn driver_pid(&self) -> u32 {
        self.driver.id()
    }

    fn path(&self, command: &str) -> String {
        format!("/session/{}/{command}", self.session)
    }

    /// One WebDriver call; its `value`, or the driver's error.
    fn call(&self, method: &str, path: &str, body: Option<Value>) -> Result<Value> {
        let body = body.map(|b| b.to_string()).unwrap_or_default();
        let mut stream = TcpStream::connect_timeout(&self.addr, Duration::from_secs(5))
            .with_context(|| format!("reaching ChromeDriver at {}", self.addr))?;
        stream.set_read_timeout(Some(CALL_TIMEOUT))?;
        stream.set_write_timeout(Some(CALL_TIMEOUT))?;
        write!(
            stream,
            "{method} {path} HTTP/1.1\r\nHost: {}\r\nContent-Type: application/json\r\n\
             Content-Length: {}\r\nConnection: close\r\n\r\n{body}",
            self.addr,
            body.len()
        )?;
        let reply = read_response(&mut stream)
            .with_context(|| format!("reading ChromeDriver's answer to {method} {path}"))?;
        let (status, payload) = split_response(&reply)?;
        let value: Value = serde_json::from_slice(&payload)
            .with_context(|| format!("ChromeDriver's answer to {method} {path} is not JSON"))?;
        let value = value.get("value").cloned().unwrap_or(Value::Null);
        if status != 200 {
            bail!("{method} {path}: HTTP {status}: {value}");
        }
        Ok(value)
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        if !self.session.is_empty() {
            let _ = self.call("DELETE", &format!("/session/{}", self.session), None);
        }
        let _ = self.driver.kill();
        let _ = self.driver.wait();
    }
}

fn binary(variable: &str, default: &str) -> Result<PathBuf> {
    let path = std::env::var_os(variable)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(default));
    if !path.exists() {
        bail!(
            "{} is missing: install Debian's chromium and chromium-driver packages \
             (apt-get install chromium chromium-driver), or name them with \
             DEOG_CHROMIUM and DEOG_CHROMEDRIVER",
            path.display()
        );
    }
    Ok(path)
}

/// One whole HTTP/1.1 response: up to its Content-Length, or its last
/// chunk, or the connection's end (the driver may keep the connection
/// open whatever the request asked).
fn read_response(stream: &mut impl Read) -> Result<Vec<u8>> {
    let mut reply = Vec::new();
    let mut buffer = [0u8; 64 * 1024];
    loop {
        let read = stream.read(&mut buffer)?;
        if read == 0 {
            return Ok(reply);
        }
        reply.extend_from_slice(&buffer[..read]);
        let Some(end) = reply.windows(4).position(|w| w == b"\r\n\r\n") else {
            continue;
        };
        let head = String::from_utf8_lossy(&reply[..end]).to_ascii_lowercase();
        let length = head.lines().find_map(|line| {
            line.strip_prefix("content-length:")
                .and_then(|v| v.trim().parse::<usize>().ok())
        });
        let body = reply.len() - end - 4;
        match length {
            Some(length) if body >= length => return Ok(reply),
            Some(_) => {}
            None if head.contains("chunked") && reply.ends_with(b"0\r\n\r\n") => return Ok(reply),
            None => {}
        }
    }
}

/// An HTTP/1.1 response's status and body (plain or chunked).
fn split_response(reply: &[u8]) -> Result<(u16, Vec<u8>)> {
    let end = reply
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .ok_or_else(|| anyhow!("an HTTP answer without headers"))?;
    let head = std::str::from_utf8(&reply[..end]).context("HTTP headers are not text")?;
    let status = head
        .split_whitespace()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .ok_or_else(|| anyhow!("no HTTP status in {head:?}"))?;
    let body = &reply[end + 4..];
    let chunked = head.lines().any(|line| {
        let line = line.to_ascii_lowercase();
        line.starts_with("transfer-encoding:") && line.contains("chunked")
    });
    if !chunked {
        return Ok((status, body.to_vec()));
    }
    let mut out = Vec::new();
    let mut rest = body;
    loop {
        let line_end = rest
            .windows(2)
            .position(|w| w == b"\r\n")
            .ok_or_else(|| anyhow!("a cut chunked body"))?;
        let size_text = std::str::from_utf8(&rest[..line_end])?;
        let size = usize::from_str_radix(size_text.split(';').next().unwrap_or("").trim(), 16)
            .with_context(|| format!("a chunk size {size_text:?}"))?;
        rest = &rest[line_end + 2..];
        if size == 0 {
            return Ok((status, out));
        }
        if rest.len() < size + 2 {
            bail!("a cut chunk");
        }
        out.extend_from_slice(&rest[..size]);
        rest = &rest[size + 2..];
    }
}

/// Standard base64, as WebDriver sends screenshots.
fn decode_base64(text: &str) -> Result<Vec<u8>> {
    let mut out = Vec::with_capacity(text.len() / 4 * 3);
    let mut buffer = 0u32;
    let mut bits = 0;
    for byte in text.bytes() {
        let value = match byte {
            b'A'..=b'Z' => byte - b'A',
            b'a'..=b'z' => byte - b'a' + 26,
            b'0'..=b'9' => byte - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            b'=' | b'\n' | b'\r' => continue,
            _ => bail!("not base64: {:?}", byte as char),
        };
        buffer = (buffer << 6) | u32::from(value);
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((buffer >> bits) as u8);
        }
    }
    Ok(out)
}

/// A folder of its own, removed when dropped (the browser's profile).
mod tempfile_dir {
    use std::path::{Path, PathBuf};

    pub struct TempDir(PathBuf);

    impl TempDir {
        pub fn new(prefix: &str) -> anyhow::Result<Self> {
            let unique = format!(
                "{prefix}-{}-{}",
                std::process::id(),
                std::time::SystemTime::now()
                    .duration_since(std::time::UNIX_EPOCH)
                    .map(|d| d.as_nanos())
                    .unwrap_or(0)
            );
            let path = std::env::temp_dir().join(unique);
            std::fs::create_dir_all(&path)?;
            Ok(Self(path))
        }

        pub fn path(&self) -> &Path {
            &self.0
        }
    }

    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

/// Whether both binaries are where [`Browser::start`] looks.
pub fn available() -> bool {
    binary("DEOG_CHROMIUM", CHROMIUM).is_ok() && binary("DEOG_CHROMEDRIVER", CHROMEDRIVER).is_ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_decodes_as_the_standard_says() {
        assert_eq!(decode_base64("aGVsbG8=").unwrap(), b"hello");
        assert_eq!(decode_base64("aGk=").unwrap(), b"hi");
        assert_eq!(decode_base64("AAEC/w==").unwrap(), [0, 1, 2, 255]);
        assert!(decode_base64("a*b").is_err());
    }

    #[test]
    fn chunked_and_plain_bodies_are_read() {
        let plain = b"HTTP/1.1 200 OK\r\nContent-Length: 2\r\n\r\n{}";
        assert_eq!(split_response(plain).unwrap(), (200, b"{}".to_vec()));
        let chunked = b"HTTP/1.1 404 Not Found\r\nTransfer-Encoding: chunked\r\n\r\n3\r\nabc\r\n2\r\nde\r\n0\r\n\r\n";
        assert_eq!(split_response(chunked).unwrap(), (404, b"abcde".to_vec()));
        assert!(split_response(b"garbage").is_err());
    }
}
