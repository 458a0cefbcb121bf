//! Learning a receiver's cycle: which message ends its epochs.
//!
//! Both protocols' epoch assemblers vote at every epoch boundary they see for the last
//! data-carrying message of the epoch that ended; once [`ENDER_VOTES`] consecutive votes agree
//! it is trusted, and the epoch is emitted the moment that message arrives instead of when the
//! next epoch begins or the line goes idle.
//!
//! A message that was ever seen **followed** by another data message of the same epoch is
//! never trusted ([`CycleEnder::followed`]): it is not the last of every cycle. That is what
//! keeps a receiver whose epochs differ in content (NAV-PVT alone, then NAV-PVT + NAV-SAT
//! every fifth second) from having NAV-PVT voted its ender by the epochs without NAV-SAT:
//! the first epoch with NAV-SAT disqualifies it for good. When data for an epoch already
//! emitted at the learned ender arrive anyway (the first such epoch, before the disqualifying
//! follower had ever been seen), the assembler forgets the ender, disqualifies it, and does
//! **not** publish that epoch again: every epoch is published exactly once. Pure, no
//! allocation.

/// Consecutive epochs that must end with the same message before it is trusted.
pub const ENDER_VOTES: u8 = 2;

/// Messages remembered as "followed within an epoch" (more than any receiver's cycle has
/// kinds of data messages; beyond it the oldest is forgotten, which only costs a vote).
pub const MAX_FOLLOWED: usize = 32;

/// The learned last message of the cycle (`K`: how an assembler names a message), the
/// candidate and its votes, and the messages that can never end a cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CycleEnder<K> {
    ender: Option<K>,
    candidate: Option<K>,
    votes: u8,
    /// Messages seen followed by another data message in one epoch (ring, `next` the slot
    /// written next).
    followed: [Option<K>; MAX_FOLLOWED],
    next: usize,
}

impl<K> Default for CycleEnder<K> {
    fn default() -> Self {
        Self {
            ender: None,
            candidate: None,
            votes: 0,
            followed: [const { None }; MAX_FOLLOWED],
            next: 0,
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

    /// Whether `key` was ever seen followed by another data message of its epoch.
    pub fn was_followed(&self, key: K) -> bool {
        self.followed.contains(&Some(key))
    }

    /// `key` was followed by another data message of the same epoch: it never ends a cycle.
    /// Forgets it as ender or candidate.
    pub fn followed(&mut self, key: K) {
        if !self.was_followed(key) {
            self.followed[self.next] = Some(key);
            self.next = (self.next + 1) % MAX_FOLLOWED;
        }
        if self.ender == Some(key) {
            self.ender = None;
        }
        if self.candidate == Some(key) {
            self.candidate = None;
            self.votes = 0;
        }
    }

    /// One vote for `key`: it was the last message of an epoch that ended. A message once
    /// followed within an epoch gets no vote (and breaks the run of votes).
    pub fn vote(&mut self, key: K) {
        if self.was_followed(key) {
            self.candidate = None;
            self.votes = 0;
            return;
        }
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

    /// Forgets the ender and the votes (the receiver's cycle changed); the followed messages
    /// stay disqualified.
    pub fn forget(&mut self) {
        self.ender = None;
        self.candidate = None;
        self.votes = 0;
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

    #[test]
    fn a_message_once_followed_is_never_trusted() {
        // Epochs alternating NAV-PVT alone and NAV-PVT + NAV-SAT: the first NAV-SAT epoch
        // shows NAV-PVT followed, so the NAV-PVT-only epochs' votes never make it the ender.
        let mut c = CycleEnder::default();
        c.followed("NAV-PVT");
        for _ in 0..5 {
            c.vote("NAV-PVT");
            c.vote("NAV-PVT");
        }
        assert_eq!(c.ender(), None);
        // Learned before the follower was seen: disqualified when it shows up.
        let mut c = CycleEnder::default();
        c.vote("NAV-PVT");
        c.vote("NAV-PVT");
        assert!(c.is_ender("NAV-PVT"));
        c.followed("NAV-PVT");
        assert_eq!(c.ender(), None);
        c.forget();
        c.vote("NAV-PVT");
        c.vote("NAV-PVT");
        assert_eq!(c.ender(), None, "stays disqualified after forget");
        c.vote("NAV-SAT");
        c.vote("NAV-SAT");
        assert!(c.is_ender("NAV-SAT"));
    }

    #[test]
    fn the_followed_ring_keeps_the_newest() {
        let mut c = CycleEnder::default();
        for k in 0..(MAX_FOLLOWED as u32 + 3) {
            c.followed(k);
        }
        assert!(!c.was_followed(0) && c.was_followed(MAX_FOLLOWED as u32 + 2));
    }
}
