//! Countdown for a loop that runs every `div` physics steps.

/// Due on physics steps 0, div, 2·div, … (cheaper than `k % div`, which would be six
/// integer divisions on the hot path of every step).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Ticker {
    div: u64,
    left: u64,
}

impl Ticker {
    /// A ticker due on the very next step (step 0).
    pub(crate) fn new(div: u64) -> Self {
        Self { div, left: 0 }
    }

    /// A ticker created at physics step `step` that is due on the multiples of `div`, as if
    /// it had been counting since step 0.
    pub(crate) fn at_step(div: u64, step: u64) -> Self {
        Self {
            div,
            left: (div - step % div) % div,
        }
    }

    /// Steps between two due steps.
    pub(crate) fn div(&self) -> u64 {
        self.div
    }

    /// True on steps 0, div, 2·div, …; call exactly once per physics step.
    #[inline]
    pub(crate) fn due(&mut self) -> bool {
        if self.left == 0 {
            self.left = self.div - 1;
            true
        } else {
            self.left -= 1;
            false
        }
    }
}
