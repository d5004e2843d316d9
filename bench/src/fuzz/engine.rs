//! One target fuzzed for a budget: its seeds run as they are, then
//! mutated inputs until the time or the exec count runs out. Each input
//! runs under `catch_unwind`; a panic is a crash, its input saved under
//! the crashes folder, its message kept; an input slower than the hang
//! limit is a hang, saved likewise.

use std::cell::{Cell, RefCell};
use std::path::{Path, PathBuf};
use std::sync::Once;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};

use super::mutate::Mutator;

/// A decoder of outside input, as fuzzed.
pub struct Target {
    /// The name `--targets` takes ("wire-update-batch").
    pub name: &'static str,
    /// Feeds the bytes to the decoder; returns normally whether it accepts
    /// them or refuses them with an error. A panic is the bug sought.
    pub decode: fn(&[u8]),
    /// Valid inputs the mutations start from.
    pub seeds: fn() -> Vec<Vec<u8>>,
}

/// How long one target runs: whichever limit comes first.
#[derive(Debug, Clone, Copy)]
pub struct Budget {
    /// Wall-clock time.
    pub time: Duration,
    /// Most inputs run, seeds included; `None` for no limit.
    pub max_execs: Option<u64>,
    /// An input that takes longer than this is a hang.
    pub hang_after: Duration,
}

/// What one target's run found.
#[derive(Debug, Clone, PartialEq)]
pub struct TargetRun {
    /// The target's name.
    pub target: &'static str,
    /// Inputs run, seeds included.
    pub execs: u64,
    /// Wall-clock time of the run.
    pub elapsed: Duration,
    /// Inputs that panicked.
    pub crashes: u64,
    /// Inputs slower than the hang limit.
    pub hangs: u64,
    /// The first panic's message ("panicked at file:line:col: ...").
    pub first_crash: Option<String>,
    /// Where the first crashing input was saved.
    pub first_crash_file: Option<PathBuf>,
    /// The slowest single input.
    pub slowest: Duration,
}

impl TargetRun {
    /// Inputs per second of wall-clock time.
    pub fn execs_per_s(&self) -> f64 {
        self.execs as f64 / self.elapsed.as_secs_f64().max(1e-9)
    }
}

/// Most inputs saved per target and kind: the first few say what broke,
/// and a decoder that panics on everything must not fill the disk.
const MAX_SAVED: usize = 20;

/// Runs `target` for `budget`, its inputs drawn from `seed`, saving
/// crashing and hanging inputs under `crashes_dir` (made when first
/// needed) as `<target>-<hash>` and `<target>-hang-<hash>`.
pub fn fuzz(target: &Target, budget: &Budget, seed: u64, crashes_dir: &Path) -> Result<TargetRun> {
    install_quiet_hook();
    let corpus = (target.seeds)();
    let mut mutator = Mutator::new(seed ^ name_hash(target.name));
    let mut run = TargetRun {
        target: target.name,
        execs: 0,
        elapsed: Duration::ZERO,
        crashes: 0,
        hangs: 0,
        first_crash: None,
        first_crash_file: None,
        slowest: Duration::ZERO,
    };
    let (mut saved_crashes, mut saved_hangs) = (0, 0);
    let start = Instant::now();
    loop {
        if budget.max_execs.is_some_and(|max| run.execs >= max) || start.elapsed() >= budget.time {
            break;
        }
        let input = match corpus.get(run.execs as usize) {
            Some(seed_input) => seed_input.clone(),
            None => mutator.next_input(&corpus),
        };
        run.execs += 1;
        let began = Instant::now();
        let outcome = run_one(target.decode, &input);
        let took = began.elapsed();
        run.slowest = run.slowest.max(took);
        if let Err(message) = outcome {
            run.crashes += 1;
            if saved_crashes < MAX_SAVED {
                saved_crashes += 1;
                let file = save(crashes_dir, &format!("{}-", target.name), &input)?;
                if run.first_crash.is_none() {
                    run.first_crash = Some(message);
                    run.first_crash_file = Some(file);
                }
            }
        } else if took > budget.hang_after
            && confirmed_slow(target.decode, &input, budget.hang_after)
        {
            run.hangs += 1;
            if saved_hangs < MAX_SAVED {
                saved_hangs += 1;
                save(crashes_dir, &format!("{}-hang-", target.name), &input)?;
            }
        }
    }
    run.elapsed = start.elapsed();
    Ok(run)
}

/// Whether an input that took longer than `limit` does so again, twice:
/// a busy machine can hold any input up for a while, a real hang is slow
/// every time.
fn confirmed_slow(decode: fn(&[u8]), input: &[u8], limit: Duration) -> bool {
    (0..2).all(|_| {
        let began = Instant::now();
        let _ = run_one(decode, input);
        began.elapsed() > limit
    })
}

thread_local! {
    /// Whether this thread is running a fuzzed input: its panics are
    /// captured, not printed.
    static CAPTURING: Cell<bool> = const { Cell::new(false) };
    /// The last captured panic's message and place.
    static CAPTURED: RefCell<Option<String>> = const { RefCell::new(None) };
}

/// Wraps the panic hook once: panics on a fuzzing thread are kept for the
/// report instead of printed (thousands would bury the table); any other
/// thread's panics go to the hook there was.
fn install_quiet_hook() {
    static INSTALL: Once = Once::new();
    INSTALL.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if CAPTURING.get() {
                CAPTURED.set(Some(info.to_string().replace('\n', " ")));
            } else {
                previous(info);
            }
        }));
    });
}

