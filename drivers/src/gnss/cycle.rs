//! Learning a receiver's cycle: which message ends its epochs.
//!
//! Both protocols' epoch assemblers vote at every epoch boundary they see for the last
//! data-carrying message of the epoch that ended; once [`ENDER_VOTES`] consecutive votes agree
//! it is trusted, and the epoch is emitted the moment that message arrives instead of when the
//! next epoch begins or the line goes idle. The assembler forgets it when data for an emitted
//! epoch arrive after it (the receiver changed its cycle). Pure, no allocation.

/// Consecutive epochs that must end with the same message before it is trusted.
pub const ENDER_VOTES: u8 = 2;

/// The learned last message of the cycle (`K`: how an assembler names a message), the
/// candidate and its votes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CycleEnder<K> {
    ender: Option<K>,
    candidate: Option<K>,
    votes: u8,
}

impl<K> Default for CycleEnder<K> {
    fn default() -> Self {
        Self {
            ender: None,
            candidate: None,
            votes: 0,
        }
    }
}

impl<K: Copy + PartialEq> CycleEnder<K> {
    /// The learned ender, if any.
    pub fn ender(&self) -> Option<&K> {
        self.ender.as_ref()
    }

    /// Whether `key` is the learned ender.
    pub fn is_ender(&self, key: K) -> bool {
        self.ender == Some(key)
    }

    /// One vote for `key`: it was the last message of an epoch that ended.
    pub fn vote(&mut self, key: K) {
        if self.candidate == Some(key) {
            self.votes = self.votes.saturating_add(1);
        } else {
            self.candidate = Some(key);
            self.votes = 1;
        }
        if self.votes >= ENDER_VOTES {
            self.ender = Some(key);
        }
    }

    /// Forgets the ender and the votes (the receiver's cycle changed).
    pub fn forget(&mut self) {
        *self = Self::default();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trusted_after_consecutive_votes_and_forgotten() {
        let mut c = CycleEnder::default();
        c.vote("GSA");
        c.vote("RMC");
        assert_eq!(c.ender(), None, "votes must be consecutive");
        c.vote("RMC");
        assert_eq!(c.ender(), Some(&"RMC"));
        c.vote("GSA");
        assert!(c.is_ender("RMC"), "one vote does not replace a trusted ender");
        c.forget();
        assert_eq!(c.ender(), None);
    }
}
