//! Mapping from a localizer's estimates (`deog map --pose estimate`): which
//! pose, if any, a frame is mapped from, given the estimates published so
//! far for its robot. Only converged estimates place a frame: a filter
//! still searching would paint walls where the robot is not. A frame the
//! localizer passed over (it published for a later frame, not this one) is
//! skipped; one it has not reached yet waits.

use std::collections::BTreeMap;

use deog_grid::Pose2;

/// What the estimates say of one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum EstimateLookup {
    /// A converged estimate for exactly this frame: map it from here.
    Converged(Pose2),
    /// The localizer's estimate for this frame is not converged: skip it.
    NotConverged,
    /// The localizer went past this frame without an estimate for it
    /// (it skipped frames to keep up): skip it.
    Passed,
    /// The localizer has not reached this frame yet: wait for it.
    Pending,
}

/// The estimates of one robot, by frame sequence, as they arrive.
#[derive(Debug, Clone, Default)]
pub struct EstimateBook {
    /// Frame sequence → the pose if the estimate was converged.
    by_frame: BTreeMap<u64, Option<Pose2>>,
    /// The highest frame sequence any estimate was published for.
    latest: u64,
}

impl EstimateBook {
    /// An empty book.
    pub fn new() -> Self {
        Self::default()
    }

    /// Records the estimate published for `frame_sequence`.
    pub fn insert(&mut self, frame_sequence: u64, pose: Pose2, converged: bool) {
        self.by_frame
            .insert(frame_sequence, converged.then_some(pose));
        self.latest = self.latest.max(frame_sequence);
    }

    /// The highest frame sequence an estimate was published for (0: none).
    pub fn latest(&self) -> u64 {
        self.latest
    }

    /// What the estimates say of frame `sequence`.
    pub fn lookup(&self, sequence: u64) -> EstimateLookup {
        match self.by_frame.get(&sequence) {
            Some(Some(pose)) => EstimateLookup::Converged(*pose),
            Some(None) => EstimateLookup::NotConverged,
            None if self.latest > sequence => EstimateLookup::Passed,
            None => EstimateLookup::Pending,
        }
    }

    /// Forgets the estimates of frames before `sequence`: frames are
    /// mapped in order, so they are not asked for again.
    pub fn forget_before(&mut self, sequence: u64) {
        self.by_frame = self.by_frame.split_off(&sequence);
    }

    /// Estimates held.
    pub fn len(&self) -> usize {
        self.by_frame.len()
    }

    /// Whether none is held.
    pub fn is_empty(&self) -> bool {
        self.by_frame.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_are_mapped_only_from_converged_estimates_of_their_own() {
        let mut book = EstimateBook::new();
        assert_eq!(book.lookup(1), EstimateLookup::Pending);
        book.insert(1, Pose2::new(1.0, 0.0, 0.0), false);
        book.insert(2, Pose2::new(2.0, 0.0, 0.0), true);
        book.insert(5, Pose2::new(5.0, 0.0, 0.0), true);
        assert_eq!(book.lookup(1), EstimateLookup::NotConverged);
        assert_eq!(
            book.lookup(2),
            EstimateLookup::Converged(Pose2::new(2.0, 0.0, 0.0))
        );
        assert_eq!(book.lookup(3), EstimateLookup::Passed);
        assert_eq!(book.lookup(6), EstimateLookup::Pending);
        assert_eq!(book.latest(), 5);
        book.forget_before(3);
        assert_eq!(book.len(), 1);
        // A forgotten frame reads as passed, never as pending.
        assert_eq!(book.lookup(2), EstimateLookup::Passed);
        // A late estimate for an earlier frame does not lower the mark.
        book.insert(4, Pose2::default(), true);
        assert_eq!(book.latest(), 5);
    }
}
