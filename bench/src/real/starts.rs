//! The global starts' first scans, drawn at random but seeded.

use anyhow::{Result, ensure};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// `count` distinct start scans from `1..=scans - window` (so each start's
/// window `k..=k + window` lies within the scans), drawn with `seed`, in
/// increasing order. Fails when fewer than `count` scans can start a
/// window.
pub(super) fn pick_starts(seed: u64, count: usize, scans: u64, window: u64) -> Result<Vec<u64>> {
    let candidates = scans.saturating_sub(window);
    ensure!(
        count as u64 <= candidates,
        "{count} global starts need as many scans in 1..={} (the scans less a window of {window}), but there are {candidates}: lower --starts, --settle-scans or --hold-scans",
        scans.saturating_sub(window)
    );
    if count == 0 {
        return Ok(Vec::new());
    }
    let candidates = usize::try_from(candidates)?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut starts: Vec<u64> = rand::seq::index::sample(&mut rng, candidates, count)
        .into_iter()
        .map(|i| i as u64 + 1)
        .collect();
    starts.sort_unstable();
    Ok(starts)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn starts_are_distinct_sorted_leave_room_for_their_window_and_follow_the_seed() {
        let starts = pick_starts(1, 20, 910, 40).expect("room");
        assert_eq!(starts.len(), 20);
        assert!(starts.windows(2).all(|w| w[0] < w[1]), "{starts:?}");
        assert!(starts.iter().all(|&k| (1..=870).contains(&k)), "{starts:?}");
        assert_eq!(starts, pick_starts(1, 20, 910, 40).expect("room"));
        assert_ne!(starts, pick_starts(2, 20, 910, 40).expect("room"));
    }

    #[test]
    fn every_candidate_can_be_drawn() {
        // Three scans can start a window of 2 in 5 scans: 1, 2 and 3.
        assert_eq!(pick_starts(7, 3, 5, 2).expect("room"), [1, 2, 3]);
        assert!(pick_starts(7, 0, 5, 2).expect("none").is_empty());
    }

    #[test]
    fn too_many_starts_are_refused() {
        let error = pick_starts(1, 4, 5, 2).expect_err("no room");
        assert!(error.to_string().contains("there are 3"), "{error}");
        assert!(pick_starts(1, 1, 40, 40).is_err());
    }
}
