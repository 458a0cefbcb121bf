//! Epoch times strictly increase on every output of a receiver.
//!
//! [`TimeOrder`] is the last gate of each output stream (the NAV epochs and the HNR-PVT
//! fixes of a u-blox receiver, the NMEA epochs): an epoch whose time is not after the last
//! one published on that output is held back and counted, so a subscriber never sees the same
//! epoch twice nor time going backwards. Epochs without a time are not ordered and pass.
//!
//! A receiver whose clock really went back (a reset, a corrected date, a capture spliced from
//! two sessions) would otherwise be silenced for good. Such a jump is told from a repeated or
//! stale epoch by its size: an epoch more than [`RESET_JUMP_NS`] before the last one published
//! restarts the order at once; and after [`RESYNC_EPOCHS`] epochs in a row were held back, each
//! later than the one before (a consistent new time line), the next one does. Both are
//! counted as resets: across a reset, and only there, an output's time goes back. Pure, no
//! allocation.

/// Epochs in a row held back, each after the previous one, before the order restarts.
pub const RESYNC_EPOCHS: u8 = 3;

/// A step back larger than this is the receiver's time line starting again, not a repeated
/// or stale epoch (those are at most a few epoch intervals old), ns.
pub const RESET_JUMP_NS: i64 = 60_000_000_000;

/// What [`TimeOrder::admit`] decided.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Admit {
    /// After the last published time (or without a time): publish.
    Publish,
    /// Not after the last published time: held back.
    HeldBack,
    /// The receiver's time went back for good: publish, the order restarts here.
    Reset,
}

/// The last published epoch time of one output, and the epochs held back since.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct TimeOrder {
    last_ns: Option<i64>,
    /// Epochs held back in a row, and the time of the last of them.
    held: u8,
    held_last_ns: Option<i64>,
}

impl TimeOrder {
    /// Whether an epoch of time `t_ns` (`i64::MIN`: none) is published; remembers it if so.
    pub fn admit(&mut self, t_ns: i64) -> Admit {
        if t_ns == i64::MIN {
            return Admit::Publish;
        }
        match self.last_ns {
            Some(last) if t_ns < last.saturating_sub(RESET_JUMP_NS) => {
                self.restart(t_ns);
                Admit::Reset
            }
            // The last epoch again: never published twice, whatever came in between.
            Some(last) if t_ns == last => Admit::HeldBack,
            Some(last) if t_ns < last => {
                let consistent = self.held_last_ns.is_none_or(|h| t_ns > h);
                self.held = if consistent { self.held.saturating_add(1) } else { 1 };
                self.held_last_ns = Some(t_ns);
                if self.held > RESYNC_EPOCHS {
                    self.restart(t_ns);
                    Admit::Reset
                } else {
                    Admit::HeldBack
                }
            }
            _ => {
                self.restart(t_ns);
                Admit::Publish
            }
        }
    }

    fn restart(&mut self, t_ns: i64) {
        self.last_ns = Some(t_ns);
        self.held = 0;
        self.held_last_ns = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn holds_back_repeats_and_regressions_and_follows_a_real_reset() {
        let mut o = TimeOrder::default();
        assert_eq!(o.admit(10), Admit::Publish);
        assert_eq!(o.admit(i64::MIN), Admit::Publish, "no time: not ordered");
        assert_eq!(o.admit(10), Admit::HeldBack, "the same epoch again");
        assert_eq!(o.admit(9), Admit::HeldBack, "backwards");
        assert_eq!(o.admit(11), Admit::Publish);
        // A jump back of more than a minute: a new time line at once.
        let mut big = TimeOrder::default();
        assert_eq!(big.admit(10 * RESET_JUMP_NS), Admit::Publish);
        assert_eq!(big.admit(RESET_JUMP_NS), Admit::Reset);
        assert_eq!(big.admit(RESET_JUMP_NS + 1), Admit::Publish);
        // A reset to an earlier, consistent time line: followed after RESYNC_EPOCHS.
        for t in 1..=i64::from(RESYNC_EPOCHS) {
            assert_eq!(o.admit(t), Admit::HeldBack);
        }
        assert_eq!(o.admit(5), Admit::Reset);
        assert_eq!(o.admit(6), Admit::Publish);
        // Repeats of one old time are not a consistent time line.
        for _ in 0..10 {
            assert_eq!(o.admit(6), Admit::HeldBack);
        }
        // A consistent line that climbs back to the last time does not publish it again.
        let mut o = TimeOrder::default();
        assert_eq!(o.admit(100), Admit::Publish);
        for t in [97, 98, 99] {
            assert_eq!(o.admit(t), Admit::HeldBack);
        }
        assert_eq!(o.admit(100), Admit::HeldBack, "the same epoch as the last published");
        assert_eq!(o.admit(101), Admit::Publish);
    }
}