/// Runs one input; `Err` holds the panic's message.
fn run_one(decode: fn(&[u8]), input: &[u8]) -> Result<(), String> {
    CAPTURING.set(true);
    let result = std::panic::catch_unwind(|| decode(input));
    CAPTURING.set(false);
    result.map_err(|payload| {
        CAPTURED.take().unwrap_or_else(|| {
            payload
                .downcast_ref::<&str>()
                .map(|s| (*s).to_owned())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "panic without a message".into())
        })
    })
}

fn save(dir: &Path, prefix: &str, input: &[u8]) -> Result<PathBuf> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let file = dir.join(format!("{prefix}{:016x}", fnv1a(input)));
    std::fs::write(&file, input).with_context(|| format!("writing {}", file.display()))?;
    Ok(file)
}

/// FNV-1a: a stable hash (std's is not promised stable across releases),
/// for file names and per-target seeds.
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

/// Each target gets its own stream of inputs, the same whichever other
/// targets run beside it.
fn name_hash(name: &str) -> u64 {
    fnv1a(name.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Panics on inputs holding the bytes "BUG", as a decoder with an
    /// unchecked index would.
    fn buggy(bytes: &[u8]) {
        if bytes.windows(3).any(|w| w == b"BUG") {
            panic!("found the bug");
        }
    }

    fn buggy_seeds() -> Vec<Vec<u8>> {
        vec![b"BUX".to_vec(), b"xxBUGxx".to_vec()]
    }

    fn sound(bytes: &[u8]) {
        let _ = std::str::from_utf8(bytes);
    }

    fn sound_seeds() -> Vec<Vec<u8>> {
        vec![b"fine".to_vec()]
    }

    fn budget(max_execs: u64) -> Budget {
        Budget {
            time: Duration::from_secs(60),
            max_execs: Some(max_execs),
            hang_after: Duration::from_secs(1),
        }
    }

    #[test]
    fn a_panicking_input_is_a_crash_with_its_input_saved() {
        let dir = tempfile::tempdir().unwrap();
        let target = Target {
            name: "test-buggy",
            decode: buggy,
            seeds: buggy_seeds,
        };
        let run = fuzz(&target, &budget(200), 1, dir.path()).unwrap();
        assert_eq!(run.execs, 200);
        assert!(run.crashes >= 1);
        let message = run.first_crash.as_deref().unwrap();
        assert!(message.contains("found the bug"), "{message}");
        assert!(
            message.contains("engine.rs"),
            "the place is kept: {message}"
        );
        let saved = std::fs::read(run.first_crash_file.as_ref().unwrap()).unwrap();
        assert_eq!(saved, b"xxBUGxx");
        assert!(
            run.first_crash_file
                .as_ref()
                .unwrap()
                .file_name()
                .unwrap()
                .to_string_lossy()
                .starts_with("test-buggy-")
        );
    }

    #[test]
    fn a_mutation_finds_a_crash_no_seed_holds() {
        fn needs_mutation(bytes: &[u8]) {
            // The seed is "BUX"; one byte set or flip away from the bug.
            if bytes.first() == Some(&b'B') && bytes.get(2) == Some(&0xFF) {
                panic!("edge byte");
            }
        }
        let dir = tempfile::tempdir().unwrap();
        let target = Target {
            name: "test-mutation",
            decode: needs_mutation,
            seeds: || vec![b"BUX".to_vec()],
        };
        let run = fuzz(&target, &budget(20_000), 3, dir.path()).unwrap();
        assert!(run.crashes >= 1, "{run:?}");
        assert!(std::fs::read_dir(dir.path()).unwrap().count() >= 1);
    }

    #[test]
    fn a_sound_decoder_has_no_crashes_and_nothing_is_written() {
        let dir = tempfile::tempdir().unwrap();
        let crashes = dir.path().join("crashes");
        let target = Target {
            name: "test-sound",
            decode: sound,
            seeds: sound_seeds,
        };
        let run = fuzz(&target, &budget(500), 1, &crashes).unwrap();
        assert_eq!((run.execs, run.crashes, run.hangs), (500, 0, 0));
        assert!(run.first_crash.is_none());
        assert!(!crashes.exists());
    }

    #[test]
    fn a_fixed_seed_runs_the_same_inputs() {
        use std::sync::Mutex;
        static SEEN: Mutex<Vec<Vec<u8>>> = Mutex::new(Vec::new());
        fn record(bytes: &[u8]) {
            SEEN.lock().unwrap().push(bytes.to_vec());
        }
        let target = Target {
            name: "test-record",
            decode: record,
            seeds: sound_seeds,
        };
        let dir = tempfile::tempdir().unwrap();
        fuzz(&target, &budget(300), 9, dir.path()).unwrap();
        let first = std::mem::take(&mut *SEEN.lock().unwrap());
        fuzz(&target, &budget(300), 9, dir.path()).unwrap();
        let second = std::mem::take(&mut *SEEN.lock().unwrap());
        assert_eq!(first.len(), 300);
        assert_eq!(first, second);
        assert_eq!(first[0], b"fine", "seeds run first, unchanged");
    }

    #[test]
    fn a_slow_input_is_a_hang() {
        fn slow(bytes: &[u8]) {
            if bytes == b"slow" {
                std::thread::sleep(Duration::from_millis(30));
            }
        }
        let dir = tempfile::tempdir().unwrap();
        let target = Target {
            name: "test-slow",
            decode: slow,
            seeds: || vec![b"slow".to_vec()],
        };
        let budget = Budget {
            hang_after: Duration::from_millis(10),
            ..budget(1)
        };
        let run = fuzz(&target, &budget, 1, dir.path()).unwrap();
        assert_eq!((run.crashes, run.hangs), (0, 1));
        assert!(
            dir.path()
                .join(format!("test-slow-hang-{:016x}", fnv1a(b"slow")))
                .exists()
        );
    }
}
