//! A process's memory and CPU time, read from Linux's `/proc`.

use anyhow::{Context, Result};

/// Clock ticks per second of `/proc/<pid>/stat` on Linux.
const CLOCK_TICKS: f64 = 100.0;

/// A `kB` field of `/proc/<pid>/status`, such as `VmRSS` or `VmHWM`.
pub fn status_kb(pid: u32, field: &str) -> Result<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status"))
        .with_context(|| format!("reading /proc/{pid}/status"))?;
    status
        .lines()
        .find_map(|line| {
            let rest = line.strip_prefix(field)?.strip_prefix(':')?;
            rest.split_whitespace().next()?.parse().ok()
        })
        .with_context(|| format!("no {field} in /proc/{pid}/status"))
}

/// User plus system CPU seconds process `pid` has used.
pub fn cpu_seconds(pid: u32) -> Result<f64> {
    stat_cpu_seconds(&format!("/proc/{pid}/stat"))
}

/// User plus system CPU seconds this process has used.
pub fn own_cpu_seconds() -> Result<f64> {
    stat_cpu_seconds("/proc/self/stat")
}

/// Fields 14 and 15 of a `stat` file, after the parenthesised name.
fn stat_cpu_seconds(path: &str) -> Result<f64> {
    let stat = std::fs::read_to_string(path).with_context(|| format!("reading {path}"))?;
    // The name may hold spaces and parentheses: the fields start after the
    // last ')'.
    let (_, rest) = stat
        .rsplit_once(')')
        .with_context(|| format!("no process name in {path}"))?;
    let fields: Vec<&str> = rest.split_whitespace().collect();
    // After the name: state is field 3, so utime (14) and stime (15) are
    // at 11 and 12.
    let ticks = |i: usize| -> Result<f64> {
        fields
            .get(i)
            .and_then(|f| f.parse::<f64>().ok())
            .with_context(|| format!("field {} of {path}", i + 3))
    };
    Ok((ticks(11)? + ticks(12)?) / CLOCK_TICKS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn this_process_has_a_resident_set_and_cpu_time() {
        let pid = std::process::id();
        assert!(status_kb(pid, "VmRSS").expect("VmRSS") > 0);
        assert!(status_kb(pid, "NoSuchField").is_err());
        // Burn a little CPU so the count cannot stay at zero by chance.
        let mut x = 0u64;
        for i in 0..20_000_000u64 {
            x = x.wrapping_mul(31).wrapping_add(i);
        }
        std::hint::black_box(x);
        assert!(own_cpu_seconds().expect("own CPU") >= 0.0);
        assert!(cpu_seconds(pid).expect("CPU by pid") >= 0.0);
        assert!(cpu_seconds(u32::MAX).is_err());
    }
}
