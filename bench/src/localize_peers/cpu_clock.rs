//! The calling thread's CPU time: what one filter update costs, whatever
//! else the machine runs.

use anyhow::{Context, Result};
use nix::time::{ClockId, clock_gettime};

/// Seconds of CPU the calling thread has used (CLOCK_THREAD_CPUTIME_ID).
pub(super) fn thread_cpu_s() -> Result<f64> {
    let t = clock_gettime(ClockId::CLOCK_THREAD_CPUTIME_ID)
        .context("reading the thread's CPU clock")?;
    Ok(t.tv_sec() as f64 + t.tv_nsec() as f64 * 1e-9)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_clock_advances_with_work_on_this_thread() {
        let before = thread_cpu_s().expect("a clock");
        let mut x = 0u64;
        for i in 0..5_000_000u64 {
            x = std::hint::black_box(x.wrapping_mul(31).wrapping_add(i));
        }
        std::hint::black_box(x);
        let after = thread_cpu_s().expect("a clock");
        assert!(after > before, "{before} then {after}");
    }
}
